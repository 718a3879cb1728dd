"""360VidStr head traces: aggregated files holding many users of one video."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from simulator.core.errors import InputError
from simulator.traces.path import HeadPath
from simulator.traces.readers.common import _check_finite, _check_increasing
from simulator.traces.readers.formats import TraceFormat


def _read_360vidstr(p: Path, user: int | None) -> HeadPath:
    """360VidStr aggregated ``<video>.txt``: line 1 times (s, 10 Hz), then per user a line of
    pitch and a line of yaw, radians; no roll. Signs/origin undocumented (taken as ours:
    yaw + right, pitch + up). A user's lines may be shorter than the time line: the path
    ends at that user's last sample."""
    rows = _parse_360vidstr(p)
    n_users = (len(rows) - 1) // 2
    if user is None:
        if n_users == 1:
            user = 1
        else:
            raise InputError(f"{p}: holds {n_users} users; choose one with --user 1..{n_users}")
    if not 1 <= user <= n_users:
        raise InputError(f"{p}: no user {user}; choose --user 1..{n_users}")
    return _360vidstr_user(p, rows, user)


def _parse_360vidstr(p: Path) -> list[NDArray]:
    """The number rows of a 360VidStr aggregated file (2n+1 of them), read once."""
    with open(p, encoding="utf-8", errors="replace") as fh:
        lines = [ln for ln in fh.read().splitlines() if ln.strip()]
    try:
        rows = [np.array(ln.split(), dtype=float) for ln in lines]
    except ValueError:
        raise InputError(f"{p}: not a 360VidStr aggregated file (non-numeric values)") from None
    if len(rows) < 3 or len(rows) % 2 == 0:
        raise InputError(
            f"{p}: a 360VidStr file has 2n+1 lines (times, then pitch and yaw per user); found {len(rows)}"
        )
    return rows


def _360vidstr_user(p: Path, rows: list[NDArray], user: int) -> HeadPath:
    """User ``user`` (1-based) of the parsed rows of a 360VidStr file."""
    pitch, yaw = rows[2 * user - 1], rows[2 * user]
    n = min(len(pitch), len(yaw), len(rows[0]))
    if n < 1:
        raise InputError(f"{p}: user {user} has no samples")
    t = rows[0][:n]
    data = np.stack([t, yaw[:n], pitch[:n]], axis=1)
    labels = list(range(1, n + 1))  # 1-based sample (column) numbers
    _check_finite(p, ["time", "yaw", "pitch"], data, labels, "sample")
    _check_increasing(p, t, labels, "sample")
    return HeadPath.from_angles_deg(
        t, np.degrees(yaw[:n]), np.degrees(pitch[:n]), 0.0, source=f"{p}:user{user}"
    )


def _all_users(p: Path) -> dict[int, HeadPath]:
    rows = _parse_360vidstr(p)
    return {u: _360vidstr_user(p, rows, u) for u in range(1, (len(rows) - 1) // 2 + 1)}


def _count_users(p: Path) -> int:
    """Users of a 360VidStr file from its line count (no parsing)."""
    with open(p, encoding="utf-8", errors="replace") as fh:
        n = sum(1 for ln in fh if ln.strip())
    return max(1, (n - 1) // 2)


def _numeric_line(s) -> bool:
    try:
        [float(v) for v in s.head.split()]
    except ValueError:
        return False
    return True


#: The format this module reads (the registry of ``simulator.traces.readers``).
TRACE_FORMATS = (
    TraceFormat("360vidstr", lambda p, user=None, **_: _read_360vidstr(p, user), _numeric_line,
                rank=60, read_all=_all_users, count_users=_count_users),
)  # fmt: skip
