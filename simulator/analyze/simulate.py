"""Simulated study data with a known condition effect, as DATA.csv rows, for checks of the statistics.

The SSQ total of participant i, video v, condition c is
``base + effect x [c = B] + flow_slope x flow + mssq_slope x mssq + u_i + w_v + e`` with
normal ``u_i`` (participant), ``w_v`` (video) and ``e`` (residual): the model
``ssq_total ~ condition + flow + mssq + (1 | participant) + (1 | video)`` with its condition
coefficient equal to ``effect``. The subscores are fixed shares of the total (written as
``ssq_n, ssq_o, ssq_d, ssq_total``), so every row is valid DATA.csv.
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from simulator.core.errors import InputError
from simulator.core.fileio import atomic_output

__all__ = ["SIM_HEADER", "simulated_rows", "write_simulated"]

SIM_HEADER = ("id", "condition", "video", "ssq_n", "ssq_o", "ssq_d", "ssq_total", "mssq", "flow")


def simulated_rows(
    participants: int,
    *,
    videos: int = 1,
    effect: float = 10.0,
    design: str = "within",
    seed: int = 0,
    base: float = 60.0,
    flow_slope: float = 0.01,
    mssq_slope: float = 0.5,
    sd_participant: float = 8.0,
    sd_video: float = 4.0,
    sd_residual: float = 6.0,
) -> list[list[object]]:
    """Rows of :data:`SIM_HEADER`: conditions ``A`` (reference) and ``B``.

    Parameters
    ----------
    participants : int
        Participants (between: alternately in A and B).
    videos : int
        Videos each participant watches (per condition, within); video flows (deg/s) range
        from 200 to 1400 (``flow_slope`` x flow is their effect on the SSQ total).
    effect : float
        The true B - A difference of the SSQ total at equal flow and MSSQ (SSQ points).
    design : ``"within"`` or ``"between"``
    seed : int
    """
    if design not in ("within", "between") or participants < 2 or videos < 1:
        raise InputError(
            f"simulated study: design within|between, >= 2 participants and "
            f">= 1 video; got {design!r}, {participants}, {videos}"
        )
    rng = np.random.default_rng(seed)
    vid_flow = np.linspace(200.0, 1400.0, videos) if videos > 1 else np.array([800.0])
    w = rng.normal(0.0, sd_video, videos)
    rows: list[list[object]] = []
    for i in range(participants):
        ms = float(np.round(rng.uniform(0.0, 40.0), 1))
        u = rng.normal(0.0, sd_participant)
        conds = ("A", "B") if design == "within" else ("AB"[i % 2],)
        for c in conds:
            for v in range(videos):
                flow = float(np.round(vid_flow[v] * rng.uniform(0.9, 1.1), 1))
                tot = (
                    base
                    + effect * (c == "B")
                    + flow_slope * flow
                    + mssq_slope * ms
                    + u
                    + w[v]
                    + rng.normal(0.0, sd_residual)
                )
                tot = float(np.clip(tot, 0.0, 200.0))
                rows.append(
                    [
                        f"P{i + 1:03d}",
                        c,
                        f"V{v + 1}",
                        round(0.8 * tot, 6),
                        round(0.6 * tot, 6),
                        round(1.2 * tot, 6),
                        round(tot, 6),
                        ms,
                        flow,
                    ]
                )
    return rows


def write_simulated(path: str | Path, rows: list[list[object]], *, comment: str = "") -> Path:
    """Write rows of :data:`SIM_HEADER` as DATA.csv (``#`` comment line first), atomically."""
    p = Path(path)
    with atomic_output(p) as tmp, open(tmp, "w", newline="", encoding="utf-8") as fh:
        fh.write(f"# SIMULATED data, not from any participant. {comment}\n")
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(SIM_HEADER)
        w.writerows(rows)
    return p
