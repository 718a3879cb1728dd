"""The Unity export: ``vimsim_epof.bin`` (the POF matrix or the sphere-mode field with a JSON
header) and the C# runtime that computes from it the same EPOF as ``vimsim epof``.

Binary layout (little-endian; ``docs/unity.md``)
------------------------------------------------
======  =====  ==============================================================
offset  bytes  content
======  =====  ==============================================================
0       8      ASCII ``VIMSIMEP``
8       4      uint32 format version (:data:`VERSION`)
12      4      uint32 ``H``: length of the JSON header in bytes
16      H      UTF-8 JSON header, padded with spaces so that 16 + H is a multiple of 16
16 + H  ...    ``data``: ``prod(shape)`` float16 or float32 values, C order; nothing after
======  =====  ==============================================================

``data`` is ``(T, P, Y)`` window POFs in deg/s (paper mode, the grid file's ``pof_dps``) or
``(T, n_lat, n_lon)`` cells in deg/s (sphere mode, the grid file's ``field_dps``); row ``t``
is video frame ``start_frame + t``. The header says which, and holds everything the runtime
needs (grid, viewport FOV, table parameters, opacity thresholds and rule, frame rate,
source video hash). Conventions as everywhere (SPEC.md): degrees; yaw + right, pitch + up,
roll + right ear down, applied yaw, pitch, roll (intrinsic); a time ``t`` (seconds from the
video start) shows frame ``floor(t * fps + 1e-6)`` (:func:`frame_at`).
"""

from __future__ import annotations

import contextlib
import importlib.resources
import inspect
import json
import math
import os
import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from simulator import __version__
from simulator.core.errors import InputError
from simulator.core.fileio import atomic_output, check_input_file, check_output_dir
from simulator.epof.exact import viewport_epof
from simulator.epof.overlaps import ViewportOverlaps, viewport_fov
from simulator.media.gridfile import GridFile, content_hash, load_grid, require_field
from simulator.mitigation.grf import OpacityRule

__all__ = [
    "CS_FILES",
    "DATA_FILE",
    "DTYPES",
    "FORMAT",
    "METHODS",
    "VERSION",
    "ExportResult",
    "export_unity",
    "frame_at",
    "read_export",
]

FORMAT = "vimsim-epof"
#: 2: the opacity rule gained ease-in / ease-out (``opacity.ease_in_s``, ``ease_out_s``).
VERSION = 2
MAGIC = b"VIMSIMEP"
#: The data file inside an export folder.
DATA_FILE = "vimsim_epof.bin"
#: The C# runtime (core, no UnityEngine) and the optional MonoBehaviour, copied beside it.
CS_FILES: tuple[str, ...] = ("VimsimEpof.cs", "VimsimEpofBehaviour.cs")
DTYPES: tuple[str, ...] = ("auto", "float16", "float32")
METHODS: tuple[str, ...] = ("auto", "paper", "sphere")
#: Tolerance (frames) of the time-to-frame rule: frame times computed as f / fps map to f.
FRAME_EPS = 1e-6
_PREFIX = 16
_CS_MARK = b"// vimsim export:"  # first line of every C# file vimsim writes
_FLOAT16_MAX = 65504.0


@dataclass(frozen=True)
class ExportResult:
    """What :func:`export_unity` wrote.

    ``files``: paths written; ``mode``: ``paper`` or ``sphere``; ``dtype`` and ``shape`` of
    the data; ``file_bytes``: size of ``vimsim_epof.bin``; ``grid_bytes``: size of the grid
    file; ``max_rel_error``: largest relative rounding of a data value against the values
    ``vimsim epof`` uses (0.0 when stored exactly; at most 2^-11 for float16).
    """

    out_dir: Path
    files: tuple[Path, ...]
    mode: str
    dtype: str
    shape: tuple[int, int, int]
    file_bytes: int
    grid_bytes: int
    max_rel_error: float
    header: dict


def _defaults(fn, names: tuple[str, ...]) -> dict:
    """Default values of ``fn``'s keyword parameters ``names``: the numbers ``vimsim epof``
    runs with, so the runtime builds the same tables."""
    sig = inspect.signature(fn)
    return {n: sig.parameters[n].default for n in names}


def _table_params() -> dict:
    """The :class:`~simulator.epof.ViewportOverlaps` table parameters ``epof_from_grid`` uses."""
    return _defaults(
        ViewportOverlaps,
        ("pitch_step_deg", "roll_step_deg", "yaw_step_deg", "rays", "lat_step_deg", "lon_step_deg"),
    )


def _is_ours(path: Path) -> bool:
    """Whether an existing file was written by ``vimsim export`` (so it may be replaced)."""
    try:
        with open(path, "rb") as f:
            head = f.read(len(_CS_MARK))
    except OSError:
        return False
    return head.startswith(MAGIC) if path.name == DATA_FILE else head == _CS_MARK


def _cs_source(name: str) -> bytes:
    return importlib.resources.files("simulator.export").joinpath("unity", name).read_bytes()


def export_unity(
    grid: GridFile | str | os.PathLike,
    out_dir: str | os.PathLike,
    *,
    method: str = "auto",
    dtype: str = "auto",
    hfov_deg: float | None = None,
    vfov_deg: float | None = None,
    rule: OpacityRule | None = None,
    cache_bins: int = 1024,
) -> ExportResult:
    """Write ``out_dir/vimsim_epof.bin`` and the C# runtime (:data:`CS_FILES`) for a grid.

    Parameters
    ----------
    grid : GridFile or path of a grid file (``vimsim preprocess``)
    out_dir : folder, created if needed; files vimsim did not write there are never replaced
    method : ``"paper"`` (window POFs, overlap weights), ``"sphere"`` (the field, exact
        integration; InputError if the grid has none) or ``"auto"``: sphere when the grid has
        a field, as ``vimsim epof``
    dtype : ``"float16"``, ``"float32"`` or ``"auto"`` (the precision ``vimsim epof`` uses:
        float32 for the POF matrix, the stored dtype of a field)
    hfov_deg, vfov_deg : float, degrees; viewport FOV, default the grid's window FOV
    rule : OpacityRule (default ``OpacityRule()``, the paper's 10th/90th percentiles, no
        easing; the CLI's default is :func:`simulator.mitigation.grf.comfort_rule`, as ``vimsim epof``);
        its thresholds are taken from the grid's flow (``source="grid"``); its smoothing and
        ease-in / ease-out times go into the header for the runtime's ``OpacityEasing``
    cache_bins : sphere mode: weight bins the runtime keeps (~16 kB each for 4 deg cells)

    Returns
    -------
    ExportResult
    """
    rule = OpacityRule() if rule is None else rule
    g = grid if isinstance(grid, GridFile) else load_grid(grid)
    src = g.path or "grid"
    if method not in METHODS:
        raise InputError(f"export method must be one of {', '.join(METHODS)}; got {method!r}")
    if dtype not in DTYPES:
        raise InputError(f"export dtype must be one of {', '.join(DTYPES)}; got {dtype!r}")
    if rule.source != "grid":
        raise InputError(
            "export: opacity thresholds come from the grid's flow (the paper's whole video); "
            "the 'viewing' source needs the whole viewing and cannot be exported"
        )
    if not (1 <= int(cache_bins) <= 1_000_000):
        raise InputError(f"cache_bins must be 1..1000000; got {cache_bins}")
    sphere = method == "sphere" or (method == "auto" and g.field_dps is not None)
    h, v = viewport_fov(g, hfov_deg, vfov_deg)
    if sphere:
        field, cells = require_field(g)
        stored = np.dtype(g.field_dps.dtype)
        values = np.asarray(field, np.float32)  # float32, what vimsim epof integrates
        default_dtype = "float16" if stored == np.float16 else "float32"
    else:
        values = np.asarray(g.pof_dps, np.float32)
        default_dtype = "float32"
    out_dtype = default_dtype if dtype == "auto" else dtype
    if out_dtype == "float16" and float(np.max(np.abs(values))) > _FLOAT16_MAX:
        raise InputError(
            f"{src}: flow up to {float(np.max(np.abs(values))):.6g} deg/s exceeds float16's "
            f"range ({_FLOAT16_MAX:g}); export with --dtype float32"
        )
    data = np.ascontiguousarray(values.astype("<f2" if out_dtype == "float16" else "<f4"))
    back = data.astype(np.float64)
    ref = np.asarray(values, np.float64)
    nz = ref != 0
    max_rel = float(np.max(np.abs(back[nz] - ref[nz]) / np.abs(ref[nz]))) if nz.any() else 0.0
    lo, hi = rule.fit(g, None)

    start = int(g.meta.get("start_frame", 0) or 0)
    T = int(data.shape[0])
    video = dict(g.meta.get("video", {}))
    grid_dict = dict(g.meta["grid"])
    grid_dict.update(
        yaw_deg=[float(x) for x in g.yaw_deg], pitch_deg=[float(x) for x in g.pitch_deg]
    )
    header: dict = {
        "format": FORMAT,
        "version": VERSION,
        "mode": "sphere" if sphere else "paper",
        "data": {
            "dtype": out_dtype,
            "shape": [int(s) for s in data.shape],
            "offset": 0,
            "bytes": int(data.nbytes),
            "order": "C, little-endian",
            "units": "deg/s of visual angle",
            "rows": "row t = video frame start_frame + t (flow from frame t-1 to t; row 0 repeats row 1)",
            "what": (
                "field cells [t][i][j]: lat centre 90 - (i + 0.5) cell_deg, lon centre -180 + (j + 0.5) cell_deg"
                if sphere
                else "window POF [t][p][y] of the window centred at grid.pitch_deg[p], grid.yaw_deg[y]"
            ),
        },
        "fps": float(g.fps),
        "n_frames": T,
        "start_frame": start,
        "frame_rule": f"frame = floor(time_s * fps + {FRAME_EPS:g}), clamped to start_frame .. start_frame + n_frames - 1",
        "viewport": {"hfov_deg": h, "vfov_deg": v},
        "grid": grid_dict,
        "opacity": {
            "rule": "linear",
            "formula": "clamp((epof - low_dps) / (high_dps - low_dps), 0, 1); if high_dps <= low_dps: 1 where epof > low_dps else 0",
            "name": "paper" if rule.is_paper else "eased",
            "easing": "per video frame, starting at the first value: v += a (x - v), a = 1 - exp(-1 / (fps smoothing_s)) "
            "(smoothing_s > 0); then the change is limited to at most +1 / (fps ease_in_s) and at least "
            "-1 / (fps ease_out_s) (each > 0; 0 = no limit)",
            "ease_in_s": float(rule.ease_in_s),
            "ease_out_s": float(rule.ease_out_s),
            "low_pct": float(rule.low_pct),
            "high_pct": float(rule.high_pct),
            "source": "absolute: fixed deg/s (--opacity-rule absolute), the same for every video"
            if rule.is_absolute
            else "grid: every window of every frame of pof_dps",
            "scale": "absolute" if rule.is_absolute else "relative",
            "low_dps": lo,
            "high_dps": hi,
            "smoothing_s": float(rule.smoothing_s),
        },
        "conventions": "degrees; yaw + turns right, pitch + looks up, roll + right ear down; applied yaw, "
        "then pitch, then roll (intrinsic); world +x right, +y up, +z forward (equirect centre)",
        "video": {
            "content_hash": video.get("content_hash", ""),
            "path": os.path.basename(str(video.get("path", ""))),
            "width": video.get("width"),
            "height": video.get("height"),
            "layout": g.meta.get("layout"),
            "eye": g.meta.get("eye"),
        },
        "grid_file": {
            "name": os.path.basename(src),
            "content_hash": content_hash(g.path) if g.path and Path(g.path).is_file() else "",
        },
        "flow": g.meta.get("flow"),
        "vimsim_version": __version__,
    }
    if sphere:
        header["field"] = {
            "cell_deg": float(cells.cell_deg),
            "n_lat": int(cells.shape[0]),
            "n_lon": int(cells.shape[1]),
            "query_step_deg": float(_defaults(viewport_epof, ("step_deg",))["step_deg"]),
            "cache_bins": int(cache_bins),
        }
    else:
        header["overlap_table"] = {k: float(x) for k, x in _table_params().items()}
        header["overlap_table"]["rays"] = int(_table_params()["rays"])
    blob = _pack(header, data)

    out = Path(out_dir)
    grid_path = Path(g.path).resolve() if g.path else None
    if grid_path is not None and out.resolve() == grid_path:
        raise InputError(f"{out}: output folder is the input grid file; choose another -o")
    out = check_output_dir(out)
    targets = [out / DATA_FILE, *(out / n for n in CS_FILES)]
    for t in targets:
        if grid_path is not None and t.resolve() == grid_path:
            raise InputError(f"{t}: output would replace the input grid file; choose another -o")
        if t.is_dir():
            raise InputError(f"{t}: is a folder; expected the export's file name to be free")
        if t.exists() and not _is_ours(t):
            raise InputError(
                f"{t}: exists and was not written by vimsim export; move it or choose another -o"
            )
    contents = [blob, *(_cs_source(n) for n in CS_FILES)]
    with contextlib.ExitStack() as stack:  # every file complete before any is renamed
        for t, c in zip(targets, contents):
            tmp = stack.enter_context(atomic_output(t))
            Path(tmp).write_bytes(c)
    return ExportResult(
        out_dir=out,
        files=tuple(targets),
        mode=header["mode"],
        dtype=out_dtype,
        shape=tuple(int(s) for s in data.shape),
        file_bytes=len(blob),
        grid_bytes=Path(g.path).stat().st_size if g.path and Path(g.path).is_file() else 0,
        max_rel_error=max_rel,
        header=header,
    )


def _pack(header: dict, data: NDArray) -> bytes:
    """Prefix + JSON header (with ``data.offset`` filled in, padded to 16 bytes) + data."""
    text = json.dumps(header, sort_keys=True, indent=1, allow_nan=False)
    size = len(text.encode()) + 64  # room for the offset's digits
    offset = _PREFIX + (size + 15) // 16 * 16
    header["data"]["offset"] = offset
    raw = json.dumps(header, sort_keys=True, indent=1, allow_nan=False).encode()
    if len(raw) > offset - _PREFIX:  # cannot happen: 64 bytes of slack for a number
        raise AssertionError("export header grew past its reserved size")
    raw = raw + b" " * (offset - _PREFIX - len(raw))
    return MAGIC + struct.pack("<II", VERSION, len(raw)) + raw + data.tobytes()


def read_export(path: str | os.PathLike) -> tuple[dict, NDArray]:
    """Read ``vimsim_epof.bin`` (or the folder holding it): ``(header, data)`` with ``data``
    shape ``header["data"]["shape"]`` in its stored dtype. InputError (one line naming the
    file) for a truncated file, another format version or a file that is not an export."""
    p = Path(path)
    if p.is_dir():
        p = p / DATA_FILE
    p = check_input_file(p, "vimsim export")
    b = p.read_bytes()
    if len(b) < _PREFIX or b[:8] != MAGIC:
        raise InputError(f"{p}: not a vimsim export (no VIMSIMEP signature)")
    version, hlen = struct.unpack("<II", b[8:16])
    if version != VERSION:
        raise InputError(
            f"{p}: export format version {version}; this vimsim reads version {VERSION}"
        )
    if _PREFIX + hlen > len(b):
        raise InputError(f"{p}: truncated: header needs {_PREFIX + hlen} bytes, file has {len(b)}")
    try:
        header = json.loads(b[_PREFIX : _PREFIX + hlen].decode("utf-8"))
        d = header["data"]
        shape = tuple(int(s) for s in d["shape"])
        dt = {"float16": "<f2", "float32": "<f4"}[d["dtype"]]
        off = int(d["offset"])
    except (ValueError, KeyError, TypeError, UnicodeDecodeError) as e:
        raise InputError(f"{p}: export header is malformed ({e})") from None
    n = math.prod(shape) * np.dtype(dt).itemsize
    if off + n != len(b):
        raise InputError(
            f"{p}: truncated or padded: data needs {off + n} bytes, the file has {len(b)}"
        )
    return header, np.frombuffer(b, dt, count=math.prod(shape), offset=off).reshape(shape)


def frame_at(header: dict, time_s) -> NDArray[np.int64]:
    """Video frame shown at ``time_s`` (seconds from the video start), the runtime's rule:
    ``floor(time_s * fps + 1e-6)`` clamped to the exported frames."""
    t = np.asarray(time_s, np.float64)
    f = np.floor(t * float(header["fps"]) + FRAME_EPS)
    s = int(header["start_frame"])
    return np.clip(f, s, s + int(header["n_frames"]) - 1).astype(np.int64)
