"""Readers of recorded head paths: vimsim's own formats and the public datasets, one module per family.

:func:`load_headpath` reads any of :data:`FORMATS` (``auto`` detects the format from the
content) into a :class:`simulator.traces.path.HeadPath` in the project's conventions (degrees;
yaw + right, pitch + up, roll + right ear down; seconds from the video start). The mapping
of each dataset's axes to ours is documented in ``docs/headpath.md`` and beside each reader.
"""

from __future__ import annotations

import os
import warnings

from simulator.core.choices import HEADPATH_FORMATS as FORMATS
from simulator.core.errors import InputError
from simulator.core.fileio import check_input_file
from simulator.traces.path import CANONICAL_COLUMNS, HeadPath
from simulator.traces.readers import avtrack360, canonical, corbillon, salient360, vidstr360
from simulator.traces.readers.columns import columns_example, load_columns, parse_column_map
from simulator.traces.readers.common import _first_line, _warn_if_coarse
from simulator.traces.readers.formats import Sniff, TraceFormat

#: Every head-trace format, by name: one entry per reader module (each declares its own
#: formats and how to recognise them, ``TRACE_FORMATS``). A new format: a new module here.
REGISTRY: dict[str, TraceFormat] = {
    f.name: f
    for module in (avtrack360, canonical, corbillon, salient360, vidstr360)
    for f in module.TRACE_FORMATS
}

__all__ = [
    "FORMATS",
    "REGISTRY",
    "TraceFile",
    "detect_format",
    "load_all_users",
    "load_columns",
    "load_headpath",
    "load_keyframes",
    "n_users",
    "parse_column_map",
    "sampling_warnings",
]


def detect_format(path: str | os.PathLike) -> str:
    """Guess the format (one of :data:`FORMATS`) from the file's content."""
    p = check_input_file(path, "head path")
    head = _first_line(p)
    sniff = Sniff(p, head)
    for f in sorted(REGISTRY.values(), key=lambda f: f.rank):
        if f.sniff(sniff):
            return f.name
    n = len(head.replace(",", " ").split())
    what = "a JSON log of no known dataset" if sniff.is_json else (
        f"its first line has {n} fields, not a known header")  # fmt: skip
    raise InputError(  # the line itself is not quoted: messages never echo file content
        f"{p}: cannot tell the head path format ({what}); expected a CSV with header "
        f"{','.join(CANONICAL_COLUMNS)}, or --format (one of {', '.join(FORMATS)}), or a lab's "
        f"own log through a column map, e.g. --columns "
        f"{columns_example(p) or 'time=t,yaw=yaw,pitch=pitch'} (check signs and units: "
        "docs/headpath.md)"
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
    if fmt not in REGISTRY:
        raise InputError(
            f"{p}: unknown head path format {format!r}; expected auto or one of {', '.join(REGISTRY)}"
        )
    try:
        hp = REGISTRY[fmt].read(p, video=video, user=user)
    except InputError as e:
        if format != "auto":
            raise
        raise InputError(f"{e} (read as {fmt}, detected){_columns_hint(p)}") from None
    _warn_if_coarse(hp)
    return hp


def _columns_hint(p) -> str:
    """``"; a lab's own log? --columns ..."`` built from the file's fields, else ``""``."""
    ex = columns_example(p)
    return f"; a lab's own log? read it through a column map, e.g. --columns {ex}" if ex else ""


def load_keyframes(path: str | os.PathLike) -> HeadPath:
    """Read a keyframe file (JSON list, or a canonical CSV) for ``headpath.synth("keyframes")``."""
    p = check_input_file(path, "keyframes")
    fmt = detect_format(p)
    if fmt not in ("keyframes-json", "canonical"):
        raise InputError(
            f"{p}: keyframes must be a JSON list or a CSV with header {','.join(CANONICAL_COLUMNS)}"
        )
    return load_headpath(p, fmt)


class TraceFile:
    """A head path file parsed once for many viewings: each user's path, and each viewing
    gets the warnings that belong to it (the file's own, and its user's sampling).

    ``user(u)`` (None or 1 for a file of one trace) re-issues the file's warnings and the
    user's sampling warning, so a caller catching warnings per viewing attributes them
    right however many viewings share the parsed file.
    """

    def __init__(self, path: str | os.PathLike, format: str = "auto"):
        p = check_input_file(path, "head path")
        self.path, self.format = p, detect_format(p) if format == "auto" else format
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            self.users = load_all_users(p, self.format, warn=False)
        self.file_warnings = [(w.message, w.category) for w in caught]
        self.multi = REGISTRY[self.format].read_all is not None

    def user(self, u: int | None) -> HeadPath:
        """User ``u``'s path (1-based; None: the file's only trace), warnings issued."""
        for msg, cat in self.file_warnings:
            warnings.warn(msg, cat, stacklevel=2)
        k = 1 if u is None and len(self.users) == 1 else u
        if k not in self.users:
            raise InputError(f"{self.path}: no user {u}; the file holds {len(self.users)}")
        if self.multi:
            _warn_if_coarse(self.users[k])
        return self.users[k]


def sampling_warnings(hp: HeadPath) -> None:
    """Warn (CoarseSamplingWarning) about ``hp``'s sampling, as the readers do for each path."""
    _warn_if_coarse(hp)


def load_all_users(
    path: str | os.PathLike, format: str = "auto", *, warn: bool = True
) -> dict[int, HeadPath]:
    """Every user of a head path file, read once: ``{user (1-based): HeadPath}``.

    360VidStr aggregated files hold many users (one pair of lines each); any other format
    holds one trace and gives ``{1: path}`` (read as :func:`load_headpath` reads it). A
    user whose samples are bad raises InputError naming the file and the user.
    ``warn=False``: no sampling warnings here; :func:`sampling_warnings` gives one user's
    (so that each warning belongs to the viewing of its user).
    """
    p = check_input_file(path, "head path")
    fmt = detect_format(p) if format == "auto" else format
    if fmt not in REGISTRY:
        raise InputError(f"{p}: unknown head path format {format!r}; expected auto or one of {', '.join(REGISTRY)}")
    read_all = REGISTRY[fmt].read_all
    if read_all is None:
        return {1: load_headpath(p, fmt)}
    out = read_all(p)
    for hp in out.values() if warn else ():
        _warn_if_coarse(hp)
    return out


def n_users(path: str | os.PathLike, format: str = "auto") -> tuple[str, int]:
    """``(format, number of users)`` of a head path file, cheaply (no parsing where the
    format can count its users from the file's layout)."""
    p = check_input_file(path, "head path")
    fmt = detect_format(p) if format == "auto" else format
    count = REGISTRY[fmt].count_users if fmt in REGISTRY else None
    return fmt, (count(p) if count else 1)
