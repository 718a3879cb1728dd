"""Any lab's head log: a delimited table read through a column map (``headpath convert --columns``).

A map names the file's column of each quantity, ``time=COL,yaw=COL,pitch=COL[,roll=COL]``;
a leading ``-`` flips that angle's sign (``pitch=-deg_pitch``). Angles are in degrees or
radians (``angles``), yaw + right, pitch + up, roll + right ear down *after* the sign
flips, applied yaw, then pitch, then roll (intrinsic: SPEC's order, which is also Unity's
``transform.eulerAngles`` Z, X, Y extrinsic order). Angles in [0, 360) are wrapped to
+-180. Time is the column times ``time_scale`` (0.001 for milliseconds), minus the first
time if ``time_from_first``. Rows repeating the previous time are dropped (loggers that
sample faster than the pose updates).

A Unity-style log (left-handed, x right, y up, z forward; Euler degrees in [0, 360);
pitch + looks down, roll + left ear down) needs only ``yaw=Y,pitch=-X,roll=-Z``.
"""

from __future__ import annotations

import math
import os

import numpy as np

from simulator.core.errors import InputError
from simulator.core.fileio import check_input_file
from simulator.traces.path import HeadPath
from simulator.traces.readers.common import _check_increasing, _dedupe_times, _hint, _value

__all__ = ["COLUMN_KEYS", "load_columns", "parse_column_map"]

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


def load_columns(
    path: str | os.PathLike,
    columns: str | dict,
    *,
    angles: str = "deg",
    time_scale: float = 1.0,
    time_from_first: bool = False,
) -> HeadPath:
    """Read a head log through a column map (see the module doc). The delimiter is taken
    from the header line (comma, semicolon, tab, else whitespace). InputError, naming the
    file, for unknown columns (the file's columns are listed), a row without a mapped
    column, a non-numeric value (line and column named), or times not increasing."""
    p = check_input_file(path, "head path")
    cmap = parse_column_map(columns) if isinstance(columns, str) else dict(columns)
    if angles not in ("deg", "rad"):
        raise InputError(f"--angles must be deg or rad; got {angles!r}")
    if not (math.isfinite(time_scale) and time_scale != 0):
        raise InputError(f"--time-scale must be a finite non-zero factor; got {time_scale}")
    with open(p, encoding="utf-8-sig", errors="replace") as fh:
        lines = [(k + 1, ln) for k, ln in enumerate(fh.read().splitlines()) if ln.strip()]
    lines = [(k, ln) for k, ln in lines if not ln.lstrip().startswith("#")]
    if not lines:
        raise InputError(f"{p}: head path file is empty")
    head = lines[0][1]
    delim = next((d for d in (",", ";", "\t") if d in head), None)
    cols = _split(head, delim)
    unknown = [c for c, _ in cmap.values() if c not in cols]
    if unknown:
        raise InputError(
            f"{p}: no column {', '.join(map(repr, unknown))} among its {len(cols)} columns"
            f"{_hint(unknown[0], cols)}"
        )
    if len(lines) < 2:
        raise InputError(f"{p}: head path file has a header but no data rows")
    keys = [k for k in COLUMN_KEYS if k in cmap]
    idx = [cols.index(cmap[k][0]) for k in keys]
    data = np.empty((len(lines) - 1, len(keys)))
    line_no = []
    for r, (k, ln) in enumerate(lines[1:]):
        f = _split(ln, delim)
        for j, (key, i) in enumerate(zip(keys, idx)):
            if i >= len(f):
                raise InputError(
                    f"{p}: line {k} has {len(f)} fields, no column {cmap[key][0]!r} (field {i + 1})"
                )
            try:
                data[r, j] = float(f[i])
            except ValueError:
                raise InputError(
                    f"{p}: line {k}, column {cmap[key][0]!r} ({key}): non-numeric value {_value(f[i])}"
                ) from None
        line_no.append(k)
    bad = ~np.isfinite(data)
    if bad.any():
        r, j = np.argwhere(bad)[0]
        raise InputError(
            f"{p}: line {line_no[r]}, column {cmap[keys[j]][0]!r}: value is not finite"
        )
    t = data[:, 0] * float(time_scale)
    keep = _dedupe_times(t)
    t, data = t[keep], data[keep]
    line_no = [ln for ln, k in zip(line_no, keep) if k]
    if time_from_first:
        t = t - t[0]
    _check_increasing(p, t, line_no)
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
