"""Flow accuracy of ``vimsim preprocess`` and ``epof`` on synthetic scenes with analytic truth.

For each scene (``vimsim synth``: rotate, forward, coaster; plus the rotate scene on the
real photo ``petra.jpg`` when ``../shared`` is present) and each flow backend (dis,
farneback; ``torch:MODEL.pt`` with ``--torch MODEL.pt``):

* per-window relative error ``|pof_dps - truth| / truth`` over every (frame, window),
  truth = the solid-angle-weighted mean of the analytic angular speed over the window's
  rays at the middle of the frame interval (:func:`simulator.synth.window_truth_dps`);
  median and 90th percentile, and the same restricted to the windows whose centre is
  within 15 deg of the horizon (|pitch| <= 15);
* EPOF along a seeded look-around head path (107 deg viewport): relative error of
  ``compute_epof`` on the estimated grid against ``compute_epof`` on the truth grid
  (flow error only), and against the exact viewport truth (solid-angle mean of the
  analytic speed over the viewport's own rays: flow error + the window approximation);
  and the truth grid's EPOF against the exact truth (the paper's window averaging alone).

Prints a Markdown table and the ratio of the default backend's median error to the 10 %
goal on rotate and forward. ``--doc docs/accuracy.md`` rewrites the table there (between
the ``accuracy:begin``/``accuracy:end`` markers).

    .venv/bin/python bench/accuracy.py [--seconds 1.5] [--size 1024x512] [--window-size 256]
        [--backends dis,farneback] [--torch MODEL.pt] [--doc docs/accuracy.md]
"""

from __future__ import annotations

import argparse
import re
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from simulator.epof import compute_epof
from simulator.media.gridfile import load_grid
from simulator.preprocess import preprocess_video
from simulator.sphere.geometry import head_rotation, perspective_rays
from simulator.sphere.windows import grid_preset
from simulator.synth import SynthConfig, load_truth, make_scene, synthesize, window_truth_dps
from simulator.traces.path import synth as synth_headpath

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared"
PETRA = SHARED / "data" / "real" / "equirect" / "vrview" / "petra.jpg"
OUT = REPO / "bench" / "_out" / "accuracy"
GOAL = 0.10
OBLIQUE = (1.0, 2.0, 0.5)


def scenes(args) -> list[tuple[str, SynthConfig]]:
    base = {"seconds": args.seconds, "fps": 30.0, "size": args.size}
    out = [
        (
            "rotate (oblique axis, 30 deg/s)",
            SynthConfig("rotate", axis=OBLIQUE, omega_dps=30.0, **base),
        ),
        ("rotate (yaw, 90 deg/s)", SynthConfig("rotate", omega_dps=90.0, **base)),
        ("rotate (yaw, 360 deg/s)", SynthConfig("rotate", omega_dps=360.0, **base)),
        ("forward (2 m/s, tunnel)", SynthConfig("forward", speed_mps=2.0, **base)),
        ("coaster (mean 6 m/s)", SynthConfig("coaster", **base)),
    ]
    if PETRA.is_file() and not args.no_photo:
        out.append(
            (
                "rotate petra.jpg (oblique, 30 deg/s)",
                SynthConfig("rotate", axis=OBLIQUE, omega_dps=30.0, texture=str(PETRA), **base),
            )
        )
    return out


def viewport_truth_dps(scene, hp, times_frame, times_interval, fov_deg=107.0, rays=32):
    """Exact EPOF truth: solid-angle mean of the analytic speed over the viewport's rays."""
    dirs, sa = perspective_rays((rays, rays), fov_deg, fov_deg)
    d = dirs.reshape(-1, 3).astype(np.float64)
    w = sa.ravel().astype(np.float64)
    yaw, pitch, roll = hp.sample_angles_deg(times_frame, hold=True)
    out = np.empty(len(times_frame))
    for k in range(len(times_frame)):
        world = head_rotation(yaw[k], pitch[k], roll[k]).apply(d)
        s = scene.speed_dps(float(times_interval[k]), world, "mono")
        out[k] = np.sum(s * w) / w.sum()
    return out


def rel_stats(est, truth):
    rel = np.abs(est - truth) / np.maximum(truth, 1e-9)
    return float(np.median(rel)), float(np.percentile(rel, 90))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=1.0)
    ap.add_argument("--size", default="1024x512")
    ap.add_argument("--window-size", type=int, default=256)
    ap.add_argument("--backends", default="dis,farneback,sphere")
    ap.add_argument("--torch", default=None, metavar="MODEL.pt")
    ap.add_argument(
        "--slow-frames",
        type=int,
        default=12,
        help="frames evaluated for backends other than the first (farneback, torch are slow)",
    )
    ap.add_argument("--no-photo", action="store_true", help="skip the petra.jpg row")
    ap.add_argument("--doc", default=None, help="rewrite the table in this Markdown file")
    args = ap.parse_args(argv)
    w, h = (int(x) for x in args.size.lower().split("x"))
    args.size = (w, h)
    backends = [b for b in args.backends.split(",") if b]
    if args.torch:
        backends.append(f"torch:{args.torch}")
    OUT.mkdir(parents=True, exist_ok=True)
    grid = grid_preset("default", size=(args.window_size, args.window_size))
    hp = synth_headpath("look-around", args.seconds + 0.5, rate_hz=60.0, seed=0)

    header = (
        "| scene | backend | window median | window p90 | window median, \\|pitch\\| <= 15 | "
        "EPOF vs truth grid (median / p90) | EPOF vs exact viewport (median / p90) | "
        "truth-grid EPOF vs exact (method only) | worst pitch row: median | "
        "median truth (deg/s) | s/frame |"
    )
    rows = [header, "|" + "---|" * 11]
    goal_ratios = {}
    for name, cfg in scenes(args):
        tag = re.sub(r"[^a-z0-9]+", "_", name.lower()).strip("_")
        vid = OUT / f"{tag}_{w}x{h}_{cfg.n_frames}f.mp4"
        if not (vid.exists() and vid.with_name(vid.stem + ".truth.npz").exists()):
            synthesize(cfg, vid)
        tr = load_truth(vid.with_name(vid.stem + ".truth.npz"))
        scene = make_scene(cfg)
        wt = window_truth_dps(scene, grid, tr.time_s, "mono")
        tf = np.arange(cfg.n_frames) / cfg.fps
        exact = viewport_truth_dps(scene, hp, tf, tr.time_s)
        for be in backends:
            out = (
                OUT
                / f"{tag}_{w}x{h}_{args.window_size}_{be.replace(':', '_').replace('/', '_')}.npz"
            )
            fast = be in (backends[0], "sphere")
            n = cfg.n_frames if fast else min(cfg.n_frames, args.slow_frames)
            t0 = time.perf_counter()
            if be == "sphere":  # sphere mode: field on the sphere (DIS), windows derived from it
                from simulator.preprocess import preprocess_sphere

                preprocess_sphere(vid, out, grid=grid, progress=False, end_s=n / cfg.fps)
            else:
                preprocess_video(vid, out, grid=grid, flow=be, progress=False, end_s=n / cfg.fps)
            dt = (time.perf_counter() - t0) / n
            g = load_grid(out)
            est = g.pof_dps[1:].astype(np.float64)
            truth = wt[1:n]
            med, p90 = rel_stats(est, truth)
            eq = np.abs(grid.pitch_deg) <= 15
            med_eq, _ = rel_stats(est[:, eq], truth[:, eq])
            e_est = compute_epof(g, hp).epof_dps[1:]
            # Truth grid: window truth, paper-mode EPOF (drop a sphere grid's field). For the
            # sphere row e_est is its exact EPOF (the field over the actual viewport).
            e_tg = compute_epof(
                replace(g, pof_dps=wt[:n].astype(np.float32), field_dps=None), hp
            ).epof_dps[1:]
            em, ep = rel_stats(e_est, e_tg)
            xm, xp = rel_stats(e_est, exact[1:n])
            mm, _ = rel_stats(e_tg, exact[1:n])
            by_row = [rel_stats(est[:, i], truth[:, i])[0] for i in range(len(grid.pitch_deg))]
            worst = int(np.argmax(by_row))
            rows.append(
                f"| {name} | {be} | {med:.3f} | {p90:.3f} | {med_eq:.3f} | {em:.3f} / {ep:.3f} | "
                f"{xm:.3f} / {xp:.3f} | {mm:.3f} | {grid.pitch_deg[worst]:+.1f}: {by_row[worst]:.3f} | "
                f"{np.median(truth):.1f} | {dt:.2f} |"
            )
            print(rows[-1], flush=True)
            if (
                be == backends[0]
                and "petra" not in name
                and name.split()[0] in ("rotate", "forward")
            ):
                goal_ratios[name] = med / GOAL
    table = "\n".join(rows)
    print()
    print(table)
    cmd = (
        f".venv/bin/python bench/accuracy.py --seconds {args.seconds:g} --size {w}x{h} "
        f"--window-size {args.window_size} --backends {args.backends} --slow-frames {args.slow_frames}"
    )
    print(f"\n{cmd}")
    for k, v in goal_ratios.items():
        print(f"ratio of {backends[0]} median error to the 10% goal, {k}: {v:.3f}")
    if args.doc:
        p = Path(args.doc)
        text = p.read_text()
        block = (
            f"<!-- accuracy:begin (written by bench/accuracy.py) -->\n"
            f"Regenerate: `{cmd} --doc {args.doc}`; clips {w}x{h} mono, "
            f"{args.seconds:g} s at 30 fps, H.264 crf 16 (backends after the first: the first "
            f"{args.slow_frames} frames); grid default (24 x 11 windows of "
            f"{args.window_size}x{args.window_size} px, 107 deg).\n\n{table}\n<!-- accuracy:end -->"
        )
        text = re.sub(
            r"<!-- accuracy:begin.*?<!-- accuracy:end -->", lambda _m: block, text, flags=re.DOTALL
        )
        p.write_text(text)
        print(f"wrote the table into {p}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
