"""Any lab's head log, a delimited table or a JSON log, read through a column map (``--columns``).

A map names the file's column of each quantity, ``time=COL,yaw=COL,pitch=COL[,roll=COL]``;
a leading ``-`` flips that angle's sign (``pitch=-deg_pitch``). Angles are in degrees or
radians (``angles``), yaw + right, pitch + up, roll + right ear down *after* the sign
flips, applied yaw, then pitch, then roll (intrinsic: SPEC's order, which is also Unity's
``transform.eulerAngles`` Z, X, Y extrinsic order). Angles in [0, 360) are wrapped to
+-180. Time is the column times ``time_scale`` (0.001 for milliseconds), or, with
``time_format`` (a ``strptime`` format such as ``%Y%m%dZ-%H%M%S_%fZ``), the clock time
it spells, in seconds; minus the first kept row's time if ``time_from_first`` (always with
``time_format``: a wall clock has no video origin). Rows repeating the previous time are
dropped (loggers that sample faster than the pose updates); ``skip_rows`` drops the first
data rows, ``drop_zero_rows`` the rows whose mapped angles are all exactly 0 (Unity's
first sample before the headset reports). Times that look like clock timestamps (over
1e8 s) without ``time_from_first`` give a :class:`ClockTimeWarning`.

A JSON log is an object keyed by timestamps or a list of objects, below any single wrapper
key, which is descended: the real SIT-VR Unity log is ``{"1-SubheadPosition":
{"20210510Z-200400_686Z": {"Ex": .., "Ey": .., "Ez": .., "Rx": .., ..}, ..}}``, read with
``time=key,yaw=Ey,pitch=-Ex,roll=-Ez``; ``time=key`` names the object's key, nested fields
go by dotted names (``yaw=rot.y``).

A Unity-style log (left-handed, x right, y up, z forward; Euler degrees in [0, 360);
pitch + looks down, roll + left ear down) needs only ``yaw=Y,pitch=-X,roll=-Z``.
"""

from __future__ import annotations

import difflib
import json
import math
import os
import warnings
from array import array
from datetime import UTC, datetime

import numpy as np

from simulator.core.errors import InputError
from simulator.core.fileio import check_input_file
from simulator.traces.path import HeadPath
from simulator.traces.readers.common import _check_increasing, _dedupe_times, _value
from simulator.traces.readers.jsonlog import json_entries, starts_as_json

__all__ = ["COLUMN_KEYS", "ClockTimeWarning", "columns_example", "load_columns", "parse_column_map"]

#: Times beyond this many seconds (about 3 years) look like clock timestamps.
CLOCK_TIME_S = 1e8


class ClockTimeWarning(UserWarning):
    """Times of a head log look like clock timestamps (seconds since 1970), not seconds
    from the video start."""

#: Quantities of a column map; ``roll`` is optional (0 when absent).
COLUMN_KEYS: tuple[str, ...] = ("time", "yaw", "pitch", "roll")


def parse_column_map(text: str) -> dict[str, tuple[str, float]]:
    """``"time=t,yaw=Y,pitch=-X"`` -> ``{"time": ("t", 1.0), "yaw": ("Y", 1.0), "pitch": ("X", -1.0)}``.

    InputError for an unknown key, a repeated key, a missing ``time``/``yaw``/``pitch``,
    or a sign on ``time``."""
    out: dict[str, tuple[str, float]] = {}
    for item in (s.strip() for s in text.split(",")):
        if not item:
            continue
        key, eq, col = item.partition("=")
        key, col = key.strip(), col.strip()
        if not eq or not col:
            raise InputError(
                f"--columns: expected KEY=COLUMN, got {item!r} (keys: {', '.join(COLUMN_KEYS)})"
            )
        if key not in COLUMN_KEYS:
            raise InputError(f"--columns: unknown key {key!r}; expected {', '.join(COLUMN_KEYS)}")
        if key in out:
            raise InputError(f"--columns: {key} given twice")
        sign = 1.0
        if col.startswith("-"):
            sign, col = -1.0, col[1:].strip()
            if key == "time":
                raise InputError(
                    "--columns: time cannot be negated; use --time-scale -1 if you must"
                )
        out[key] = (col, sign)
    missing = [k for k in COLUMN_KEYS[:3] if k not in out]
    if missing:
        raise InputError(f"--columns needs {', '.join(missing)} (e.g. time=t,yaw=yaw,pitch=pitch)")
    return out


def _split(line: str, delim: str | None) -> list[str]:
    return [f.strip().strip('"') for f in (line.split(delim) if delim else line.split())]


def _flatten(obj, prefix: str, out: dict) -> dict:
    """Nested JSON objects (and lists) as ``{"a.b.c": value}``."""
    items = obj.items() if isinstance(obj, dict) else enumerate(obj)
    for k, v in items:
        name = f"{prefix}{k}"
        if isinstance(v, (dict, list)):
            _flatten(v, name + ".", out)
        else:
            out[name] = v
    return out


def _is_samples(v) -> bool:
    """Whether ``v`` is a container of samples: a non-empty object or list whose members
    are all objects (one sample's members are values)."""
    members = list(v.values()) if isinstance(v, dict) else v if isinstance(v, list) else []
    return bool(members) and all(isinstance(x, dict) for x in members)


def _descend(obj) -> tuple[object, list[str]]:
    """Below every single wrapper key (``{"1-SubheadPosition": {time: sample, ..}}``, the
    real SIT-VR log): the samples, and the keys descended."""
    path: list[str] = []
    while isinstance(obj, dict) and len(obj) == 1:
        (k, v), = obj.items()
        if not _is_samples(v):
            break
        obj, path = v, [*path, str(k)]
    return obj, path


def _json_table(p, text: str) -> tuple[list[str], list[tuple[str, dict]]]:
    """Columns and rows (label, {column: value}) of a JSON log (see the module doc)."""
    try:
        obj = json.loads(text)
    except RecursionError:
        raise InputError(f"{p}: JSON nested too deeply") from None
    except json.JSONDecodeError as e:
        raise InputError(f"{p}: not valid JSON (line {e.lineno}: {e.msg})") from None
    obj, _ = _descend(obj)
    if isinstance(obj, dict):
        entries = [(f"entry {i + 1}", {"key": k}, v) for i, (k, v) in enumerate(obj.items())]
    elif isinstance(obj, list):
        entries = [(f"entry {i + 1}", {}, v) for i, v in enumerate(obj)]
    else:
        raise InputError(f"{p}: expected a JSON object keyed by time, or a list of objects")
    rows, cols = [], {}
    for label, row, v in entries:
        if isinstance(v, (dict, list)):
            _flatten(v, "", row)
        else:
            row["value"] = v
        cols.update(dict.fromkeys(row))
        rows.append((label, row))
    return list(cols), rows


def _text_table(p, text: str) -> tuple[list[str], list[tuple[str, dict]]]:
    """Columns and rows (label, {column: value}) of a delimited log; the delimiter is the
    header's (comma, semicolon, tab, else whitespace); ``#`` lines are comments."""
    lines = [(k + 1, ln) for k, ln in enumerate(text.splitlines()) if ln.strip()]
    lines = [(k, ln) for k, ln in lines if not ln.lstrip().startswith("#")]
    if not lines:
        raise InputError(f"{p}: head path file is empty")
    delim = next((d for d in (",", ";", "\t") if d in lines[0][1]), None)
    cols = _split(lines[0][1], delim)
    return cols, [(f"line {k}", dict(zip(cols, _split(ln, delim)))) for k, ln in lines[1:]]


def _read_table(p) -> tuple[list[str], list[tuple[str, dict]]]:
    with open(p, encoding="utf-8-sig", errors="replace") as fh:
        text = fh.read()
    if text.lstrip().startswith(("{", "[")):
        return _json_table(p, text)
    return _text_table(p, text)


def _unknown_message(p, unknown: list[str], rows) -> str:
    """One line: the unknown columns and the closest field names of one sample (difflib,
    at most 5, each cut to 30 characters); none close, only how many fields it has (a
    header is never listed: docs/reliability.md)."""
    label, sample = rows[0] if rows else ("", {})
    names = [str(c) for c in sample]
    close = difflib.get_close_matches(unknown[0], names, n=5, cutoff=0.5)
    miss = f"{p}: no column {', '.join(map(repr, unknown))}"
    if not close:
        return f"{miss}; none of the {len(names)} fields of one sample ({label}) is close"
    return f"{miss}; closest fields of one sample ({label}): {', '.join(_value(n) for n in close)}"


#: Field names that look like each quantity: exact (lower case), then name endings.
_GUESS = {
    "time": (("key", "time", "t", "timestamp", "time_s", "sec", "seconds", "ms", "stamp"),
             ("time", "stamp", "_t", "_ms", "_s")),
    "yaw": (("yaw", "ey", "ry", "heading"), ("rot.y", "yaw", ".ey")),
    "pitch": (("pitch", "ex", "rx"), ("rot.x", "pitch", ".ex")),
    "roll": (("roll", "ez", "rz"), ("rot.z", "roll", ".ez")),
}  # fmt: skip


def columns_example(path: str | os.PathLike) -> str:
    """A ``--columns`` map of the file's own fields that look like each quantity (``COL``
    for a quantity none looks like; ``--time-format FMT`` after it when the time field is
    not a number), for messages: only names that match a known pattern are quoted (a
    header is never listed: docs/reliability.md); ``""`` if the file is no table of at
    least three fields or none looks like an angle. Signs and units need the user's check."""
    try:
        cols, rows = _read_table(path)
    except (InputError, OSError, ValueError):
        return ""
    free = [str(c) for c in (rows[0][1] if rows else cols)]
    if len(free) < 3:
        return ""
    out = {}
    for key, (exact, ends) in _GUESS.items():
        hit = next((n for n in free if n.lower() in exact), None)
        hit = hit or next((n for n in free if n.lower().endswith(ends)), None)
        if hit is not None:
            out[key] = hit[:30]
            free.remove(hit)
    if not out.keys() & {"yaw", "pitch"}:
        return ""
    text = ",".join(f"{k}={out.get(k, 'COL')}" for k in COLUMN_KEYS if k in out or k != "roll")
    t0 = rows[0][1].get(out["time"]) if rows and "time" in out else 0.0
    try:
        float(t0)
    except (TypeError, ValueError):  # a clock time such as 20210510Z-200400_686Z
        return text + " --time-format FMT"
    return text


def _clock_seconds(p, label: str, value, fmt: str) -> float:
    """Seconds since 1970 (UTC) of a clock time ``value`` in ``strptime`` format ``fmt``."""
    try:
        d = datetime.strptime(str(value).strip(), fmt)
    except ValueError:
        raise InputError(
            f"{p}: {label}: time {_value(str(value))} does not match --time-format {fmt!r}"
        ) from None
    return (d if d.tzinfo else d.replace(tzinfo=UTC)).timestamp()


def _row_numbers(p, cmap: dict, keys: list[str], label: str, row: dict, time_format):
    """The mapped values of one row as floats; errors name the row and the column."""
    out = []
    for key in keys:
        col = cmap[key][0]
        if col not in row:
            raise InputError(f"{p}: {label} has no column {col!r}")
        v = row[col]
        if key == "time" and time_format:
            out.append(_clock_seconds(p, label, v, time_format))
            continue
        try:
            if isinstance(v, bool):
                raise TypeError(col)
            x = float(v)
        except (TypeError, ValueError):
            raise InputError(
                f"{p}: {label}, column {col!r} ({key}): non-numeric value {_value(str(v))}"
            ) from None
        if not math.isfinite(x):
            raise InputError(f"{p}: {label}, column {col!r}: value is not finite")
        out.append(x)
    return out


class _Table:
    """A log's columns (every name seen, in order), its first row (for messages) and the
    mapped numbers of its kept rows (``data``, (N, len(keys)); row labels ``kind`` +
    ``numbers``), filled row by row: no row is kept as a dict. ``problem``: the first
    row's error, raised once the map's columns are known to exist."""

    def __init__(self, p, cmap: dict, keys: list[str], time_format: str | None, skip_rows: int):
        self.p, self.cmap, self.keys, self.time_format = p, cmap, keys, time_format
        self.skip, self.seen, self.kind = skip_rows, 0, "line"
        self.cols: dict[str, None] = {}
        self.first: list[tuple[str, dict]] = []
        self.values, self.numbers = array("d"), array("q")
        self.problem: InputError | None = None

    def add(self, number: int, row: dict) -> None:
        self.seen += 1
        self.cols.update(dict.fromkeys(row))
        if not self.first:
            self.first.append((f"{self.kind} {number}", row))
        if self.seen <= self.skip or self.problem is not None:
            return
        try:
            self.values.extend(_row_numbers(self.p, self.cmap, self.keys, f"{self.kind} {number}",
                                            row, self.time_format))  # fmt: skip
        except InputError as e:
            self.problem = e
            return
        self.numbers.append(number)

    @property
    def data(self):
        return np.frombuffer(self.values, dtype=np.float64).reshape(-1, len(self.keys))


def _sample_row(key, v) -> dict:
    row = {} if key is None else {"key": key}
    if isinstance(v, (dict, list)):
        return _flatten(v, "", row)
    row["value"] = v
    return row


def _stream_json(t: _Table) -> None:
    """The rows of a JSON log, entry by entry (:mod:`jsonlog`: the document is never held
    whole). A top-level object of one key holding samples is a wrapper (:func:`_descend`):
    its samples are the rows (that one value decoded whole)."""
    t.kind = "entry"
    held = None  # the first entry, until a second shows the top level is no wrapper
    for i, (key, v) in enumerate(json_entries(t.p)):
        if i == 0 and key is not None and _is_samples(v):
            held = (key, v)
            continue
        if held is not None:
            t.add(1, _sample_row(*held))
            held = None
        t.add(i + 1, _sample_row(key, v))
    if held is not None:
        obj, _ = _descend({held[0]: held[1]})
        items = obj.items() if isinstance(obj, dict) else ((None, x) for x in obj)
        for i, (key, v) in enumerate(items):
            t.add(i + 1, _sample_row(key, v))


def _stream_text(t: _Table) -> None:
    """The rows of a delimited log (as :func:`_text_table` reads them)."""
    with open(t.p, encoding="utf-8-sig", errors="replace") as fh:
        cols, rows = _text_table(t.p, fh.read())
    t.cols.update(dict.fromkeys(cols))
    for label, row in rows:
        t.add(int(label.split(" ", 1)[1]), row)


def load_columns(
    path: str | os.PathLike,
    columns: str | dict,
    *,
    angles: str = "deg",
    time_scale: float = 1.0,
    time_from_first: bool = False,
    time_format: str | None = None,
    skip_rows: int = 0,
    drop_zero_rows: bool = False,
) -> HeadPath:
    """Read a head log through a column map (see the module doc). InputError, naming the
    file, for unknown columns (the file's columns are listed), a row without a mapped
    column, a non-numeric value or a time not in ``time_format`` (row and column named),
    or times not increasing; ClockTimeWarning for clock timestamps."""
    p = check_input_file(path, "head path")
    cmap = parse_column_map(columns) if isinstance(columns, str) else dict(columns)
    if angles not in ("deg", "rad"):
        raise InputError(f"--angles must be deg or rad; got {angles!r}")
    if not (math.isfinite(time_scale) and time_scale != 0):
        raise InputError(f"--time-scale must be a finite non-zero factor; got {time_scale}")
    if skip_rows < 0:
        raise InputError(f"--skip-rows must be >= 0; got {skip_rows}")
    keys = [k for k in COLUMN_KEYS if k in cmap]
    table = _Table(p, cmap, keys, time_format, skip_rows)
    (_stream_json if starts_as_json(p) else _stream_text)(table)  # arrays, not row dicts
    unknown = [c for c, _ in cmap.values() if c not in table.cols]
    if unknown:
        raise InputError(_unknown_message(p, unknown, table.first))
    if table.problem is not None:
        raise table.problem
    if table.seen <= skip_rows:
        raise InputError(f"{p}: head path file has no data rows" + (
            f" after --skip-rows {skip_rows}" if skip_rows else ""))  # fmt: skip
    data, labels = table.data, np.frombuffer(table.numbers, dtype=np.int64)
    if drop_zero_rows:
        nonzero = np.any(data[:, 1:] != 0.0, axis=1)
        data, labels = data[nonzero], labels[nonzero]
        if not len(data):
            raise InputError(f"{p}: every row's angles are 0 (--drop-zero-rows left nothing)")
    t = data[:, 0] * (1.0 if time_format else float(time_scale))
    keep = _dedupe_times(t)
    t, data = t[keep], data[keep]
    labels = labels[keep]
    if time_from_first or time_format:
        t = t - t[0]
    elif abs(float(t[0])) > CLOCK_TIME_S:
        warnings.warn(
            f"{p}: times start at {float(t[0]):.4g} s: these look like CLOCK TIMESTAMPS, not "
            "seconds from the video start; pass --time-from-first (or --time-format) if so",
            ClockTimeWarning,
            stacklevel=2,
        )
    _check_increasing(p, t, labels, table.kind)
    ang = {}
    for key in ("yaw", "pitch", "roll"):
        if key not in cmap:
            ang[key] = np.zeros_like(t)
            continue
        a = data[:, keys.index(key)] * cmap[key][1]
        if angles == "rad":
            a = np.degrees(a)
        ang[key] = (a + 180.0) % 360.0 - 180.0  # [0, 360) -> [-180, 180)
    spec = ",".join(f"{k}={'-' if sg < 0 else ''}{c}" for k, (c, sg) in cmap.items())
    src = f"{p}[{spec}]"
    return HeadPath.from_angles_deg(t, ang["yaw"], ang["pitch"], ang["roll"], source=src)
