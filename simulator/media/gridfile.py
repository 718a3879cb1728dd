"""The grid file: the per-window optical-flow matrix of a video (the paper's POF matrix).

A ``.npz`` (no pickles; loaded with ``allow_pickle=False``) holding

``pof_dps`` : float32, shape (T, P, Y)
    Perceived optical flow of each window for frame t in **deg/s of visual angle**: the
    solid-angle-weighted mean over the window of the angle between the ray of a pixel
    and the ray of its flow target, times fps. Frame t is the flow from frame t-1 to t;
    frame 0 repeats frame 1.
``pof_px`` : float32, shape (T, P, Y)
    The paper's measure: mean flow magnitude in window pixels per frame.
``yaw_deg`` : float64, shape (Y,); ``pitch_deg`` : float64, shape (P,)
    Window centres in degrees (yaw + right, pitch + up; windows have no roll).
``meta`` : 0-d str array, a JSON object with at least ``format``
    (:data:`FORMAT`), ``version`` (:data:`VERSION`), ``grid`` (a
    :class:`~simulator.sphere.windows.WindowGrid` dict: steps, pitch range, ``hfov_deg``,
    ``vfov_deg``, window ``size``), ``fps``, ``n_frames``, ``flow`` (method and
    parameters), ``layout``, ``eye``, ``video`` (``path``, ``width``, ``height``,
    ``sar``, ``content_hash``).

Optional (sphere mode): ``field_dps`` float16/float32 (T, n_lat, n_lon), the per-frame
angular-speed field on a lon/lat grid, described by ``meta["field"]``; and (sphere-mode
grids recording the camera's rotation, described by ``meta["ego"]``) ``field_trans_dps`` (the same
field with the camera rotation removed), ``ego_omega_dps`` float32 (T, 3) (the camera's
angular velocity, deg/s, world frame) and ``ego_confidence`` float32 (T,).
"""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
import zipfile
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from simulator.core.errors import InputError
from simulator.core.fileio import atomic_output, check_input_file
from simulator.media.gridcheck import check_ego, check_headers, check_meta, check_values
from simulator.media.lazyfield import LazyField
from simulator.sphere.cells import CellGrid
from simulator.sphere.windows import WindowGrid

__all__ = [
    "FORMAT", "VERSION", "FieldSpool", "GridFile", "check_field_values", "content_hash", "load_grid",
    "save_grid",
]

FORMAT = "vimsim-grid"
VERSION = 1
_REQUIRED_META = ("format", "version", "grid", "fps", "n_frames", "flow", "layout", "eye", "video")


@dataclass(frozen=True)
class GridFile:
    """A loaded grid file (see the module docstring for the arrays and their units)."""

    pof_dps: NDArray[np.float32]
    pof_px: NDArray[np.float32]
    yaw_deg: NDArray[np.float64]
    pitch_deg: NDArray[np.float64]
    meta: dict
    path: str = ""
    field_dps: NDArray | LazyField | None = field(default=None, repr=False)  # lazy when loaded
    field_trans_dps: NDArray | LazyField | None = field(default=None, repr=False)
    #: small per-frame arrays: ``ego_omega_dps`` (T, 3), ``ego_confidence`` (T,)
    extras: dict = field(default_factory=dict, repr=False)

    @property
    def grid(self) -> WindowGrid:
        return WindowGrid.from_dict(self.meta["grid"])

    @property
    def fps(self) -> float:
        return float(self.meta["fps"])

    @property
    def n_frames(self) -> int:
        return int(self.pof_dps.shape[0])

    @property
    def hfov_deg(self) -> float:
        return float(self.meta["grid"]["hfov_deg"])

    @property
    def vfov_deg(self) -> float:
        return float(self.meta["grid"]["vfov_deg"])

    def frame_times_s(self) -> NDArray[np.float64]:
        """Time of each grid row, seconds from the grid's first row (``t / fps``, or the
        stream's timestamps of a variable-rate video, ``meta["frame_times_s"]``, less the
        first; the rows' times on the player's clock: :func:`simulator.epof.overlaps._frames`)."""
        times = self.meta.get("frame_times_s")
        if times is not None and len(times) == self.n_frames:
            return np.asarray(times, float) - float(times[0])
        return np.arange(self.n_frames) / self.fps

    def check_video(
        self, info, *, source: str | None = None, frames: tuple[int, int] | None = None
    ) -> None:
        """Raise InputError unless this grid was made from the video described by ``info``
        (a :class:`simulator.media.video.MediaInfo`): same stored size and frame rate, and a
        frame count within one frame (container headers and decoders may differ by one); the
        size is not checked for a grid that does not record it (`vimsim grid import`).

        ``frames = (f0, f1)``: only video frames ``f0 <= i < f1`` are needed (a rendered
        time range), so a grid made with ``preprocess --start/--end`` covering them is
        accepted; default: the grid must cover the whole video."""
        v = self.meta["video"]
        src = source or self.path
        sized = "width" in v and "height" in v  # an imported grid (grid import) has no size
        if sized and (int(v["width"]), int(v["height"])) != (info.width, info.height):
            raise InputError(
                f"{src}: grid was made from a {v['width']}x{v['height']} video, not this "
                f"{info.width}x{info.height} one ({info.path}); run vimsim preprocess on it"
            )
        if abs(float(self.meta["fps"]) - info.fps) > 1e-3 * info.fps:
            raise InputError(
                f"{src}: grid is for a {self.meta['fps']} fps video; {info.path} is {info.fps:g} fps"
            )
        n_video = int(v.get("n_frames", self.meta["n_frames"]))
        if abs(n_video - info.n_frames) > 1:
            raise InputError(
                f"{src}: grid was made from a video of {n_video} frames; {info.path} has {info.n_frames}: made from another video?"
            )
        want = v.get("content_hash")
        if want and Path(info.path).is_file() and content_hash(info.path) != want:
            raise InputError(
                f"{src}: grid was made from another video than {info.path} (content hash differs); "
                f"run vimsim preprocess on it"
            )
        start, end = int(self.meta.get("start_frame", 0)), int(self.meta.get("end_frame", n_video))
        if frames is not None:
            f0, f1 = int(frames[0]), int(frames[1])
            # The last row of a grid may be missing (flow needs a next frame): one frame of slack.
            if start > f0 or start + self.n_frames < min(f1, n_video) - 1:
                raise InputError(
                    f"{src}: grid covers frames {start}..{start + self.n_frames} of {info.path}; "
                    f"the range needs frames {f0}..{f1}: preprocess that range (or the whole video)"
                )
            return
        if start != 0 or self.n_frames < n_video - 1:
            raise InputError(
                f"{src}: grid covers frames {start}..{end} of {info.path} only (made with --start/--end); "
                f"this needs a grid of the whole video"
            )


class FieldSpool:
    """Per-frame fields ``(n_lat, n_lon)`` float32 streamed to an anonymous temporary file
    beside the output as they are made (memory flat in the video's length; the file has no
    name, so nothing is left even after ``kill -9``). Row 0 repeats row 1 (frame 0 has no
    predecessor). :func:`save_grid` copies it into the grid file chunk by chunk."""

    def __init__(self, shape: tuple[int, int], directory: str | os.PathLike = "."):
        self.shape = (int(shape[0]), int(shape[1]))
        self._fh = tempfile.TemporaryFile(dir=directory)  # noqa: SIM115 - closed by close()
        self.n_rows = 0
        self.finite = True

    def append(self, f: NDArray) -> None:
        row = np.ascontiguousarray(f, np.float32).reshape(self.shape)
        self.finite = self.finite and bool(np.all(np.isfinite(row)))
        b = row.tobytes()
        self._fh.write(b + b if self.n_rows == 0 else b)  # row 0 = row 1
        self.n_rows += 2 if self.n_rows == 0 else 1

    def chunks(self, rows: int = 256):
        """The rows in order, ``(<= rows, n_lat, n_lon)`` float32 arrays."""
        self._fh.flush()
        self._fh.seek(0)
        size = self.shape[0] * self.shape[1] * 4
        while b := self._fh.read(rows * size):
            yield np.frombuffer(b, np.float32).reshape(-1, *self.shape)

    def close(self) -> None:
        self._fh.close()


def _write_npz(fh, arrays: dict, spools: dict) -> None:
    """``np.savez_compressed``'s layout, with each ``name: (spool, dtype)`` of ``spools``
    copied from its :class:`FieldSpool` chunk by chunk."""
    with zipfile.ZipFile(fh, "w", zipfile.ZIP_DEFLATED, allowZip64=True) as zf:
        for k, a in arrays.items():
            with zf.open(k + ".npy", "w", force_zip64=True) as f:
                np.lib.format.write_array(f, np.asanyarray(a), allow_pickle=False)
        for name, (spool, dtype) in spools.items():
            header = {
                "descr": np.lib.format.dtype_to_descr(np.dtype(dtype)),
                "fortran_order": False,
                "shape": (spool.n_rows, *spool.shape),
            }
            with zf.open(name + ".npy", "w", force_zip64=True) as f:
                np.lib.format.write_array_header_1_0(f, header)
                for c in spool.chunks():
                    f.write(c.astype(dtype).tobytes())


def save_grid(
    path: str | os.PathLike,
    pof_dps: NDArray,
    pof_px: NDArray,
    grid: WindowGrid,
    meta: dict,
    *,
    field_dps: NDArray | None = None,
    field_trans_dps: NDArray | None = None,
    extras: dict | None = None,
) -> None:
    """Write a grid file atomically (temporary name, renamed when complete).

    ``meta`` is completed with ``format``, ``version`` and ``grid``; it must already
    hold ``fps``, ``n_frames``, ``flow``, ``layout``, ``eye`` and ``video``.
    ``field_dps`` and ``field_trans_dps``: an array or ``(FieldSpool, dtype)``;
    ``extras``: more small arrays by name (``ego_omega_dps``, ``ego_confidence``).
    """
    pof_dps = np.asarray(pof_dps, np.float32)
    pof_px = np.asarray(pof_px, np.float32)
    P, Y = grid.shape
    if pof_dps.ndim != 3 or pof_dps.shape[1:] != (P, Y) or pof_px.shape != pof_dps.shape:
        raise ValueError(
            f"pof arrays must be (T, {P}, {Y}); got {pof_dps.shape} and {pof_px.shape}"
        )
    m = dict(meta)
    m.update(format=FORMAT, version=VERSION, grid=grid.to_dict())
    missing = [k for k in _REQUIRED_META if k not in m]
    if missing:
        raise ValueError(f"grid meta lacks {missing}")
    arrays = {
        "pof_dps": pof_dps,
        "pof_px": pof_px,
        "yaw_deg": np.asarray(grid.yaw_deg, np.float64),
        "pitch_deg": np.asarray(grid.pitch_deg, np.float64),
        "meta": np.array(json.dumps(m, sort_keys=True)),
        **{k: np.asarray(v) for k, v in (extras or {}).items()},
    }
    spools = {}
    for name, f in (("field_dps", field_dps), ("field_trans_dps", field_trans_dps)):
        if isinstance(f, tuple) and isinstance(f[0], FieldSpool):
            spools[name] = f
        elif f is not None:
            arrays[name] = np.asarray(f)
    with atomic_output(path) as tmp, open(tmp, "wb") as fh:
        if spools:
            _write_npz(fh, arrays, spools)
        else:
            np.savez_compressed(fh, **arrays)


def load_grid(path: str | os.PathLike, *, scan: bool = True) -> GridFile:
    """Read and validate a grid file; InputError (one line) if it is not a vimsim grid
    of this version or its arrays are inconsistent.

    ``scan=False`` leaves out the pass over the sphere fields' values (finite, >= 0: a
    decompression of each); the caller checks them with :func:`check_field_values` (e.g.
    once they are read into memory) or knows them checked."""
    p = check_input_file(path, "grid")
    if not zipfile.is_zipfile(p):
        raise InputError(f"{p}: not a vimsim grid file (expected a .npz made by vimsim preprocess)")
    need = {"pof_dps", "pof_px", "yaw_deg", "pitch_deg", "meta"}
    check_headers(p, need)
    try:
        with np.load(p, allow_pickle=False) as z:
            names = set(z.files)
            if not need <= names:
                raise InputError(
                    f"{p}: not a vimsim grid file; arrays {sorted(need - names)} missing"
                )
            # The field stays in the file: read lazily, chunk by chunk (memory flat in T).
            arrs = {k: z[k] for k in names if k not in _LAZY}
        for k in _LAZY:
            if k in names:
                arrs[k] = LazyField(p, k + ".npy")
    except InputError:
        raise
    except (zipfile.BadZipFile, zlib.error, ValueError, OSError, EOFError, MemoryError) as e:
        raise InputError(
            f"{p}: not a vimsim grid file (.npz expected): {type(e).__name__}"
        ) from None
    m = arrs["meta"]
    if m.ndim != 0 or m.dtype.kind != "U":
        raise InputError(f"{p}: grid meta is not a JSON string; not a vimsim grid file")
    try:
        meta = json.loads(str(m))
    except (json.JSONDecodeError, TypeError, RecursionError):
        raise InputError(
            f"{p}: grid meta is not JSON (or nested too deeply); not a vimsim grid file"
        ) from None
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        fmt = meta.get("format") if isinstance(meta, dict) else None
        raise InputError(f"{p}: not a vimsim grid file (format {str(fmt)[:40]!r})")
    if meta.get("version") != VERSION:
        raise InputError(
            f"{p}: grid file version {str(meta.get('version'))[:20]}; this vimsim reads version {VERSION}: re-run vimsim preprocess"
        )
    missing = [k for k in _REQUIRED_META if k not in meta]
    if missing:
        raise InputError(f"{p}: grid meta lacks {missing}")
    check_meta(p, meta)
    for k in (
        "pof_dps",
        "pof_px",
        "yaw_deg",
        "pitch_deg",
        *(["field_dps"] if "field_dps" in arrs else []),
    ):
        if arrs[k].dtype.kind != "f":
            raise InputError(
                f"{p}: {k} has dtype {arrs[k].dtype}; expected real floating point numbers"
            )
    dps, px = arrs["pof_dps"], arrs["pof_px"]
    yaw, pitch = arrs["yaw_deg"], arrs["pitch_deg"]
    for k, a, lo, hi in (("yaw_deg", yaw, -180.0, 360.0), ("pitch_deg", pitch, -90.0, 90.0)):
        if a.ndim != 1 or a.size < 1:
            raise InputError(f"{p}: {k} has shape {a.shape}; expected a non-empty 1-D array")
        if not np.all(np.isfinite(a)) or a.min() < lo or a.max() > hi:
            raise InputError(f"{p}: {k} has values outside [{lo:g}, {hi:g}] deg or non-finite")
        if a.size > 1 and not np.all(np.diff(a) > 0):
            raise InputError(f"{p}: {k} is not strictly increasing")
    Y, P = yaw.shape[0], pitch.shape[0]
    if dps.ndim != 3 or dps.shape[1:] != (P, Y) or px.shape != dps.shape:
        raise InputError(
            f"{p}: pof arrays have shape {dps.shape}/{px.shape}; expected (T, {P}, {Y})"
        )
    for k, a in (("pof_dps", dps), ("pof_px", px)):
        if a.shape[0] < 1 or not np.all(np.isfinite(a)):
            raise InputError(f"{p}: {k} is empty or has non-finite values")
        if a.min() < 0:
            raise InputError(
                f"{p}: {k} has negative values ({float(a.min()):.3g}); flow magnitudes are >= 0"
            )
    if "field_dps" in arrs and scan:
        check_values(p, "field_dps", arrs["field_dps"])
    extras = check_ego(p, arrs, dps.shape[0], scan)
    try:
        WindowGrid.from_dict(meta["grid"])
    except (TypeError, KeyError, ValueError, AttributeError, InputError) as e:
        raise InputError(f"{p}: grid description in meta is invalid ({type(e).__name__})") from None
    return GridFile(
        pof_dps=dps.astype(np.float32, copy=False),
        pof_px=px.astype(np.float32, copy=False),
        yaw_deg=arrs["yaw_deg"].astype(np.float64),
        pitch_deg=arrs["pitch_deg"].astype(np.float64),
        meta=meta,
        path=str(p),
        field_dps=arrs.get("field_dps"),
        field_trans_dps=arrs.get("field_trans_dps"),
        extras=extras,
    )


#: Arrays read lazily (chunk by chunk) from a grid file.
_LAZY = ("field_dps", "field_trans_dps")
def check_field_values(grid: GridFile) -> None:
    """The value checks :func:`load_grid` ``(scan=False)`` left out, on the grid's fields
    as they are now (in memory: no decompression)."""
    for name in _LAZY:
        f = getattr(grid, name)
        if f is not None:
            check_values(grid.path, name, f)


def content_hash(
    path: str | os.PathLike, *, chunk: int = 1 << 20, max_bytes: int = 64 << 20
) -> str:
    """SHA-256 of a file's first ``max_bytes`` and its size (fast for long videos).

    Returns ``"sha256:<hex>"``; identifies the source video of a grid.
    """
    p = Path(path)
    h = hashlib.sha256()
    size = p.stat().st_size
    h.update(str(size).encode())
    with open(p, "rb") as f:
        read = 0
        while read < max_bytes:
            b = f.read(min(chunk, max_bytes - read))
            if not b:
                break
            h.update(b)
            read += len(b)
    return "sha256:" + h.hexdigest()


# ---------------------------------------------------------------- sphere-mode field
#: How a user makes a grid with a field; quoted by every "no field" error.
MAKE_FIELD_HINT = "vimsim preprocess VIDEO -o GRID.npz --method sphere"


def cells_from_meta(meta: dict, *, source: str = "grid") -> CellGrid:
    """The :class:`CellGrid` described by ``meta["field"]``; InputError if absent/invalid."""
    fm = meta.get("field") if isinstance(meta, dict) else None
    if not isinstance(fm, dict) or "cell_deg" not in fm:
        raise InputError(
            f"{source}: grid has no sphere-mode field; make one with `{MAKE_FIELD_HINT}`"
        )
    return CellGrid(float(fm["cell_deg"]))


def require_field(grid_file) -> tuple[NDArray[np.float32] | LazyField, CellGrid]:
    """``(field_dps (T, n_lat, n_lon), cells)`` of a loaded grid file: the grid file's
    :class:`~simulator.media.lazyfield.LazyField` (read chunk by chunk; its chunks are float32)
    or, for a field given in memory, a float32 array.

    Raises InputError (one line, with the command that makes one) if the grid has no
    field, e.g. a paper-mode grid.
    """
    src = getattr(grid_file, "path", "") or "grid"
    f = getattr(grid_file, "field_dps", None)
    if f is None:
        raise InputError(
            f"{src}: grid has no sphere-mode field (made in paper mode?); make one with `{MAKE_FIELD_HINT}`"
        )
    cells = cells_from_meta(grid_file.meta, source=src)
    if not isinstance(f, LazyField):
        f = np.asarray(f)
    if f.ndim != 3 or tuple(f.shape[1:]) != cells.shape:
        raise InputError(
            f"{src}: field_dps has shape {tuple(f.shape)}; expected (T, {cells.shape[0]}, {cells.shape[1]}) for {cells.cell_deg} deg cells"
        )
    if isinstance(f, LazyField):
        return f.with_dtype(np.float32), cells  # validated (finite, >= 0) by load_grid
    if not np.all(np.isfinite(f)):
        raise InputError(f"{src}: field_dps has non-finite values")
    return f.astype(np.float32, copy=False), cells
