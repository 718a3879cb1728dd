"""Shared parsing and checks of the head-path readers (tables, finite values, increasing times, unit warnings)."""

from __future__ import annotations

import difflib
import math
import warnings
from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from simulator.core.errors import InputError
from simulator.core.fileio import csv_row
from simulator.traces.path import (
    COARSE_STEP_DEG,
    CoarseSamplingWarning,
    HeadPath,
    MillisecondsWarning,
    RadiansWarning,
)


def _value(v: str) -> str:
    """One field of a file as a message quotes it: stripped, at most 30 characters."""
    v = v.strip()
    return repr(v[:30] + ("..." if len(v) > 30 else ""))


def _hint(missing: str, found: list[str]) -> str:
    """``"; did you mean 'x'?"`` for the closest of ``found`` (a typo), else ``""``. Only
    that one name is quoted: messages never echo a file's content beyond the field
    that failed."""
    m = difflib.get_close_matches(missing, [f.strip() for f in found], n=1, cutoff=0.6)
    return f"; did you mean {_value(m[0])}?" if m else ""


def _first_line(p: Path) -> str:
    with open(p, encoding="utf-8-sig", errors="replace") as fh:
        for line in fh:
            if line.strip():
                return line.strip()
    raise InputError(f"{p}: head path file is empty")


def _warn_if_coarse(hp: HeadPath) -> None:
    """CoarseSamplingWarning when consecutive poses differ by more than 90 deg."""
    if hp.n < 2:
        return
    r = hp.rotations
    step = np.degrees((r[:-1].inv() * r[1:]).magnitude())
    big = np.flatnonzero(step > COARSE_STEP_DEG)
    if big.size:
        k = int(big[0])
        t = hp.times_s
        more = f" ({big.size} such steps)" if big.size > 1 else ""
        warnings.warn(
            f"{hp.source or 'head path'}: poses at {t[k]:.6g} s and {t[k + 1]:.6g} s differ by "
            f"{step[k]:.0f} deg{more}: sampling too coarse; interpolation takes the shortest arc",
            CoarseSamplingWarning,
            stacklevel=3,
        )


def _parse_table(
    p: Path, sep: str | None, *, what: str
) -> tuple[list[str], NDArray[np.float64], list[int]]:
    """Header (stripped names) and float rows of a delimited text file.

    Returns ``(columns, data (N, C), line_numbers)``; InputError on ragged or
    non-numeric rows (names the line) and on a file with a header only.
    """
    with open(p, encoding="utf-8-sig", errors="replace") as fh:
        lines = fh.read().splitlines()
    rows = [
        (i + 1, ln) for i, ln in enumerate(lines) if ln.strip() and not ln.lstrip().startswith("#")
    ]
    if not rows:
        raise InputError(f"{p}: {what} file is empty")
    split = (lambda s: csv_row(s, p)) if sep == "," else (lambda s: s.split())
    cols = [c.strip() for c in split(rows[0][1])]
    if len(rows) < 2:
        raise InputError(f"{p}: {what} file has a header but no data rows")
    data = np.empty((len(rows) - 1, len(cols)))
    for k, (ln, text) in enumerate(rows[1:]):
        vals = split(text)
        if len(vals) != len(cols):
            raise InputError(f"{p}: line {ln} has {len(vals)} fields; the header has {len(cols)}")
        try:
            data[k] = [float(v) for v in vals]
        except ValueError:
            j = next(j for j, v in enumerate(vals) if not _is_float(v))
            raise InputError(
                f"{p}: line {ln}, column {_value(cols[j])}: non-numeric value {_value(vals[j])}"
            ) from None
    return cols, data, [ln for ln, _ in rows[1:]]


def _is_float(v: str) -> bool:
    try:
        float(v)
    except ValueError:
        return False
    return True


def _check_finite(
    p: Path, cols: list[str], data: NDArray, lines: list[int], what: str = "line"
) -> None:
    """InputError naming ``{what} {lines[k]}`` (file line, or 1-based sample number)."""
    bad = ~np.isfinite(data)
    if np.any(bad):
        k, c = np.argwhere(bad)[0]
        raise InputError(
            f"{p}: {what} {lines[k]}: {cols[c]} is {data[k, c]}; expected a finite number"
        )


def _check_increasing(p: Path, t: NDArray, lines: list[int], what: str = "line") -> None:
    """InputError naming ``{what} {lines[k]}``; ``lines`` labels the rows of ``t``."""
    d = np.diff(t)
    if np.any(d <= 0):
        k = int(np.flatnonzero(d <= 0)[0])
        raise InputError(
            f"{p}: time is not strictly increasing at {what} {lines[k + 1]} "
            f"({t[k + 1]:.6g} s after {t[k]:.6g} s)"
        )


def _warn_if_radians(p: Path, *angles: NDArray) -> None:
    """RadiansWarning only on strong evidence: every angle within +-2*pi *and* the first
    (yaw) spanning more than 3 units with at least 10 samples: in degrees that would be a
    viewer who never turned more than 6 deg yet moved over 3 deg; in radians, over 170 deg
    of looking around. Small degree values (a still viewer) raise nothing."""
    a = np.concatenate([np.abs(np.ravel(x)) for x in angles])
    yaw = np.ravel(angles[0]) if angles else np.zeros(0)
    if (
        a.size
        and yaw.size >= 10
        and a.max() <= 2 * math.pi + 1e-9
        and float(yaw.max() - yaw.min()) > 3.0
    ):
        warnings.warn(
            f"{p}: every angle lies within +-2*pi (max {a.max():.3f}) while yaw spans "
            f"{float(yaw.max() - yaw.min()):.2f}: these look like RADIANS, "
            "but this format holds DEGREES; convert them (x 180/pi) if so",
            RadiansWarning,
            stacklevel=3,
        )


def _warn_if_milliseconds(p: Path, t: NDArray) -> None:
    """MillisecondsWarning when times look like milliseconds: at least 20 samples, a
    median step of 4 to 50 (a 20-250 Hz tracker in ms; in seconds, one sample every
    4-50 s) and a span over 200."""
    if t.size >= 20:
        step = float(np.median(np.diff(t)))
        if 4.0 <= step <= 50.0 and float(t[-1] - t[0]) > 200.0:
            warnings.warn(
                f"{p}: time_s steps by {step:.3g} (median) over {float(t[-1] - t[0]):.6g}: these "
                "look like MILLISECONDS, but this format holds seconds; divide by 1000 if so",
                MillisecondsWarning,
                stacklevel=3,
            )


def _check_pitch(p: Path, pitch: NDArray, lines: list[int], what: str = "line") -> None:
    """InputError for a pitch outside [-90, 90] deg (naming the first such row)."""
    bad = np.flatnonzero(np.abs(pitch) > 90.0 + 1e-9)
    if bad.size:
        k = int(bad[0])
        raise InputError(
            f"{p}: {what} {lines[k]}: pitch_deg is {pitch[k]:.6g}; expected degrees in [-90, 90]"
        )


def _columns(
    p: Path, cols: list[str], need: tuple[str, ...], optional: tuple[str, ...] = ()
) -> dict[str, int]:
    missing = [c for c in need if c not in cols]
    unknown = [c for c in cols if c not in need and c not in optional]
    if missing or unknown:
        exp = ",".join(need + optional)
        raise InputError(
            f"{p}: columns {cols} do not match; expected {exp}"
            + (f" (missing {missing})" if missing else "")
            + (f" (unknown {unknown})" if unknown else "")
        )
    return {c: cols.index(c) for c in cols}


def _quats_to_rotation(p: Path, q_xyzw: NDArray, lines: list[int]) -> Rotation:
    n = np.linalg.norm(q_xyzw, axis=1)
    bad = n < 1e-9
    if np.any(bad):
        k = int(np.flatnonzero(bad)[0])
        raise InputError(
            f"{p}: line {lines[k]}: quaternion has zero length; expected a unit quaternion"
        )
    return Rotation.from_quat(q_xyzw / n[:, None])


def _dedupe_times(t: NDArray) -> NDArray[np.bool_]:
    """Mask keeping the first row of each run of equal times."""
    keep = np.ones(t.size, bool)
    keep[1:] = np.diff(t) != 0
    return keep
