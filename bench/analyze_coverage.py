"""Coverage of the study statistics' intervals on simulated studies with a known effect, and the analysis time of 48 participants x 2 conditions x 3 videos.

Figures:
* coverage: 200 seeded simulated studies (``simulator.analyze.simulate``: 24 participants,
  both conditions, 3 videos of flow 200..1400 deg/s, a true condition effect of 5 SSQ
  points, random participant and video intercepts). The fraction of runs whose reported 95 %
  interval of the model's condition term contains the true 5 (goal >= 90 %), and, beside
  it, the fraction whose bootstrap interval of the matched-pairs rank-biserial r contains
  the population r (estimated once from a simulated study of 20000 participants);
* time: ``vimsim analyze DATA.csv -o OUT --power 0.8`` on 48 participants x 2 conditions x
  3 videos (288 rows), wall clock with the interpreter's start-up, median of 3 runs (goal
  <= 3 s), as a ratio to ``vimsim --help`` (the CLI's start-up), to importing the libraries
  the analysis needs (pandas, scipy.stats, statsmodels, matplotlib: the floor any such
  analysis pays) and to ``python -c pass``, all measured in the same run.
  Add ``--runs 0`` for the timing alone.

Run: .venv/bin/python bench/analyze_coverage.py [--runs 200]
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
OUT = REPO / "bench" / "_out" / "analyze_coverage"

from simulator.analyze.data import read_study
from simulator.analyze.design import design_table
from simulator.analyze.simulate import SIM_HEADER, simulated_rows, write_simulated
from simulator.analyze.stats import (
    StatsOptions,
    _paired_row,
    _rb_paired,
    fit_model,
    participant_means,
)

EFFECT = 5.0


def _population_r(seed: int = 999_999) -> float:
    """The matched-pairs rank-biserial r of a very large simulated study (the target),
    from the participants' mean differences B - A as the tests form them."""
    df = pd.DataFrame(simulated_rows(20000, videos=3, effect=EFFECT, seed=seed), columns=SIM_HEADER)
    w = df.groupby(["id", "condition"])["ssq_total"].mean().unstack()
    return float(_rb_paired((w["B"] - w["A"]).to_numpy()[None, :])[0])


def coverage(runs: int) -> tuple[float, float, int]:
    """(model interval coverage, bootstrap r interval coverage, runs that did not converge)."""
    r_true = _population_r()
    hit_model = hit_r = not_conv = 0
    for seed in range(runs):
        path = write_simulated(
            OUT / "run.csv", simulated_rows(24, videos=3, effect=EFFECT, seed=seed)
        )
        study = read_study(path)
        d = design_table(study, study.participants, ("A", "B"))
        rows, info = fit_model(d.table, "none", 0.05, crossed_video=True)
        not_conv += not info["converged"]
        c = next(r for r in rows if r["term"] == "condition[T.B]")
        hit_model += c["ci_low"] <= EFFECT <= c["ci_high"]
        w = participant_means(d.table, "ssq_total")
        diff = (w["B"] - w["A"]).to_numpy(dtype=np.float64)
        t = _paired_row("ssq_total", diff, StatsOptions(seed=seed), np.random.default_rng(seed))
        hit_r += t["effect_ci_low"] <= r_true <= t["effect_ci_high"]
    print(f"population matched-pairs rank-biserial r (20000 participants): {r_true:.4f}")
    return hit_model / runs, hit_r / runs, not_conv


def _wall(cmd: list[str], repeats: int = 3) -> float:
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        subprocess.run(
            cmd, check=True, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
        )
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def timing() -> tuple[float, float, float, float]:
    """Median wall seconds of the analysis, of ``vimsim --help``, of importing the
    libraries the analysis needs, and of ``python -c pass``."""
    data = write_simulated(OUT / "48x2x3.csv", simulated_rows(48, videos=3, effect=EFFECT, seed=1))
    py = sys.executable
    libs = (
        "import pandas, scipy.stats, statsmodels.formula.api, matplotlib; "
        "matplotlib.use('Agg'); import matplotlib.pyplot"
    )
    t_pass = _wall([py, "-c", "pass"])
    t_help = _wall([py, "-m", "simulator", "--help"])
    t_libs = _wall([py, "-c", libs])
    t_an = _wall(
        [py, "-m", "simulator", "analyze", str(data), "-o", str(OUT / "report"), "--power", "0.8"]
    )
    return t_an, t_help, t_libs, t_pass


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=200)
    args = ap.parse_args()
    OUT.mkdir(parents=True, exist_ok=True)
    np.seterr(all="ignore")
    t0 = time.perf_counter()
    if args.runs <= 0:
        _timing_report()
        return
    cov_m, cov_r, nc = coverage(args.runs)
    print(
        f"coverage of the 95 % interval, {args.runs} seeded runs (24 participants x 2 "
        f"conditions x 3 videos, true effect {EFFECT} SSQ points):"
    )
    print(
        f"  model condition term (MixedLM, crossed participant + video): {cov_m:.1%} "
        f"(goal >= 90 %, ratio to goal {cov_m / 0.9:.3f}); not converged: {nc}"
    )
    print(f"  bootstrap interval of the rank-biserial r vs. the population r: {cov_r:.1%}")
    print(f"  ({time.perf_counter() - t0:.0f} s for the coverage runs)")
    _timing_report()


def _timing_report() -> None:
    t_an, t_help, t_libs, t_pass = timing()
    print(
        "analysis of 48 participants x 2 conditions x 3 videos (288 rows), with start-up, "
        "median of 3:"
    )
    print(
        f"  vimsim analyze --power 0.8: {t_an:.2f} s (goal <= 3 s, ratio to goal {t_an / 3.0:.2f})"
    )
    print(
        f"  reference vimsim --help: {t_help:.2f} s; ratio analyze / --help = {t_an / t_help:.2f}"
    )
    print(
        f"  reference import of pandas, scipy.stats, statsmodels, matplotlib: {t_libs:.2f} s; "
        f"ratio analyze / imports = {t_an / t_libs:.2f}"
    )
    print(
        f"  reference python -c pass: {t_pass:.3f} s; ratio analyze / python = {t_an / t_pass:.1f}"
    )
    print(f"  load average during the run: {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs")


if __name__ == "__main__":
    main()
