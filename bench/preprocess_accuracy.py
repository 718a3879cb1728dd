"""Accuracy of ``vimsim preprocess`` against analytic truth.

A real panorama (vrview ``petra.jpg``, 2048x1024) is rotated about a known axis at
omega deg/s and encoded as H.264 (crf 18) at 30 fps. Under that rotation a scene point at
direction ``d`` moves at ``omega |a x d|`` (``a`` the unit axis), so a window's true POF
is the solid-angle-weighted mean of ``omega |a x R_w d_i|`` over its pixel rays ``d_i``
(:func:`simulator.sphere.geometry.perspective_rays`, :func:`simulator.sphere.geometry.head_rotation`).

Prints, per case (axis, omega) and DIS preset, the median and 90th percentile of
``|pof_dps - truth| / truth`` over every (frame, window), the ratio of the median to the
10 % goal, and for a still video the median and maximum ``pof_dps`` (goal < 0.5 deg/s).

    .venv/bin/python bench/preprocess_accuracy.py [--frames 8] [--presets ultrafast,fast]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from PIL import Image
from scipy.spatial.transform import Rotation

from simulator.flow.dis import DISFlow
from simulator.media.gridfile import load_grid
from simulator.media.video import VideoWriter
from simulator.preprocess import preprocess_video
from simulator.sphere import geometry
from simulator.sphere.geometry import head_rotation, perspective_rays
from simulator.sphere.windows import grid_preset

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared"
OUT = REPO / "bench" / "_out"
PANO = SHARED / "data" / "real" / "equirect" / "vrview" / "petra.jpg"
GOAL_REL = 0.10
GOAL_STILL_DPS = 0.5
OBLIQUE = np.array([1.0, 2.0, 0.5]) / np.linalg.norm([1.0, 2.0, 0.5])


def make_rotation_video(path: Path, img: np.ndarray, axis, omega_dps: float, fps: float, n: int):
    """Encode ``n`` frames of ``img`` rotated by ``omega_dps * t`` about unit ``axis``."""
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    H, W = img.shape[:2]
    with VideoWriter(path, fps, (W, H), crf=18) as vw:
        for i in range(n):
            rot = Rotation.from_rotvec(axis * np.radians(omega_dps * i / fps))
            vw.write(geometry.rotate_equirect(img, rot))


def window_truth_dps(grid, axis, omega_dps: float) -> np.ndarray:
    """True POF (deg/s), shape (P, Y): solid-angle mean of ``omega |a x R_w d|``."""
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    dirs, sa = perspective_rays(grid.size, grid.hfov_deg, grid.vfov_deg)
    d = dirs.reshape(-1, 3).astype(np.float64)
    wts = sa.ravel().astype(np.float64)
    pitch, yaw = grid.centres_deg()
    R = head_rotation(yaw.ravel(), pitch.ravel()).as_matrix()
    out = np.empty(len(R))
    for k, Rk in enumerate(R):
        world = d @ Rk.T
        out[k] = omega_dps * np.sum(np.linalg.norm(np.cross(axis, world), axis=1) * wts) / wts.sum()
    return out.reshape(grid.shape)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=8)
    ap.add_argument("--fps", type=float, default=30.0)
    ap.add_argument("--presets", default="ultrafast,fast,medium")
    ap.add_argument("--window-size", type=int, default=256)
    args = ap.parse_args(argv)
    if not PANO.is_file():
        print(f"skip: {PANO} not found", file=sys.stderr)
        return 0
    OUT.mkdir(parents=True, exist_ok=True)
    img = np.asarray(Image.open(PANO).convert("RGB").resize((2048, 1024), Image.LANCZOS))
    grid = grid_preset("default", size=(args.window_size, args.window_size))
    cases = [
        ("yaw", (0.0, 1.0, 0.0), 15.0),
        ("yaw", (0.0, 1.0, 0.0), 60.0),
        ("oblique", OBLIQUE, 15.0),
        ("oblique", OBLIQUE, 60.0),
        ("still", (0.0, 1.0, 0.0), 0.0),
    ]
    print(
        f"panorama {PANO.name} 2048x1024, {args.frames} frames at {args.fps:g} fps, H.264 crf 18; "
        f"grid default {grid.shape[0]}x{grid.shape[1]} windows of {grid.size[0]}x{grid.size[1]} px, 107 deg"
    )
    print(
        f"{'case':<18}{'preset':<11}{'median rel':>11}{'p90 rel':>9}{'ratio to 10%':>14}"
        f"{'median dps':>12}{'s/frame':>9}"
    )
    for name, axis, omega in cases:
        vid = OUT / f"rot_{name}_{omega:g}_{args.frames}f.mp4"
        if not vid.exists():
            make_rotation_video(vid, img, axis, omega, args.fps, args.frames)
        for preset in args.presets.split(","):
            out = OUT / f"rot_{name}_{omega:g}_{preset}.npz"
            t0 = time.perf_counter()
            preprocess_video(vid, out, grid=grid, flow=DISFlow(preset), progress=False)
            dt = (time.perf_counter() - t0) / args.frames
            g = load_grid(out)
            est = g.pof_dps[1:].astype(np.float64)  # row 0 repeats row 1
            label = f"{name} {omega:g} deg/s"
            if omega == 0:
                print(
                    f"{label:<18}{preset:<11}{'':>11}{'':>9}{np.max(est) / GOAL_STILL_DPS:>14.3f}"
                    f"{np.median(est):>12.4f}{dt:>9.2f}   (max {np.max(est):.4f} deg/s; goal < 0.5)"
                )
                continue
            truth = window_truth_dps(grid, axis, omega)[None]
            rel = np.abs(est - truth) / truth
            med, p90 = np.median(rel), np.percentile(rel, 90)
            print(
                f"{label:<18}{preset:<11}{med:>11.4f}{p90:>9.4f}{med / GOAL_REL:>14.3f}"
                f"{np.median(est):>12.3f}{dt:>9.2f}   (median truth {np.median(truth):.3f})"
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
