"""The authors' per-window CSV layout (Cao et al.'s Unity project): read such a folder into a grid file, write a paper-mode grid into one.

One CSV per window, ``horizontal_<yaw>_vertical_<pitch>.csv`` (centres in degrees, yaw +
right, pitch + up), holding a header line ``,0`` then ``frame,value`` rows from frame 0
(the mean flow magnitude in window px/frame); beside them ``percentileData.csv``: two
lines, the opacity scale's low and high px/frame (``0.18`` and ``53.73`` in their data).
Values are written as the shortest decimal that reads back to the grid's float32, so
import -> export -> import is exact.
"""

from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from simulator.core.errors import InputError
from simulator.core.fileio import OutputFolder, atomic_output
from simulator.media.gridfile import GridFile, load_grid, save_grid
from simulator.sphere.windows import WindowGrid, grid_preset

__all__ = ["PERCENTILE_FILE", "RUNTIME_FILES", "CaoFolder", "export_cao_csv", "import_cao_csv", "read_cao_folder",
           "window_file_name"]  # fmt: skip

PERCENTILE_FILE = "percentileData.csv"
#: The rule's runtimes written beside the CSVs: ``name -> package folder`` (C# for Unity, an ES
#: module for web players; no engine dependency).
RUNTIME_FILES = {"VimsimCao2021.cs": "export/unity", "vimsim_cao2021.js": "export/web"}
_NAME = re.compile(r"^horizontal_(-?\d+(?:\.\d+)?)_vertical_(-?\d+(?:\.\d+)?)\.csv$")


def _deg_text(v: float) -> str:
    """A centre in a file name: ``-180``, ``7.5`` (never ``-0``)."""
    v = float(v) + 0.0
    return f"{v:g}" if v != 0 else "0"


def window_file_name(yaw_deg: float, pitch_deg: float) -> str:
    """``horizontal_<yaw>_vertical_<pitch>.csv`` of a window centre (degrees)."""
    return f"horizontal_{_deg_text(yaw_deg)}_vertical_{_deg_text(pitch_deg)}.csv"


def _value_text(v: np.float32) -> str:
    return np.format_float_positional(np.float32(v), unique=True, trim="0")


@dataclass(frozen=True)
class CaoFolder:
    """A folder read by :func:`read_cao_folder`: ``pof_px`` float32 (T, P, Y), centres in
    degrees (``yaw_deg`` increasing in [-180, 180), ``pitch_deg`` increasing), their steps,
    and the percentile file's ``(low, high)`` px/frame (None without one)."""

    pof_px: NDArray[np.float32]
    yaw_deg: NDArray[np.float64]
    pitch_deg: NDArray[np.float64]
    yaw_step_deg: float
    pitch_step_deg: float
    percentiles_px: tuple[float, float] | None


def _number(text: str, where: str, what: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise InputError(f"{where}: {what} {text[:40]!r} is not a number") from None
    if not math.isfinite(v) or v < 0:
        raise InputError(f"{where}: {what} {text[:40]!r} must be a finite number >= 0")
    return v


def _read_window(path: Path) -> NDArray[np.float32]:
    """The rows of one window file: header ``,0`` then ``frame,number`` with frames 0..N-1."""
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except (OSError, UnicodeDecodeError) as e:
        raise InputError(f"{path}: cannot read as text ({type(e).__name__})") from None
    rows = [(i + 1, ln.strip()) for i, ln in enumerate(lines) if ln.strip()]
    if not rows or rows[0][1].replace(" ", "") != ",0":
        raise InputError(f"{path}: first line must be the header ',0'")
    vals = []
    for lineno, ln in rows[1:]:
        parts = ln.split(",")
        where = f"{path}, line {lineno}"
        if len(parts) != 2 or not re.fullmatch(r"\d+", parts[0].strip()):
            raise InputError(f"{where}: expected 'frame,number'; got {ln[:40]!r}")
        if int(parts[0]) != len(vals):
            raise InputError(
                f"{where}: frame {int(parts[0])} where frame {len(vals)} was expected "
                "(frames must be 0..N-1 in order)"
            )
        vals.append(_number(parts[1].strip(), where, "value"))
    if not vals:
        raise InputError(f"{path}: no 'frame,number' rows after the header")
    return np.asarray(vals, np.float32)


def _steps(centres: list[float], what: str, folder: Path, full_circle: bool) -> float:
    d = np.diff(np.asarray(centres, float))
    if len(centres) < 2:
        if full_circle:
            raise InputError(
                f"{folder}: one {what} centre only; the yaw windows must go round 360 deg"
            )
        return 15.0
    step = float(d[0])
    if np.abs(d - step).max() > 1e-6 or (full_circle and abs(step * len(centres) - 360) > 1e-6):
        span = "evenly spaced round 360 deg" if full_circle else "evenly spaced"
        raise InputError(f"{folder}: {what} centres {centres[:6]} are not {span}")
    return step


def read_cao_folder(folder: str | os.PathLike) -> CaoFolder:
    """Read a folder in the authors' layout (any window grid its file names declare).

    InputError (one line naming the file) for: no window files, a window of the declared
    yaw x pitch grid missing, a header other than ``,0``, a row not ``frame,number``,
    frames not 0..N-1 in order, windows of unequal length, a bad percentile file.
    """
    d = Path(folder)
    if not d.is_dir():
        raise InputError(
            f"{d}: not a folder of window CSVs (horizontal_<yaw>_vertical_<pitch>.csv)"
        )
    found: dict[tuple[float, float], Path] = {}
    for f in sorted(d.iterdir()):
        m = _NAME.match(f.name)
        if not m:
            continue
        yaw = (float(m.group(1)) + 180.0) % 360.0 - 180.0  # 180 and -180 are one window
        key = (yaw, float(m.group(2)))
        if key in found or not (-90.0 <= key[1] <= 90.0):
            raise InputError(
                f"{f}: window yaw {key[0]:g} pitch {key[1]:g} is a duplicate or beyond the poles"
            )
        found[key] = f
    if not found:
        raise InputError(f"{d}: no window files horizontal_<yaw>_vertical_<pitch>.csv")
    yaws = sorted({k[0] for k in found})
    pitches = sorted({k[1] for k in found})
    for p in pitches:
        for y in yaws:
            if (y, p) not in found:
                raise InputError(
                    f"{d / window_file_name(y, p)}: missing; the folder declares yaw "
                    f"{_deg_text(yaws[0])}..{_deg_text(yaws[-1])} x pitch "
                    f"{_deg_text(pitches[0])}..{_deg_text(pitches[-1])}"
                )
    ys = _steps(yaws, "yaw", d, True)
    ps = _steps(pitches, "pitch", d, False)
    cols = {}
    for (y, p), f in found.items():
        cols[(y, p)] = _read_window(f)
    n0 = len(cols[(yaws[0], pitches[0])])
    for (y, p), v in cols.items():
        if len(v) != n0:
            raise InputError(
                f"{found[(y, p)]}: {len(v)} frames; {found[(yaws[0], pitches[0])].name} has "
                f"{n0} (windows of unequal length)"
            )
    pof = np.empty((n0, len(pitches), len(yaws)), np.float32)
    for (y, p), v in cols.items():
        pof[:, pitches.index(p), yaws.index(y)] = v
    return CaoFolder(pof, np.asarray(yaws), np.asarray(pitches), ys, ps, _read_percentiles(d))


def _read_percentiles(d: Path) -> tuple[float, float] | None:
    f = d / PERCENTILE_FILE
    if not f.exists():
        return None
    try:
        lines = [ln.strip() for ln in f.read_text(encoding="utf-8").splitlines() if ln.strip()]
    except (OSError, UnicodeDecodeError) as e:
        raise InputError(f"{f}: cannot read as text ({type(e).__name__})") from None
    if len(lines) != 2:
        raise InputError(f"{f}: expected two lines (low and high px/frame); got {len(lines)}")
    lo, hi = (_number(t, str(f), "value") for t in lines)
    if not lo < hi:
        raise InputError(f"{f}: low {lo:g} must be below high {hi:g} px/frame")
    return lo, hi


def import_cao_csv(
    folder: str | os.PathLike,
    output: str | os.PathLike,
    *,
    fps: float,
    hfov_deg: float | None = None,
    vfov_deg: float | None = None,
    size: tuple[int, int] | None = None,
) -> GridFile:
    """Read ``folder`` (:func:`read_cao_folder`) and write the grid file ``output``.

    The window FOV and size default to the ``cao2021`` preset's (107 x 96.3 deg, 1600 x
    1440 px). ``pof_px`` holds the files' values; ``pof_dps`` converts them at the window's
    centre pixel pitch, ``value * hfov / width * fps`` (an approximation: their files carry
    px/frame only). ``meta["cao"]`` records the folder and the percentile file."""
    if not (isinstance(fps, (int, float)) and math.isfinite(fps) and fps > 0):
        raise InputError(f"--fps must be frames per second > 0; got {fps!r}")
    c = read_cao_folder(folder)
    pre = grid_preset("cao2021", hfov_deg=hfov_deg, vfov_deg=vfov_deg, size=size)
    grid = WindowGrid(yaw_step_deg=c.yaw_step_deg, pitch_step_deg=c.pitch_step_deg,
                      pitch_min_deg=float(c.pitch_deg[0]), pitch_max_deg=float(c.pitch_deg[-1]),
                      yaw_start_deg=float(c.yaw_deg[0]), hfov_deg=pre.hfov_deg,
                      vfov_deg=pre.vfov_deg, size=pre.size)  # fmt: skip
    if not (np.allclose(grid.yaw_deg, c.yaw_deg) and np.allclose(grid.pitch_deg, c.pitch_deg)):
        raise InputError(f"{folder}: window centres do not form a regular grid")
    T = c.pof_px.shape[0]
    dps = c.pof_px.astype(np.float64) * (grid.hfov_deg / grid.size[0]) * float(fps)
    meta = {
        "fps": float(fps),
        "n_frames": T,
        "flow": {"method": "imported", "source": "cao-csv", "units": "px/frame (pof_px)"},
        "layout": "mono",
        "eye": "left",
        "video": {"path": "", "n_frames": T},
        "cao": {
            "folder": str(folder),
            "percentiles_px": c.percentiles_px,
            "pof_dps": "pof_px * hfov_deg / width * fps (centre pixel pitch)",
        },
    }
    save_grid(output, dps, c.pof_px, grid, meta)
    return load_grid(output)


def export_cao_csv(
    grid: str | os.PathLike | GridFile, out_dir: str | os.PathLike, *,
    percentiles_px: tuple[float, float],
) -> list[Path]:  # fmt: skip
    """Write a paper-mode grid's ``pof_px`` in the authors' layout into ``out_dir`` (one
    file per window, values as float32's shortest decimals) and ``percentileData.csv``
    with ``percentiles_px``. A sphere-mode grid is refused (their runtime reads windows
    measured one by one). Returns the files written (the folder keeps its manifest)."""
    g = grid if isinstance(grid, GridFile) else load_grid(grid)
    if g.field_dps is not None or g.meta.get("method") == "sphere":
        raise InputError(
            f"{g.path or 'grid'}: a sphere-mode grid; --format cao-csv needs a paper-mode grid "
            "(vimsim preprocess --method paper, or vimsim grid import)"
        )
    lo, hi = (float(v) for v in percentiles_px)
    if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
        raise InputError(f"cao-csv percentiles must be finite, low < high; got {lo}, {hi}")
    names = {
        window_file_name(y, p): (i, j)
        for i, p in enumerate(g.pitch_deg) for j, y in enumerate(g.yaw_deg)
    }  # fmt: skip
    inputs = [g.path] if g.path else []
    folder = OutputFolder(out_dir, [*names, PERCENTILE_FILE, *RUNTIME_FILES],
                          "export --format cao-csv")  # fmt: skip
    out = folder.prepare(inputs)
    for name, (i, j) in names.items():
        col = g.pof_px[:, i, j]
        text = ",0\n" + "".join(f"{k},{_value_text(v)}\n" for k, v in enumerate(col))
        with atomic_output(out / name) as t:
            t.write_text(text, encoding="utf-8")
    with atomic_output(out / PERCENTILE_FILE) as t:
        t.write_text(f"{_value_text(lo)}\n{_value_text(hi)}\n", encoding="utf-8")
    for name, pkg in RUNTIME_FILES.items():
        with atomic_output(out / name) as t:
            t.write_bytes(runtime_source(name, pkg))
    folder.complete()
    return [out / n for n in [*names, PERCENTILE_FILE, *RUNTIME_FILES]]


def runtime_source(name: str, pkg: str) -> bytes:
    """The bytes of one of :data:`RUNTIME_FILES` (package data)."""
    from importlib.resources import files

    return files("simulator").joinpath(pkg, name).read_bytes()
