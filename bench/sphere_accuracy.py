"""Accuracy of sphere mode (issue 7): against analytic truth, against paper mode, and
across FOVs (a field made once, windows/EPOF asked for at another FOV).

Same run, same clips, same head path:

1. Synthetic scenes with analytic truth (``simulator.synth``: rotate about yaw and an
   oblique axis at two speeds, forward, coaster; 1024x512 H.264): per-window relative
   error of ``pof_dps`` against the truth (solid-angle mean of the analytic speed over
   each window's rays) for paper mode (264 windows of 256^2 px, DIS) and for sphere mode
   (window matrix derived from the field); the paper-vs-sphere window difference; the
   sphere-mode exact EPOF along a look-around head path against the exact viewport truth.
   Goal: sphere window POF within 5% median of truth.
2. Real video (``../shared/data/real/equirect/threejs/pano.mp4``): sphere vs paper window
   POF, per (frame, window) and for the whole-clip window means. Goal: within 5%.
3. FOV transfer: a sphere grid made at 107 deg gives windows (and paper-style EPOF) at
   80 deg and at the Quest 2 per-eye FOV; compared with a paper-mode grid made directly
   at that FOV (like with like: window means vs window means). Goal: within 5%.

    .venv/bin/python bench/sphere_accuracy.py [--seconds 1.0] [--pano-seconds 2.0]
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from simulator import sphere as S
from simulator.epof import compute_epof
from simulator.geometry import grid_preset, head_rotation, perspective_rays
from simulator.gridfile import load_grid
from simulator.headpath import synth as synth_headpath
from simulator.headsets import get_headset
from simulator.preprocess import preprocess_video
from simulator.synth import SynthConfig, load_truth, make_scene, synthesize, window_truth_dps

REPO = Path(__file__).resolve().parents[1]
PANO = REPO.parent / "shared" / "data" / "real" / "equirect" / "threejs" / "pano.mp4"
OUT = REPO / "bench" / "_out" / "sphere"
GOAL = 0.05
OBLIQUE = (1.0, 2.0, 0.5)


def rel(est, ref):
    r = np.abs(np.asarray(est, float) - ref) / np.maximum(np.abs(ref), 1e-9)
    return float(np.median(r)), float(np.percentile(r, 90))


def viewport_truth(scene, yaw, pitch, roll, times, fov=107.0, rays=32):
    dirs, sa = perspective_rays((rays, rays), fov, fov)
    d = dirs.reshape(-1, 3).astype(float)
    w = sa.ravel().astype(float)
    out = np.empty(len(times))
    for k, t in enumerate(times):
        world = head_rotation(yaw[k], pitch[k], roll[k]).apply(d)
        out[k] = float(scene.speed_dps(float(t), world) @ w / w.sum())
    return out


def grids_for(vid: Path, tag: str, grid, *, end_s=None):
    """(paper GridFile, sphere GridFile, s/frame paper, s/frame sphere) for one clip."""
    pg, sg = OUT / f"{tag}_paper_{grid.hfov_deg:g}.npz", OUT / f"{tag}_sphere.npz"
    t = time.perf_counter()
    preprocess_video(vid, pg, grid=grid, end_s=end_s, progress=False)
    tp = time.perf_counter() - t
    t = time.perf_counter()
    S.preprocess_sphere(vid, sg, grid=grid_preset("default"), end_s=end_s, progress=False)
    ts = time.perf_counter() - t
    p, s = load_grid(pg), load_grid(sg)
    return p, s, tp / p.n_frames, ts / s.n_frames


def transfer_rows(name, vid, tag, sphere_grid, hp, fovs, *, end_s=None):
    """Rows comparing windows/EPOF derived from the 107-deg field with paper grids made at
    each FOV directly."""
    rows = []
    field, cells = S.require_field(sphere_grid)
    for label, (h, v) in fovs:
        g = grid_preset("default", hfov_deg=h, vfov_deg=v)
        pg = OUT / f"{tag}_paper_{h:g}x{v:g}.npz"
        preprocess_video(vid, pg, grid=g, end_s=end_s, progress=False)
        paper = load_grid(pg)
        dps, px = S.window_pof(field, cells.cell_deg, g, sphere_grid.fps)
        w_med, w_p90 = rel(dps[1:], paper.pof_dps[1:])
        m_med, _ = rel(dps[1:].mean(0), paper.pof_dps[1:].mean(0))
        px_med, _ = rel(px[1:], paper.pof_px[1:])
        derived = replace(paper, pof_dps=dps, pof_px=px)
        e_p = compute_epof(paper, hp, hold=True).epof_dps[1:]
        e_s = compute_epof(derived, hp, hold=True).epof_dps[1:]
        e_med, e_p90 = rel(e_s, e_p)
        rows.append(
            f"| {name} | {label} | {w_med:.3f} / {w_p90:.3f} | {m_med:.3f} | {e_med:.3f} / {e_p90:.3f} | {px_med:.3f} |"
        )
        print(rows[-1], flush=True)
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=1.0)
    ap.add_argument("--pano-seconds", type=float, default=2.0)
    ap.add_argument("--size", default="1024x512")
    args = ap.parse_args(argv)
    w, h = (int(x) for x in args.size.lower().split("x"))
    OUT.mkdir(parents=True, exist_ok=True)
    grid = grid_preset("default")
    hp = synth_headpath(
        "look-around", max(args.seconds, args.pano_seconds) + 1.0, rate_hz=60.0, seed=0
    )
    q2 = get_headset("quest-2")
    fovs = [
        ("80 x 80", (80.0, 80.0)),
        (f"quest-2 {q2.hfov_deg:g} x {q2.vfov_deg:g}", (q2.hfov_deg, q2.vfov_deg)),
    ]
    print(f"load average {os.getloadavg()[0]:.1f}; sphere config {S.SphereConfig()}")

    base = {"seconds": args.seconds, "fps": 30.0, "size": (w, h)}
    scenes = [
        ("rotate yaw 15 deg/s", SynthConfig("rotate", omega_dps=15.0, **base)),
        ("rotate yaw 60 deg/s", SynthConfig("rotate", omega_dps=60.0, **base)),
        ("rotate oblique 15 deg/s", SynthConfig("rotate", axis=OBLIQUE, omega_dps=15.0, **base)),
        ("rotate oblique 60 deg/s", SynthConfig("rotate", axis=OBLIQUE, omega_dps=60.0, **base)),
        ("forward 2 m/s", SynthConfig("forward", speed_mps=2.0, **base)),
        ("coaster 6 m/s", SynthConfig("coaster", **base)),
    ]
    print(
        "\n1. Synthetic scenes vs analytic truth (per window and frame: median / p90 relative error)"
    )
    head = (
        "| scene | paper vs truth | sphere vs truth | sphere vs paper | sphere exact EPOF vs viewport truth | "
        "median truth (deg/s) | s/frame paper / sphere |"
    )
    rows1 = [head, "|" + "---|" * 7]
    print(rows1[0])
    ratios = []
    transfer_src = []
    for name, cfg in scenes:
        tag = name.replace(" ", "_").replace("/", "")
        vid = OUT / f"{tag}_{w}x{h}_{cfg.n_frames}f.mp4"
        if not (vid.exists() and vid.with_name(vid.stem + ".truth.npz").exists()):
            synthesize(cfg, vid)
        tr = load_truth(vid.with_name(vid.stem + ".truth.npz"))
        scene = make_scene(cfg)
        wt = window_truth_dps(scene, grid, tr.time_s, "mono")[1:]
        p, s, tp, ts = grids_for(vid, tag, grid)
        pm, pp = rel(p.pof_dps[1:], wt)
        sm, sp = rel(s.pof_dps[1:], wt)
        dm, dp = rel(s.pof_dps[1:], p.pof_dps[1:])
        tf = np.arange(p.n_frames) / cfg.fps
        yaw, pitch, roll = hp.sample_angles_deg(tf, hold=True)
        field, cells = S.require_field(s)
        ex = S.viewport_epof(field, cells.cell_deg, yaw, pitch, roll, hfov_deg=107.0)[1:]
        vt = viewport_truth(scene, yaw, pitch, roll, tr.time_s)[1:]
        em, ep = rel(ex, vt)
        rows1.append(
            f"| {name} | {pm:.3f} / {pp:.3f} | {sm:.3f} / {sp:.3f} | {dm:.3f} / {dp:.3f} | "
            f"{em:.3f} / {ep:.3f} | {np.median(wt):.1f} | {tp:.2f} / {ts:.3f} |"
        )
        print(rows1[-1], flush=True)
        ratios.append(sm / GOAL)
        if cfg.scene in ("forward", "coaster"):
            transfer_src.append((name, vid, tag, s))

    print("\n2. Real video: sphere vs paper window POF")
    rows2 = []
    pano = None
    if PANO.is_file():
        p, s, tp, ts = grids_for(PANO, "pano", grid, end_s=args.pano_seconds)
        dm, dp = rel(s.pof_dps[1:], p.pof_dps[1:])
        mm, mp = rel(s.pof_dps[1:].mean(0), p.pof_dps[1:].mean(0))
        ratio = float(s.pof_dps[1:].mean() / p.pof_dps[1:].mean())
        rows2.append(
            f"pano.mp4 ({p.n_frames} frames, {PANO.stat().st_size // 1024} KB, 1920x1080 SAR 9:8): "
            f"per (frame, window) median {dm:.3f} / p90 {dp:.3f}; whole-clip window means median "
            f"{mm:.3f} / p90 {mp:.3f}; mean sphere/paper {ratio:.3f}; median paper POF "
            f"{np.median(p.pof_dps[1:]):.2f} deg/s; s/frame paper {tp:.2f}, sphere {ts:.3f}"
        )
        print(rows2[-1], flush=True)
        pano = ("pano.mp4", PANO, "pano", s)
    else:
        print(f"skip: {PANO} not found")

    print(
        "\n3. FOV transfer: field made at 107 deg, windows/EPOF derived at another FOV vs a paper grid made at that FOV"
    )
    head3 = "| clip | FOV | windows: median / p90 | window clip means: median | paper-style EPOF (look-around): median / p90 | pof_px (approx.): median |"
    rows3 = [head3, "|" + "---|" * 6]
    print(head3)
    for name, vid, tag, s in [*transfer_src, *([pano] if pano else [])]:
        end_s = args.pano_seconds if tag == "pano" else None
        rows3 += transfer_rows(name, vid, tag, s, hp, fovs, end_s=end_s)

    print("\n" + "\n".join(rows1) + "\n\n" + "\n".join(rows2) + "\n\n" + "\n".join(rows3))
    print(
        f"\nratio of sphere median window error to the {GOAL:.0%} goal, per scene: "
        + ", ".join(f"{r:.2f}" for r in ratios)
    )
    print(
        f".venv/bin/python bench/sphere_accuracy.py --seconds {args.seconds:g} --pano-seconds {args.pano_seconds:g} --size {w}x{h}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
