"""The trace options (how a head trace is read and put on its video's clock), declared once for the CLI and the study manifest.

:data:`TRACE_OPTIONS` is the one table: each :class:`TraceOption` names a manifest key
(``time_scale``) whose CLI flag is the same name with dashes (``--time-scale``), its type,
default, bounds or choices and help. The CLI's argparse options
(:func:`simulator.commands.headpath.add_reader_options`) and the study manifest's
``[traces]`` table and per-viewing keys (:mod:`simulator.study.manifest`) are generated from
it, and :class:`TraceOptions` holds one set of values, checked once in ``__post_init__``
whichever side built it. Its errors speak the language of where the options came from
(``origin``): ``--hold-last`` on the command line, ``hold_last = true`` in a manifest
(:func:`spell`, :func:`translate`).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field, fields

from simulator.core.choices import HEADPATH_FORMATS
from simulator.core.errors import InputError

__all__ = [
    "TRACE_OPTIONS",
    "TraceOption",
    "TraceOptions",
    "option",
    "spell",
    "translate",
]


@dataclass(frozen=True)
class TraceOption:
    """One trace option: ``key`` (manifest key; the CLI flag is ``--key`` with dashes),
    ``kind`` (``str``, ``float``, ``int``, ``flag``, ``choice`` or ``user``), ``default``,
    ``help`` (one sentence), ``metavar``, ``choices``, a lower bound ``lo`` (``lo_open``:
    exclusive) and ``columns_only`` (meaningful only with a column map)."""

    key: str
    kind: str
    default: object
    help: str
    metavar: str | None = None
    choices: tuple | None = None
    lo: float | None = None
    lo_open: bool = False
    columns_only: bool = False

    @property
    def flag(self) -> str:
        return "--" + self.key.replace("_", "-")


#: Every trace option, in the order the CLI's help lists them.
TRACE_OPTIONS: tuple[TraceOption, ...] = (
    TraceOption("format", "choice", "auto", "head path format (auto: detected from the "
                "content; see docs/headpath.md)", choices=("auto", *HEADPATH_FORMATS)),
    TraceOption("video", "str", None, "AVTrack360 files hold one trace per video: which "
                "one, e.g. 6.mp4", metavar="NAME"),
    TraceOption("user", "user", None, "360VidStr aggregated files hold one trace per user: "
                "which one (1-based)", metavar="N"),
    TraceOption("columns", "str", None, "read any delimited or JSON log through a column "
                "map: time=COL,yaw=COL,pitch=COL[,roll=COL]; a leading - flips a sign; "
                "nested JSON fields by dotted names, time=key for a JSON object keyed by "
                "timestamps (a single wrapper key is descended), e.g. the SIT-VR Unity log: "
                "time=key,yaw=Ey,pitch=-Ex,roll=-Ez", metavar="MAP"),
    TraceOption("angles", "choice", "deg", "columns: angle unit (default deg)", choices=("deg", "rad"),
                columns_only=True),
    TraceOption("time_format", "str", None, "columns: the time column is a clock time in "
                "this strptime format, e.g. %Y%m%dZ-%H%M%S_%fZ (counted from the first row)",
                metavar="FMT", columns_only=True),
    TraceOption("time_from_first", "flag", False, "columns: count time from the first row "
                "(for clock timestamps)", columns_only=True),
    TraceOption("skip_rows", "int", 0, "columns: drop the first N data rows", metavar="N",
                lo=0, columns_only=True),
    TraceOption("drop_zero_rows", "flag", False, "columns: drop rows whose angles are all "
                "exactly 0 (Unity's first sample)", columns_only=True),
    TraceOption("time_scale", "float", None, "seconds per unit of the trace's time (0.001 "
                "for milliseconds, 1e-6 for microseconds; default 1); also allows a trace "
                "much longer than its video", metavar="F", lo=0.0, lo_open=True),
    TraceOption("time_offset", "float", 0.0, "video time, seconds, of the trace's time 0: "
                "negative for a trace that starts before the video, positive after it "
                "(default 0)", metavar="S"),
    TraceOption("hold_last", "flag", False, "hold the first/last pose where the head path "
                "does not cover the video"),
    TraceOption("allow_long_trace", "flag", False, "accept a trace spanning over 10x its "
                "video or over a day (refused by default: a time unit slip)"),
)  # fmt: skip

_BY_KEY = {o.key: o for o in TRACE_OPTIONS}


def option(key: str) -> TraceOption:
    """The :class:`TraceOption` of ``key``."""
    return _BY_KEY[key]


def spell(key: str, origin: str = "cli", value: object = None) -> str:
    """How the user sets option ``key`` where the options came from: ``--time-scale 1e-6``
    (``origin="cli"``) or ``time_scale = 1e-6`` (``"manifest"``; text values quoted as
    TOML writes them); a flag without value."""
    o = _BY_KEY[key]
    if origin == "cli":
        return o.flag if o.kind == "flag" or value is None else f"{o.flag} {value}"
    if o.kind == "flag":
        return f"{key} = true"
    if key == "video":  # a viewing's own `video` is its [[videos]] id
        v = "..." if value is None else f'"{value}"'
        return f"trace_video = {v} (video = {v} in [traces])"
    if value is None:
        return f"{key} = ..."
    text = str(value)
    numeric = o.kind in ("float", "int", "user") and re.fullmatch(r"-?[\d.e+-]+", text)
    bare = numeric or re.fullmatch(r"[A-Z]+", text)  # a number, or a placeholder (S, FMT)
    return f"{key} = {text}" if bare else f'{key} = "{text}"'


_FLAG_RE = re.compile(
    r"--("
    + "|".join(o.flag[2:] for o in TRACE_OPTIONS)
    + r")\b(?!-)(:)?(?: (-?[^\s(;,'\"-][^\s;]*))?"
)


def _manifest_term(m: re.Match) -> str:
    key = m.group(1).replace("-", "_")
    rest = f" {m.group(3)}" if m.group(3) is not None else ""
    if m.group(2):  # "--columns: ..." (the option named as a message's subject)
        return f"{key}:{rest}"
    if _BY_KEY[key].kind == "flag":  # takes no value: the next word is the sentence's
        return spell(key, "manifest") + rest
    value = m.group(3)
    if value is not None and value.endswith((")", ".")):  # the end of a sentence
        return spell(key, "manifest", value.rstrip(").")) + value[len(value.rstrip(").")) :]
    return spell(key, "manifest", value)


def translate(message: str, origin: str) -> str:
    """``message`` with every trace option's CLI flag spelled as ``origin`` sets it (a
    manifest's errors name its keys: ``--hold-last`` -> ``hold_last = true``)."""
    if origin == "cli":
        return message
    return _FLAG_RE.sub(_manifest_term, message)


@dataclass(frozen=True)
class TraceOptions:
    """One set of trace option values (see :data:`TRACE_OPTIONS`); checked on creation.

    ``origin`` (``"cli"`` or ``"manifest"``) is where they came from: errors name the fix
    in its terms. ``time_scale`` None = 1 (not given: a very long trace is refused).
    """

    format: str = "auto"
    video: str | None = None
    user: int | None = None
    columns: str | None = None
    angles: str = "deg"
    time_format: str | None = None
    time_from_first: bool = False
    skip_rows: int = 0
    drop_zero_rows: bool = False
    time_scale: float | None = None
    time_offset: float = 0.0
    hold_last: bool = False
    allow_long_trace: bool = False
    origin: str = field(default="cli", compare=False)

    def __post_init__(self) -> None:
        s = lambda k, v=None: spell(k, self.origin, v)
        if self.columns and self.format != "auto":
            raise InputError(f"{s('columns')} and {s('format')} exclude each other: a column "
                             f"map is the format; drop {s('format')}")  # fmt: skip
        if not self.columns:
            given = [
                o.key for o in TRACE_OPTIONS if o.columns_only and getattr(self, o.key) != o.default
            ]
            if given:
                raise InputError(f"{s(given[0])} has no effect without a column map; add "
                                 f"{s('columns', 'time=COL,yaw=COL,pitch=COL')} or drop it")  # fmt: skip
        if self.time_format and self.time_scale is not None:
            raise InputError(f"{s('time_scale')} has no effect with {s('time_format')} (clock "
                             "times are seconds); drop it")  # fmt: skip
        for k in ("time_scale", "time_offset"):
            v = getattr(self, k)
            if v is not None and not (isinstance(v, (int, float)) and math.isfinite(v)):
                raise InputError(f"{s(k)}: expected a finite number; got {v!r}")
        if self.time_scale is not None and self.time_scale <= 0:
            raise InputError(
                f"{s('time_scale')}: expected a number > 0, e.g. 0.001; got {self.time_scale!r}"
            )

    @classmethod
    def from_values(cls, get, origin: str = "cli") -> TraceOptions:
        """Built from ``get(key, default)`` (an argparse namespace's ``getattr`` or a
        mapping's ``get``): options not given take their defaults."""
        keys = [f.name for f in fields(cls) if f.name != "origin"]
        return cls(**{k: get(k, _BY_KEY[k].default) for k in keys}, origin=origin)

    def fix(self, message: str) -> str:
        """``message`` with CLI flags spelled in this origin's terms (:func:`translate`)."""
        return translate(message, self.origin)
