"""The ``vimsim_epof.bin`` format: prefix, JSON header, flow data and grain layout; packing, reading, checks.

Binary layout (little-endian; ``docs/unity.md``)
------------------------------------------------
======  =====  ==============================================================
offset  bytes  content
======  =====  ==============================================================
0       8      ASCII ``VIMSIMEP``
8       4      uint32 format version (:data:`VERSION`)
12      4      uint32 ``H``: length of the JSON header in bytes
16      H      UTF-8 JSON header, padded with spaces so that 16 + H is a multiple of 16
16 + H  ...    ``data``: ``prod(shape)`` float16 or float32 values, C order
...     ...    ``grains``: ``n_grains x 3`` float32 world unit vectors (header ``grains``),
               at ``grains.offset`` (a multiple of 16); nothing after
======  =====  ==============================================================

A time ``t`` (seconds from the video start) shows frame ``floor(t * fps + 1e-6)``, or for a
variable-rate video the last frame of ``frame_times_s`` at or before it (:func:`frame_at`); the export covers frames ``range.start_frame`` (inclusive) to
``range.end_frame`` (exclusive) of a source of ``source.n_frames`` frames (:func:`covers`).
"""

from __future__ import annotations

import json
import math
import os
import struct
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from simulator.core.errors import InputError
from simulator.core.fileio import check_input_file

__all__ = [
    "DATA_FILE",
    "FORMAT",
    "FRAME_EPS",
    "MAGIC",
    "ROT_FILE",
    "VERSION",
    "check_mitigation_header",
    "covers",
    "frame_at",
    "grain_layout_bytes",
    "pack",
    "pack_head",
    "read_export",
    "read_grain_layout",
]

FORMAT = "vimsim-epof"
#: 2: the opacity rule gained ease-in / ease-out (``opacity.ease_in_s``, ``ease_out_s``).
#: 3: the grain layout (section ``grains``), GRF and vignette settings (``grf``,
#: ``vignette``, ``mitigation``), the source video's length (``source``) and the exported
#: range (``range``). 4: a variable-rate video's frame times (``frame_times_s``), which
#: the frame rule then uses. 5: a source not covering the sphere (``coverage``) and the
#: file's initial orientation (``source.orientation_deg``), which the EPOF then uses (a
#: format-4 runtime would ignore them and give another EPOF: it refuses the file).
VERSION = 5
MAGIC = b"VIMSIMEP"
#: The data file inside an export folder.
DATA_FILE = "vimsim_epof.bin"
#: The rotational part of a sphere-mode field, same format (written when the grid has it:
#: a sphere-mode grid with the per-frame camera rotation, :mod:`simulator.epof.parts`).
ROT_FILE = "vimsim_epof_rot.bin"
#: Tolerance (frames) of the time-to-frame rule: frame times computed as f / fps map to f.
FRAME_EPS = 1e-6
_PREFIX = 16


def _align(n: int) -> int:
    return (n + 15) // 16 * 16


def pack_head(header: dict, data_bytes: int) -> tuple[bytes, bytes]:
    """``(prefix + JSON header, padding after the data)`` of a file whose data has
    ``data_bytes`` bytes: ``data.offset`` and ``grains.offset`` are filled in (``header`` is
    changed), the header padded to 16 bytes; the grain layout follows the padding. Lets a
    writer stream the data (``head + data + pad + grains`` = :func:`pack`)."""
    header["data"]["offset"] = 0
    header["grains"]["offset"] = 0
    text = json.dumps(header, sort_keys=True, indent=1, allow_nan=False)
    size = len(text.encode()) + 64  # room for the offsets' digits
    offset = _PREFIX + _align(size)
    g_off = _align(offset + data_bytes)
    header["data"]["offset"] = offset
    header["grains"]["offset"] = g_off
    raw = json.dumps(header, sort_keys=True, indent=1, allow_nan=False).encode()
    if len(raw) > offset - _PREFIX:  # cannot happen: 64 bytes of slack for two numbers
        raise AssertionError("export header grew past its reserved size")
    raw = raw + b" " * (offset - _PREFIX - len(raw))
    return MAGIC + struct.pack("<II", VERSION, len(raw)) + raw, b"\0" * (g_off - offset - data_bytes)


def grain_layout_bytes(grains: NDArray) -> bytes:
    """The grain layout section: ``n x 3`` float32 little-endian, C order."""
    return np.ascontiguousarray(grains, "<f4").tobytes()


def pack(header: dict, data: NDArray, grains: NDArray) -> bytes:
    """Prefix + JSON header (``data.offset`` and ``grains.offset`` filled in, padded to 16
    bytes) + data + padding to 16 + grain layout (float32)."""
    head, pad = pack_head(header, data.nbytes)
    return head + data.tobytes() + pad + grain_layout_bytes(grains)


def _bad(p: Path, field: str, problem: str) -> InputError:
    return InputError(f"{p}: export header field {field}: {problem}; export again with vimsim export")


def check_mitigation_header(header: dict, p: Path, grain_floats: int | None) -> None:
    """InputError (one line naming the file and the field) for GRF / vignette settings a
    runtime could not draw: a grain layout of the wrong size, a density outside (0, 1),
    cutout radii in the wrong order, a negative feather."""
    try:
        grf, vig, g = header["grf"], header["vignette"], header["grains"]
        n = int(grf["n_grains"])
        density, inner, outer = (float(grf[k]) for k in ("density", "inner_deg", "outer_deg"))
        size, aperture, feather = float(grf["grain_deg"]), float(vig["aperture_min_deg"]), float(
            vig["feather_deg"]
        )
        shape = [int(s) for s in g["shape"]]
    except (KeyError, TypeError, ValueError) as e:
        raise _bad(p, "grf/vignette/grains", f"missing or malformed ({e})") from None
    if not (0.0 < density < 1.0):
        raise _bad(p, "grf.density", f"{density:g} is not a blocked fraction in (0, 1)")
    if not (0.0 <= inner < outer <= 180.0):
        raise _bad(p, "grf.inner_deg/outer_deg", f"cutout radii {inner:g}, {outer:g} are not 0 <= inner < outer <= 180")
    if not (0.0 < size <= 30.0):
        raise _bad(p, "grf.grain_deg", f"{size:g} is not degrees in (0, 30]")
    if not (0.0 < aperture < 180.0) or not (0.0 <= feather <= 180.0):
        raise _bad(p, "vignette", f"aperture {aperture:g} / feather {feather:g} deg out of range")
    if shape != [n, 3] or (grain_floats is not None and grain_floats != 3 * n):
        got = f"shape {shape}" if grain_floats is None else f"{grain_floats // 3} grains"
        raise _bad(p, "grains", f"a layout of {got} for grf.n_grains = {n}")


def _parse(p: Path, b: bytes) -> tuple[dict, str, tuple[int, ...], int]:
    if len(b) < _PREFIX or b[:8] != MAGIC:
        raise InputError(f"{p}: not a vimsim export (no VIMSIMEP signature)")
    version, hlen = struct.unpack("<II", b[8:16])
    if version < VERSION:
        raise InputError(
            f"{p}: export format version {version}, made by an older vimsim (no grain layout, "
            f"range or source length); export again with vimsim export (version {VERSION})"
        )
    if version != VERSION:
        raise InputError(f"{p}: export format version {version}; this vimsim reads version {VERSION}")
    if _PREFIX + hlen > len(b):
        raise InputError(f"{p}: truncated: header needs {_PREFIX + hlen} bytes, file has {len(b)}")
    try:
        header = json.loads(b[_PREFIX : _PREFIX + hlen].decode("utf-8"))
        d = header["data"]
        shape = tuple(int(s) for s in d["shape"])
        dt = {"float16": "<f2", "float32": "<f4"}[d["dtype"]]
        off = int(d["offset"])
    except (ValueError, KeyError, TypeError, UnicodeDecodeError, RecursionError) as e:
        raise InputError(f"{p}: export header is malformed ({e})") from None
    return header, dt, shape, off


def _load(path: str | os.PathLike) -> tuple[Path, bytes, dict, NDArray, NDArray]:
    p = Path(path)
    if p.is_dir():
        p = p / DATA_FILE
    p = check_input_file(p, "vimsim export")
    b = p.read_bytes()
    header, dt, shape, off = _parse(p, b)
    n = math.prod(shape) * np.dtype(dt).itemsize
    try:
        g_off = int(header["grains"]["offset"])
    except (KeyError, TypeError, ValueError):
        raise _bad(p, "grains", "missing") from None
    check_mitigation_header(header, p, None)
    if off + n > len(b) or g_off < off + n or g_off > len(b):
        raise InputError(f"{p}: truncated: data needs {off + n} bytes, the file has {len(b)}")
    if (len(b) - g_off) % 12:
        need = g_off + 12 * int(header["grf"]["n_grains"])
        raise InputError(f"{p}: truncated: the grain layout needs {need} bytes, the file has {len(b)}")
    check_mitigation_header(header, p, (len(b) - g_off) // 4)
    data = np.frombuffer(b, dt, count=math.prod(shape), offset=off).reshape(shape)
    grains = np.frombuffer(b, "<f4", offset=g_off).reshape(-1, 3)
    return p, b, header, data, grains


def read_export(path: str | os.PathLike) -> tuple[dict, NDArray]:
    """Read ``vimsim_epof.bin`` (or the folder holding it): ``(header, data)`` with ``data``
    shape ``header["data"]["shape"]`` in its stored dtype. InputError (one line naming the
    file) for a truncated file, another format version (an older one: export again), a file
    that is not an export, or GRF settings a runtime could not draw
    (:func:`check_mitigation_header`)."""
    _, _, header, data, _ = _load(path)
    return header, data


def read_grain_layout(path: str | os.PathLike) -> NDArray[np.float32]:
    """The exported grain layout, ``(n_grains, 3)`` float32 world unit vectors."""
    return _load(path)[4]


def _frame_of(header: dict, t: NDArray[np.float64]) -> NDArray[np.float64]:
    """The video frame shown at times ``t`` by the export's rule: ``floor(t * fps + 1e-6)``,
    or for a variable-rate export (``frame_times_s``) the last exported frame whose time is
    at most ``t`` (tolerance 1e-6 / fps s): ``start_frame - 1`` before the first, ``end_frame``
    from ``range.end_s`` on. NaN stays NaN."""
    fps = float(header["fps"])
    times = header.get("frame_times_s")
    if times is None:
        with np.errstate(invalid="ignore"):
            return np.floor(t * fps + FRAME_EPS)
    ft = np.asarray(times, np.float64)
    s, end_s = int(header["start_frame"]), float(header["range"]["end_s"])
    tt = t + FRAME_EPS / fps
    with np.errstate(invalid="ignore"):
        f = s + np.searchsorted(ft, np.where(np.isfinite(tt), tt, 0.0), side="right") - 1.0
        f = np.where(tt >= end_s, s + len(ft), f)
    return np.where(np.isfinite(tt), f, np.nan)


def frame_at(header: dict, time_s) -> NDArray[np.int64]:
    """Video frame shown at ``time_s`` (seconds from the video start), the runtime's rule:
    ``floor(time_s * fps + 1e-6)`` (a variable-rate export: looked up in its
    ``frame_times_s``) clamped to the exported frames."""
    f = _frame_of(header, np.asarray(time_s, np.float64))
    s = int(header["start_frame"])
    return np.clip(f, s, s + int(header["n_frames"]) - 1).astype(np.int64)


def covers(header: dict, time_s) -> NDArray[np.bool_]:
    """Whether the export has the frame shown at ``time_s`` (the runtime's ``Covers``):
    ``start_frame <= frame < end_frame`` by the rule of :func:`frame_at`; False for NaN or
    infinite."""
    f = _frame_of(header, np.asarray(time_s, np.float64))
    r = header["range"]
    with np.errstate(invalid="ignore"):
        return np.isfinite(f) & (f >= int(r["start_frame"])) & (f < int(r["end_frame"]))
