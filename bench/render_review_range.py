"""Cost of ``render --review`` and of ``render --start/--end`` against a plain full render.

Same input for all three runs: three.js ``pano.mp4`` (real hand-held 360 video, 1920x1080,
25 fps, 188 frames), its default grid (cached in ``outputs/bench15/``, made by
bench/opacity_flicker.py or here), the AVTrack360 subject-2 trace of video 6, stereo
default outputs of a mono source (one eye file), eye size ``--eye-size`` (default 720),
the comfort opacity rule; best of ``--repeat`` (3) interleaved runs. Figures:

* review: wall time of ``render --review`` / plain ``render`` (goal <= 1.3);
* range: wall time of a quarter of the video (``--start 0 --end 1.88``) / the full render
  (goal <= 0.35 for a 10 s range of 40 s).

The reference (plain full render) is measured in the same run. Usage:
``.venv/bin/python bench/render_review_range.py [--eye-size 1440]``
"""

from __future__ import annotations

import argparse
import tempfile
import time

from _pano import TRACES, VIDEO, pano_grid  # bench/_pano.py: the clip, its cached grid

TRACE = TRACES / "2.json"


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--eye-size", type=int, default=720)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    from simulator.media.gridfile import load_grid
    from simulator.mitigation.grf import GrfConfig, comfort_rule
    from simulator.render import RenderConfig, create_context
    from simulator.traces.readers import load_headpath
    from simulator.viewing.job import render_viewing

    gp = pano_grid()
    grid = load_grid(gp)
    hp = load_headpath(TRACE, video="6.mp4")
    ctx = create_context()
    cfg = RenderConfig(eye_size=(args.eye_size, args.eye_size), grf=GrfConfig())
    n = grid.n_frames
    quarter = round(n / 4) / grid.fps

    def run(**kw):
        with tempfile.TemporaryDirectory() as d:
            t0 = time.perf_counter()
            s = render_viewing(VIDEO, hp, d, grid=grid, config=cfg, rule=comfort_rule(),
                               progress=False, ctx=ctx, hold=True, **kw)  # fmt: skip
            return time.perf_counter() - t0, s["frames_written"]

    run(end_s=0.4)  # warm-up (shader compile, overlap table, caches)
    # Interleaved repeats, best of each: the machine is shared, so single runs are noisy.
    runs: dict[str, list] = {"full": [], "review": [], "quarter": []}
    for _ in range(args.repeat):
        runs["full"].append(run())
        runs["review"].append(run(review=True))
        runs["quarter"].append(run(start_s=0.0, end_s=quarter))
    (t_full, n_full), (t_rev, n_rev), (t_q, n_q) = (
        min(runs[k]) for k in ("full", "review", "quarter")
    )
    print(
        f"{VIDEO.name}, eye {args.eye_size}x{args.eye_size}, renderer {ctx.info.get('GL_RENDERER')}"
    )
    print(f"plain render (reference): {t_full:.2f} s for {n_full} frames")
    print(
        f"render --review:          {t_rev:.2f} s for {n_rev} frames  ratio {t_rev / t_full:.3f} (goal <= 1.3)"
    )
    print(
        f"render --end {quarter:.2f} (1/4):  {t_q:.2f} s for {n_q} frames  ratio {t_q / t_full:.3f} (goal <= 0.35)"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
