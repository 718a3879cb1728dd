"""``vimsim ego``: the camera's rotation per frame of a video (or of a sphere-mode grid), as a CSV.

Columns (one row per video frame; row 0 repeats row 1, as the grid file's rows)::

    frame,time_s,omega_x_dps,omega_y_dps,omega_z_dps,yaw_rate_dps,pitch_rate_dps,
    roll_rate_dps,rotation_dps,confidence

``omega_*``: the camera's angular velocity, deg/s, a vector in the world frame (the
equirect frame at frame t-1: +x right, +y up, +z forward; right-handed). The rates are
the same vector about the camera's own axes in vimsim's head conventions: yaw rate
``= omega_y`` (+ turning right), pitch rate ``= -omega_x`` (+ looking up), roll rate
``= -omega_z`` (+ right ear down). ``rotation_dps = |omega|``; ``confidence`` in [0, 1]
(:class:`simulator.preprocess.ego.EgoFit`). Frame ``k`` is at ``k / fps`` seconds (a
variable-rate video: at its timestamp, from the video or the grid's ``frame_times_s``) and
holds the motion from frame ``k - 1`` to ``k``.
"""

from __future__ import annotations

import io
import os
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from simulator.core.errors import InputError
from simulator.core.fileio import atomic_output, check_input_file
from simulator.core.progress import Counter, Progress
from simulator.media.gridfile import load_grid
from simulator.media.source import Source
from simulator.preprocess.common import frame_range
from simulator.preprocess.ego import EgoRows
from simulator.preprocess.sphere import SphereConfig, field_from_video

__all__ = ["EGO_COLUMNS", "EgoTable", "camera_rotation", "write_ego_csv"]

EGO_COLUMNS: tuple[str, ...] = (
    "frame", "time_s", "omega_x_dps", "omega_y_dps", "omega_z_dps",
    "yaw_rate_dps", "pitch_rate_dps", "roll_rate_dps", "rotation_dps", "confidence",
)  # fmt: skip


@dataclass(frozen=True)
class EgoTable:
    """``frame`` (T,) int, ``time_s`` (T,), ``omega_dps`` (T, 3) world frame,
    ``confidence`` (T,), and where it came from (``source``)."""

    frame: NDArray[np.int64]
    time_s: NDArray[np.float64]
    omega_dps: NDArray[np.float64]
    confidence: NDArray[np.float64]
    source: str = ""

    def rates_dps(self) -> NDArray[np.float64]:
        """``(T, 3)`` yaw, pitch and roll rates (deg/s, module docstring)."""
        w = self.omega_dps
        return np.column_stack([w[:, 1], -w[:, 0], -w[:, 2]])


class _Discard:
    """A field sink that keeps nothing but the count (``vimsim ego`` needs no field)."""

    def __init__(self):
        self.n_rows = 0

    def append(self, _f) -> None:
        self.n_rows += 2 if self.n_rows == 0 else 1


def _from_grid(p: Path) -> EgoTable:
    g = load_grid(p)
    if "ego_omega_dps" not in g.extras:
        raise InputError(
            f"{p}: grid has no per-frame camera rotation (made before vimsim estimated it, "
            "or in paper mode); re-run vimsim preprocess VIDEO -o GRID.npz --method sphere, "
            "or give vimsim ego the video"
        )
    start = int(g.meta.get("start_frame") or 0)
    frames = start + np.arange(g.n_frames)
    times = g.meta.get("frame_times_s")  # a variable-rate video's (player's clock)
    ok = times is not None and len(times) >= g.n_frames
    return EgoTable(
        frames,
        np.asarray(times[: g.n_frames], np.float64) if ok else frames / g.fps,
        g.extras["ego_omega_dps"].astype(np.float64),
        g.extras["ego_confidence"].astype(np.float64),
        str(p),
    )


def camera_rotation(
    source,
    *,
    layout: str | None = None,
    eye: str = "left",
    start_s: float = 0.0,
    end_s: float | None = None,
    flow: str = "dis",
    config: SphereConfig = SphereConfig(),
    progress: Progress | None = None,
) -> EgoTable:
    """The camera's angular velocity per frame of a video (sphere mode's estimate,
    nothing else kept: memory flat in the video's length) or read from a sphere-mode
    grid file (``.npz`` made by ``vimsim preprocess --method sphere``). ``source``: a
    :class:`simulator.media.source.Source` (any projection, its eye) or a path (opened with
    ``layout`` and ``eye``; equirect unless the file's metadata says otherwise)."""
    if not isinstance(source, Source):
        p = check_input_file(source, "video or grid")
        if zipfile.is_zipfile(p):
            return _from_grid(p)
        source = Source.open(p, layout=layout, eye=eye)
    info, p = source.info, source.path
    if not info.is_video:
        raise InputError(f"{p}: is a still image; vimsim ego needs a video with at least 2 frames")
    f0, f1 = frame_range(info, float(start_s), end_s, str(p))
    bar = Counter(progress, f1 - f0)
    ego = EgoRows(_Discard())
    try:
        field_from_video(
            source, config, start=f0, end=f1, flow=flow,
            progress=lambda n: bar.update(n - bar.done), sink=_Discard(), ego=ego,
        )  # fmt: skip
    finally:
        bar.close()
    arr = ego.arrays()
    frames = f0 + np.arange(len(arr["ego_confidence"]))
    return EgoTable(
        frames,
        info.times_s(frames),  # the stream's timestamps (player's clock)
        arr["ego_omega_dps"].astype(np.float64),
        arr["ego_confidence"].astype(np.float64),
        str(p),
    )


def write_ego_csv(path: str | os.PathLike, table: EgoTable) -> None:
    """Write the table (:data:`EGO_COLUMNS`) atomically."""
    rates = table.rates_dps()
    mag = np.linalg.norm(table.omega_dps, axis=1)
    cols = [table.time_s, *table.omega_dps.T, *rates.T, mag, table.confidence]
    buf = io.StringIO()
    buf.write(",".join(EGO_COLUMNS) + "\n")
    for i, fr in enumerate(table.frame):
        buf.write(f"{int(fr)}," + ",".join(f"{round(float(c[i]), 6) + 0.0:.10g}" for c in cols) + "\n")
    with atomic_output(path) as tmp:
        Path(tmp).write_text(buf.getvalue())
