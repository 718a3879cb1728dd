"""The study manifest's trace options: the ``[traces]`` default table and each viewing's own trace keys, validated from the one option table the CLI is generated from too.

Every key of :data:`simulator.core.traceopts.TRACE_OPTIONS` is accepted in ``[traces]``
(defaults for every viewing with a trace file) and in a ``[[viewings]]`` entry (over
them; a viewing's ``format`` replaces a ``[traces]`` column map and its keys, a viewing's
``columns`` a ``[traces]`` format), with the CLI's meaning; in a viewing, whose ``video`` names a ``[[videos]]`` id,
the AVTrack360 video choice is ``trace_video``. A key with no effect where it is written
is refused, saying where it belongs: a column-map key without ``columns``
(:class:`~simulator.core.traceopts.TraceOptions` checks), any trace key on a scripted
viewer (``viewers``: no trace file). Errors speak the manifest's terms (``hold_last =
true``, not ``--hold-last``).
"""

from __future__ import annotations

from simulator.core.errors import InputError
from simulator.core.traceopts import TRACE_OPTIONS, TraceOptions
from simulator.study.entry import Entry, user_spans

__all__ = ["TRACE_KEYS", "VIEWING_TRACE_KEYS", "trace_defaults", "viewing_trace_options"]

#: The ``[traces]`` table's keys: every trace option, by its manifest key.
TRACE_KEYS: tuple[str, ...] = tuple(o.key for o in TRACE_OPTIONS)
#: A viewing's trace keys (``video`` there is the ``[[videos]]`` id: ``trace_video``).
VIEWING_TRACE_KEYS: tuple[str, ...] = tuple(
    "trace_video" if k == "video" else k for k in TRACE_KEYS
)


def _values(e: Entry, rename: dict[str, str]) -> dict:
    """The trace keys ``e`` gives, typed and bounded as the table declares them
    (``rename``: manifest key -> option key)."""
    out = {}
    for o in TRACE_OPTIONS:
        key = next((k for k, v in rename.items() if v == o.key), o.key)
        if key not in e.t:
            continue
        if o.kind == "flag":
            out[o.key] = e.get(key, (bool,))
        elif o.kind == "choice":
            out[o.key] = e.get(key, (str,), choices=o.choices)
        elif o.kind == "str":
            out[o.key] = e.get(key, (str,))
        elif o.kind == "user":
            v = e.get(key, (int, str, list))
            if v != "all":
                user_spans(e, key, v)  # a bad spec is named (never expanded) before any file is read
            out[o.key] = v
        else:
            out[o.key] = e.number(key, lo=o.lo, lo_open=o.lo_open, integer=o.kind == "int")
    return out


def trace_defaults(m, t) -> dict:
    """The ``[traces]`` table's values (only the keys given), checked: unknown keys and
    bad values name the table."""
    e = Entry(m, "[traces]", t or {}, TRACE_KEYS)
    given = _values(e, {})
    _options(e, given, {})  # contradictions within the table are its own
    return given


def _options(e: Entry, given: dict, rename: dict) -> TraceOptions:
    try:
        return TraceOptions(**{k: v for k, v in given.items() if k != "user"}, origin="manifest")
    except InputError as err:
        msg = str(err)
        for key, opt in rename.items():
            msg = msg.replace(f"{opt} = ", f"{key} = ")
        e.fail(msg)


def viewing_trace_options(
    e: Entry, defaults: dict, *, scripted: bool
) -> tuple[TraceOptions, object]:
    """``(options, user spec)`` of one ``[[viewings]]`` entry: ``[traces]`` with the
    entry's own keys over them. A scripted viewer (``scripted``) takes none: its trace
    keys are refused (they belong on an entry with a ``trace`` file)."""
    rename = {"trace_video": "video"}
    own = _values(e, rename)
    if scripted:
        if own:
            key = next(k for k in VIEWING_TRACE_KEYS if k in e.t)
            e.fail(f"{key} has no effect on scripted viewers (viewers = ...: no trace file); it "
                   "belongs on a [[viewings]] entry with a trace (or in [traces])")  # fmt: skip
        return TraceOptions(origin="manifest"), None
    merged = {**defaults, **own}
    if "columns" in own and "format" not in own:
        merged.pop("format", None)  # the viewing's column map is its format
    if "format" in own and "columns" not in own:  # its format replaces [traces]' column map
        for o in TRACE_OPTIONS:
            if (o.key == "columns" or o.columns_only) and o.key not in own:
                merged.pop(o.key, None)
    opts = _options(e, merged, rename)
    if opts.columns and merged.get("user") is not None:
        e.fail("user has no effect with a column map (it reads one trace); user belongs on a "
               "360VidStr trace: drop it here or columns")  # fmt: skip
    return opts, merged.get("user")
