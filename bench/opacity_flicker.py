"""GRF opacity flicker on a real hand-held 360 video: the paper's rule vs smoothing and easing.

Video: three.js ``pano.mp4`` (real, hand-held camera, 25 fps, 7.5 s), preprocessed with the
default options (``vimsim preprocess``; the grid is cached in ``outputs/bench15/``). Head
paths: the 40 real AVTrack360 traces (subjects 2 and 3, 20 videos each; first 7.5 s).
EPOF: paper mode, 107 deg viewport, computed once per trace; each opacity rule is applied
to the same EPOF.

Figures per rule, over all frames of all traces:
* ``flicker``: share of frame steps whose opacity changes faster than 3 /s, i.e. by more
  than 0.1 per frame at 30 fps (the measure of docs/epof.md);
* ``jump>0.2``: share of frame steps with |opacity change| > 0.2 at the video's 25 fps;
* ``lag``: mean |opacity - paper opacity| (what the easing costs in fidelity to the EPOF);
* ratio of flicker to the paper rule's (the reference, measured in the same run).

Run: ``.venv/bin/python bench/opacity_flicker.py`` (the preprocess takes ~3 min once).
"""

from __future__ import annotations

import numpy as np
from _pano import TRACES, VIDEO, pano_grid  # bench/_pano.py: the clip, its cached grid

RULES = {
    "paper (no smoothing)": {},
    "smooth 0.2 s": {"smoothing_s": 0.2},
    "smooth 0.5 s": {"smoothing_s": 0.5},
    "ease in 0.2 / out 1.0 s": {"ease_in_s": 0.2, "ease_out_s": 1.0},
    "ease in 0.4 / out 1.5 s (default)": {"ease_in_s": 0.4, "ease_out_s": 1.5},
    "ease in 0.4 / out 1.5 + smooth 0.2": {"ease_in_s": 0.4, "ease_out_s": 1.5, "smoothing_s": 0.2},
}


def main() -> int:
    import json

    from simulator.epof import compute_epof
    from simulator.media.gridfile import load_grid
    from simulator.mitigation.grf import OpacityRule
    from simulator.traces.readers import load_headpath

    grid = load_grid(pano_grid())
    fps = float(grid.fps)
    epofs, thr = [], None
    for subj in ("2.json", "3.json"):
        names = [d["filename"] for d in json.loads((TRACES / subj).read_text())["data"]]
        for name in names:
            hp = load_headpath(TRACES / subj, video=name)
            res = compute_epof(grid, hp, hfov_deg=107, vfov_deg=107, hold=True)
            epofs.append(res.epof_dps)
            thr = res.thresholds_dps
    print(f"{VIDEO.name}: {grid.n_frames} frames at {fps:g} fps, {len(epofs)} real head traces, "
          f"opacity 0 at {thr[0]:.3g}, 1 at {thr[1]:.3g} deg/s")  # fmt: skip
    paper = [OpacityRule()(e, thr) for e in epofs]
    ref = None
    print(f"{'rule':38s} {'flicker':>8s} {'jump>0.2':>9s} {'lag':>6s} {'ratio':>6s}")
    for name, kw in RULES.items():
        rule = OpacityRule(**kw)
        ops = [rule(e, thr, fps=fps) for e in epofs]
        d = np.concatenate([np.diff(o) for o in ops])
        flick = float(np.mean(np.abs(d) * fps > 3.0))
        jump = float(np.mean(np.abs(d) > 0.2))
        lag = float(np.mean(np.concatenate([np.abs(o - p) for o, p in zip(ops, paper)])))
        ref = flick if ref is None else ref
        print(f"{name:38s} {flick:8.1%} {jump:9.1%} {lag:6.3f} {flick / ref:6.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
