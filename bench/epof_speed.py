"""EPOF query speed beside a 90 Hz headset's frame budget, and accuracy vs brute force.

Usage: python bench/epof_speed.py

Prints: table build time; one query from Python (median us, through
``ViewportOverlaps.epof`` and through ``epof_from_grid``) and its share of the 11.1 ms
frame budget of a 90 Hz headset; batch queries/s; ratios to the targets (single
<= 50 us, batch >= 200,000/s); EPOF error vs a 256x256-ray brute-force reference on
random orientations (roll, |pitch| up to 90).
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from simulator.epof import epof_from_grid, viewport_overlaps
from simulator.media.gridfile import load_grid, save_grid
from simulator.sphere.windows import grid_preset

FRAME_BUDGET_US = 1e6 / 90.0
SINGLE_TARGET_US = 50.0
BATCH_TARGET = 200_000.0


def main() -> int:
    g = grid_preset("default")
    T = 600
    rng = np.random.default_rng(0)
    pof = rng.uniform(1, 100, (T, *g.shape)).astype(np.float32)
    t0 = time.perf_counter()
    vo = viewport_overlaps(g, 107.0, 107.0)
    print(
        f"table build (default grid, 107 deg): {time.perf_counter() - t0:.2f} s, {vo.table.nbytes / 1e6:.1f} MB"
    )
    ts = []
    for i in range(5000):
        y, p, r = (i * 7.3) % 360 - 180, (i * 3.1) % 180 - 90, (i * 1.9) % 60 - 30
        t1 = time.perf_counter()
        vo.epof(pof, y, p, r, i % T)
        ts.append(time.perf_counter() - t1)
    single = float(np.median(ts)) * 1e6
    with tempfile.TemporaryDirectory() as d:
        meta = {"fps": 60.0, "n_frames": T, "flow": {}, "layout": "mono", "eye": "left",
                "video": {"path": "v", "width": 2, "height": 1, "sar": 1, "content_hash": ""}}  # fmt: skip
        save_grid(Path(d) / "g.npz", pof, pof, g, meta)
        gf = load_grid(Path(d) / "g.npz")
        epof_from_grid(gf, 0.0, 0.0, 0.0, 0)
        ts2 = []
        for i in range(3000):
            t1 = time.perf_counter()
            epof_from_grid(gf, i * 0.7, 10.0, 0.0, i % T)
            ts2.append(time.perf_counter() - t1)
    single2 = float(np.median(ts2)) * 1e6
    Q = 400_000
    y, p, r = rng.uniform(-180, 180, Q), rng.uniform(-90, 90, Q), rng.uniform(-180, 180, Q)
    f = rng.integers(0, T, Q)
    vo.epof(pof, y[:1000], p[:1000], r[:1000], f[:1000])
    t1 = time.perf_counter()
    vo.epof(pof, y, p, r, f)
    qps = Q / (time.perf_counter() - t1)
    print(f"single query (ViewportOverlaps.epof): median {single:.1f} us = {single / FRAME_BUDGET_US:.2%} of the "
          f"{FRAME_BUDGET_US / 1000:.1f} ms 90 Hz frame budget; target {SINGLE_TARGET_US:.0f} us, ratio {single / SINGLE_TARGET_US:.2f}")  # fmt: skip
    print(
        f"single query (epof_from_grid):       median {single2:.1f} us, ratio to target {single2 / SINGLE_TARGET_US:.2f}"
    )
    print(
        f"batch: {qps:,.0f} queries/s ({1e6 / qps:.2f} us each); target {BATCH_TARGET:,.0f}/s, ratio {qps / BATCH_TARGET:.2f}"
    )
    from simulator.testing.reference import brute_overlaps

    errs = []
    for _ in range(25):
        yy, pp, rr = rng.uniform(-180, 180), rng.uniform(-90, 90), rng.uniform(-180, 180)
        for kind in range(3):
            w = [rng.uniform(1, 100, g.shape), rng.lognormal(2, 1, g.shape),
                 np.where(rng.random(g.shape) < 0.15, 100.0, 1.0)][kind]  # fmt: skip
            ref_ol = brute_overlaps(g, yy, pp, rr, 107.0, 107.0)
            ref = (w * ref_ol).sum() / ref_ol.sum()
            errs.append(abs(vo.epof(w, yy, pp, rr) - ref) / ref)
    errs = np.array(errs)
    print(f"accuracy vs brute force (256^2 rays, {len(errs)} cases): median {np.median(errs):.4%}, "
          f"max {errs.max():.4%}; bound 1%, ratio {errs.max() / 0.01:.2f}")  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
