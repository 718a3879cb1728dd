"""A head trace read with its options and put on its video's clock: time scale and offset, and the checks that its span fits the video.

Trace time ``t`` becomes video time ``t * time_scale + time_offset`` (seconds), so a
trace starting 5 s before the video takes ``time_offset = -5``. A trace whose span is
implausible for its video (over :data:`LONG_FACTOR` times the video's duration, or over a
day) is refused, naming the likely time unit and the ``time_scale`` that fixes it, unless
the user gave ``time_scale`` or ``allow_long_trace``; one covering more than 150 % of the video, or less than 90 % with
``hold_last`` (without it, such a trace does not cover the video and is refused), gives a
:class:`TraceSpanWarning`.
"""

from __future__ import annotations

import math
import os
import warnings

from simulator.core.errors import InputError
from simulator.core.traceopts import TraceOptions, spell
from simulator.traces.path import HeadPath
from simulator.traces.readers import load_columns, load_headpath

__all__ = [
    "COVER_RANGE",
    "DAY_S",
    "LONG_FACTOR",
    "TraceSpanWarning",
    "check_span",
    "place",
    "read_trace",
]

#: A span over this many seconds (a day) is refused whatever the video.
DAY_S = 86400.0
#: A span over this many times the video's duration is refused.
LONG_FACTOR = 10.0
#: A span outside this fraction of the video's duration warns.
COVER_RANGE = (0.9, 1.5)
#: Units a trace's clock may have been in, with the factor to seconds.
_UNITS = (
    (1e-3, "0.001", "milliseconds"),
    (1e-6, "1e-6", "microseconds"),
    (1e-9, "1e-9", "nanoseconds"),
)


class TraceSpanWarning(UserWarning):
    """A head trace covers much less or much more than its video."""


def place(hp: HeadPath, opts: TraceOptions, *, scaled: bool = False) -> HeadPath:
    """``hp`` on the video's clock: times x ``opts.time_scale`` (unless ``scaled``: the
    reader applied it) plus ``opts.time_offset``."""
    scale = 1.0 if scaled or opts.time_scale is None else float(opts.time_scale)
    if scale == 1.0 and not opts.time_offset:
        return hp
    return HeadPath(hp.times_s * scale + float(opts.time_offset), hp.rotations, hp.source)


def read_trace(path: str | os.PathLike, opts: TraceOptions) -> HeadPath:
    """The head path of ``path`` read with ``opts`` (a column map, or a format with its
    video/user choice) and placed on the video's clock (:func:`place`). InputError (one
    line naming the file) whose fix is spelled in ``opts.origin``'s terms."""
    try:
        if opts.columns:
            hp = load_columns(
                path,
                opts.columns,
                angles=opts.angles,
                time_scale=1.0 if opts.time_scale is None else float(opts.time_scale),
                time_from_first=opts.time_from_first,
                time_format=opts.time_format,
                skip_rows=opts.skip_rows,
                drop_zero_rows=opts.drop_zero_rows,
            )
            return place(hp, opts, scaled=True)
        user = None if opts.user == "all" else opts.user
        return place(load_headpath(path, opts.format, video=opts.video, user=user), opts)
    except InputError as e:
        raise InputError(opts.fix(str(e))) from None


def _likely_unit(span_s: float, ref_s: float) -> tuple[float, str, str]:
    """The unit (factor to seconds, as written, name) bringing ``span_s`` closest to ``ref_s``."""
    return min(_UNITS, key=lambda u: abs(math.log(max(span_s * u[0], 1e-12) / ref_s)))


def check_span(
    hp: HeadPath, video_s: float | None, opts: TraceOptions, *, video: str = "", warn: bool = True
) -> list[str]:
    """Refuse (InputError) a span implausible for a video of ``video_s`` seconds (None:
    no video, only the one-day limit) unless ``opts`` gives ``time_scale`` or
    ``allow_long_trace``; warn (:class:`TraceSpanWarning`) when the span is outside
    :data:`COVER_RANGE` of the video's duration. ``video`` names it in messages.
    Returns the warnings' texts; ``warn=False`` only returns them (a command that prints
    them once its work is done, so that bad input still ends in one line)."""
    span = hp.end_s - hp.start_s
    src = hp.source or "(unnamed)"
    of = f" for video {video} ({video_s:.3g} s)" if video and video_s else (
        f" for a {video_s:.3g} s video" if video_s else "")  # fmt: skip
    trusted = opts.time_scale is not None or opts.allow_long_trace
    if not trusted and (span > DAY_S or (video_s and span > LONG_FACTOR * video_s)):
        _, f, unit = _likely_unit(span, video_s or 600.0)
        raise InputError(
            f"head path {src}: span {span:,.0f} s is implausible{of}: {unit}? pass "
            f"{spell('time_scale', opts.origin, f)} (or "
            f"{spell('allow_long_trace', opts.origin)} if it really is that long)"
        )
    if not video_s or hp.n < 2:
        return []
    ratio = span / video_s
    # short and not held: the coverage check refuses it (one line); held, it warns here
    if (ratio < COVER_RANGE[0] and opts.hold_last) or ratio > COVER_RANGE[1]:
        fix, vid = (
            spell("time_offset", opts.origin, "S"),
            f"video {video}" if video else "the video",
        )
        msg = (f"head path {src} spans {span:.4g} s, {ratio:.0%} of {vid} ({video_s:.3g} s): the right "
               f"trace and time unit? ({fix} places a trace starting before or after the video)")  # fmt: skip
        if warn:
            warnings.warn(msg, TraceSpanWarning, stacklevel=2)
        return [msg]
    return []
