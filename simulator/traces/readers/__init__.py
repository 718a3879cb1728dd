"""Readers of recorded head paths: vimsim's own formats and the public datasets, one module per family.

:func:`load_headpath` reads any of :data:`FORMATS` (``auto`` detects the format from the
content) into a :class:`simulator.traces.path.HeadPath` in the project's conventions (degrees;
yaw + right, pitch + up, roll + right ear down; seconds from the video start). The mapping
of each dataset's axes to ours is documented in ``docs/headpath.md`` and beside each reader.
"""

from __future__ import annotations

import os

from simulator.core.choices import HEADPATH_FORMATS as FORMATS
from simulator.core.errors import InputError
from simulator.core.fileio import check_input_file
from simulator.traces.path import CANONICAL_COLUMNS, HeadPath
from simulator.traces.readers.avtrack360 import _read_avtrack360
from simulator.traces.readers.canonical import _read_canonical, _read_keyframes_json, _read_quat
from simulator.traces.readers.columns import load_columns, parse_column_map
from simulator.traces.readers.common import _first_line, _warn_if_coarse
from simulator.traces.readers.corbillon import _read_corbillon, _read_corbillon_euler
from simulator.traces.readers.salient360 import _read_salient360_dyn, _read_salient360_static
from simulator.traces.readers.vidstr360 import _360vidstr_user, _parse_360vidstr, _read_360vidstr

__all__ = [
    "FORMATS",
    "detect_format",
    "load_all_users",
    "load_columns",
    "load_headpath",
    "load_keyframes",
    "parse_column_map",
]


def detect_format(path: str | os.PathLike) -> str:
    """Guess the format (one of :data:`FORMATS`) from the file's content."""
    p = check_input_file(path, "head path")
    head = _first_line(p)
    low = head.lower()
    if head.startswith(("{", "[")):
        with open(p, encoding="utf-8-sig", errors="replace") as fh:
            text = fh.read(1 << 16)
        if "pitch_yaw_roll_data_hmd" in text:
            return "avtrack360"
        return "keyframes-json"
    toks = set(low.replace(",", " ").replace('"', " ").replace("'", " ").split())
    if {"timestamp", "viewpoint", "w", "x", "y", "z"} <= toks:
        return "corbillon"
    if {"timestamp", "viewpoint", "yaw", "pitch", "roll"} <= toks:
        return "corbillon-euler"
    if {"cam_pitch", "cam_yaw", "cam_roll"} <= toks:
        return "salient360-dyn"
    if "camerarotation.x" in toks and "camerarotation.w" in toks:
        return "salient360-static"
    if "time_s" in toks and {"qw", "qx", "qy", "qz"} <= toks:
        return "quat"
    if "time_s" in toks:
        return "canonical"
    try:
        [float(v) for v in head.split()]
        return "360vidstr"
    except ValueError:
        pass
    n = len(head.replace(",", " ").split())
    raise InputError(  # the line itself is not quoted: messages never echo file content
        f"{p}: cannot tell the head path format from its first line ({n} fields, not a "
        f"known header); expected a "
        f"CSV with header {','.join(CANONICAL_COLUMNS)} (or pass --format, one of {', '.join(FORMATS)})"
    )


def load_headpath(
    path: str | os.PathLike,
    format: str = "auto",
    *,
    video: str | None = None,
    user: int | None = None,
) -> HeadPath:
    """Read a head path file.

    Parameters
    ----------
    path : file name
    format : ``auto`` or one of :data:`FORMATS`
    video : str, AVTrack360 only: which video's trace (``"6.mp4"`` or ``"6"``)
    user : int, 360VidStr only: which user (1-based, as the dataset's readMe counts)

    Raises
    ------
    InputError
        One line naming the file and the problem (empty, unknown columns, NaN, time not
        increasing, zero-length quaternion, ...). Angles that look like radians where
        degrees are expected give a :class:`RadiansWarning`.
    """
    p = check_input_file(path, "head path")
    fmt = detect_format(p) if format == "auto" else format
    if fmt not in FORMATS:
        raise InputError(
            f"{p}: unknown head path format {format!r}; expected auto or one of {', '.join(FORMATS)}"
        )
    if fmt == "avtrack360":
        hp = _read_avtrack360(p, video)
    elif fmt == "360vidstr":
        hp = _read_360vidstr(p, user)
    else:
        hp = _READERS[fmt](p)
    _warn_if_coarse(hp)
    return hp


_READERS = {
    "canonical": _read_canonical,
    "quat": _read_quat,
    "keyframes-json": _read_keyframes_json,
    "corbillon": _read_corbillon,
    "corbillon-euler": _read_corbillon_euler,
    "salient360-dyn": _read_salient360_dyn,
    "salient360-static": _read_salient360_static,
}


def load_keyframes(path: str | os.PathLike) -> HeadPath:
    """Read a keyframe file (JSON list, or a canonical CSV) for ``headpath.synth("keyframes")``."""
    p = check_input_file(path, "keyframes")
    fmt = detect_format(p)
    if fmt not in ("keyframes-json", "canonical"):
        raise InputError(
            f"{p}: keyframes must be a JSON list or a CSV with header {','.join(CANONICAL_COLUMNS)}"
        )
    return load_headpath(p, fmt)


def load_all_users(path: str | os.PathLike, format: str = "auto") -> dict[int, HeadPath]:
    """Every user of a head path file, read once: ``{user (1-based): HeadPath}``.

    360VidStr aggregated files hold many users (one pair of lines each); any other format
    holds one trace and gives ``{1: path}`` (read as :func:`load_headpath` reads it). A
    user whose samples are bad raises InputError naming the file and the user.
    """
    p = check_input_file(path, "head path")
    fmt = detect_format(p) if format == "auto" else format
    if fmt != "360vidstr":
        return {1: load_headpath(p, fmt)}
    rows = _parse_360vidstr(p)
    out = {u: _360vidstr_user(p, rows, u) for u in range(1, (len(rows) - 1) // 2 + 1)}
    for hp in out.values():
        _warn_if_coarse(hp)
    return out
