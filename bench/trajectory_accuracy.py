"""Trajectory scene: truth vs estimate, equality with the rotate scene, and
render speed against the coaster scene, all in one run.

1. Truth vs estimate: camera CSVs for a walk (1.4 m/s with head bob and sway, sampled
   at 10 Hz), a turn while walking (1.2 m/s on a 30 deg/s arc, looking along the path,
   irregular sampling around 15 Hz) and two pure rotations (the rotate scene's yaw pan
   and an oblique axis, 30 deg/s, sampled at 5 Hz) are rendered with ``vimsim synth
   --scene trajectory`` (1024x512 mono H.264, 30 fps); sphere mode (DIS) gives each
   clip's window POF (default grid, 24 x 11 windows, 107 deg); truth = the
   solid-angle mean of the analytic speed over each window's rays
   (:func:`simulator.synth.window_truth_dps`). Goal: median relative error <= 5 %.
2. Pure rotation = rotate scene: the same rotation rendered by the ``rotate`` scene;
   the two truth files (every cell, every frame) and the two window truths are
   compared (goal: within 0.1 %), and, for information, the two clips' estimates.
3. Speed: the coaster's own ride written as a 60 Hz camera CSV and replayed by the
   trajectory scene in the coaster's room (same pictures: the comparison is of the scene
   code, not of content); seconds per frame of the whole call a user makes
   (``synthesize_trajectory`` from the CSV, ``synthesize`` for the coaster scene, same
   size and frame count: set-up, rendering on worker threads, H.264 encoding, truth file) and of
   ``scene.render`` alone (one thread); interleaved rounds, median of the per-round
   ratios coaster / trajectory, in CPU time of the process (all threads) and wall time.
   Goal >= 1 for the whole call in CPU time (the trajectory scene at least as fast as
   the coaster per frame; wall time on this shared machine swings with other users).

    .venv/bin/python bench/trajectory_accuracy.py [--seconds 1] [--size 1024x512] [--rounds 6] [--speed-frames 12]
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from simulator.media.gridfile import load_grid
from simulator.preprocess import preprocess_sphere
from simulator.sphere.geometry import head_angles_deg
from simulator.sphere.windows import grid_preset
from simulator.synth import SynthConfig, load_truth, make_scene, synthesize, window_truth_dps
from simulator.synth.camera_path import CameraTrajectory, save_camera_csv
from simulator.synth.trajectory import (
    make_trajectory_scene,
    synthesize_trajectory,
    trajectory_config,
)

REPO = Path(__file__).resolve().parents[1]
OUT = REPO / "bench" / "_out" / "trajectory"
GOAL_EST = 0.05
GOAL_EQUAL = 0.001
OMEGA = 30.0
OBLIQUE = (1.0, 2.0, 0.5)


def _times(seconds: float, step: float) -> np.ndarray:
    """0, step, 2 step, ... and ``seconds`` itself (the clip covers the whole span)."""
    t = np.arange(0.0, seconds - 1e-6, step)
    return np.append(t, seconds)


def walk(seconds: float) -> CameraTrajectory:
    """1.4 m/s along +z; head bob 3 cm at 2 Hz (steps), sway 2 cm at 1 Hz, gaze wobble."""
    t = _times(seconds, 0.1)
    pos = np.column_stack(
        [
            0.02 * np.sin(2 * np.pi * 1.0 * t),
            0.03 * np.sin(2 * np.pi * 2.0 * t),
            1.4 * t,
        ]
    )
    yaw = 2.0 * np.sin(2 * np.pi * 0.5 * t)
    pitch = 1.0 * np.sin(2 * np.pi * 2.0 * t + 0.5)
    roll = 1.0 * np.sin(2 * np.pi * 1.0 * t)
    return CameraTrajectory.from_poses_deg(t, pos, yaw, pitch, roll, source="walk")


def turn_walk(seconds: float) -> CameraTrajectory:
    """1.2 m/s on an arc turning right at 30 deg/s, looking along the path; poses at
    irregular times (~15 Hz, seeded jitter)."""
    rng = np.random.default_rng(3)
    t = _times(seconds, 1 / 15)
    t[1:-1] += rng.uniform(-0.02, 0.02, t.size - 2)
    w = np.radians(30.0)
    rad = 1.2 / w  # m
    yaw = np.degrees(w * t)  # + turns right: heading (sin yaw, 0, cos yaw)
    pos = np.column_stack(
        [rad * (1 - np.cos(w * t)), 0.02 * np.sin(4 * np.pi * t), rad * np.sin(w * t)]
    )
    return CameraTrajectory.from_poses_deg(t, pos, yaw, 0 * t, 0 * t, source="turn-walk")


def pure_rotation(seconds: float, axis) -> CameraTrajectory:
    """The rotate scene's motion: camera R(t) = rotvec(-a omega t), poses every 0.2 s."""
    t = _times(seconds, 0.2)
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    rot = Rotation.from_rotvec(-a[None] * np.radians(OMEGA) * t[:, None])
    y, p, r = head_angles_deg(rot)
    return CameraTrajectory.from_poses_deg(t, np.zeros((t.size, 3)), y, p, r, source="rotation")


def coaster_replica(cscene, seconds: float) -> CameraTrajectory:
    """The coaster scene's camera path sampled at 60 Hz as a camera trajectory."""
    t = _times(seconds, 1 / 60)
    rot = Rotation.concatenate([cscene.rotation(float(x)) for x in t])
    pos = np.stack([cscene.position(float(x)) for x in t])
    return CameraTrajectory(t, pos, rot, source="coaster ride")


def rel(est, ref):
    r = np.abs(np.asarray(est, float) - ref) / np.maximum(np.abs(ref), 1e-9)
    return float(np.median(r)), float(np.percentile(r, 90))


def estimate(vid: Path, grid) -> np.ndarray:
    g = OUT / (vid.stem + "_sphere.npz")
    preprocess_sphere(vid, g, grid=grid, progress=False)
    return load_grid(g).pof_dps.astype(np.float64)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=1.0)
    ap.add_argument("--size", default="1024x512")
    ap.add_argument("--rounds", type=int, default=6, help="speed: interleaved rounds")
    ap.add_argument("--speed-frames", type=int, default=12, help="speed: frames per run")
    ap.add_argument("--speed-only", action="store_true", help="only section 3")
    args = ap.parse_args(argv)
    size = tuple(int(x) for x in args.size.lower().split("x"))
    OUT.mkdir(parents=True, exist_ok=True)
    grid = grid_preset("default")
    w, h = size
    print(f"clips {w}x{h} mono, {args.seconds:g} s at 30 fps, H.264 crf 16; sphere mode, DIS")
    print(f"load average {os.getloadavg()[0]:.1f} (shared machine)\n")

    ok = True
    if not args.speed_only:
        ok = accuracy(args, size, grid)
    ok &= speed(args, size)
    print("\nall goals met" if ok else "\nSOME GOALS NOT MET")
    return 0


def accuracy(args, size, grid) -> bool:
    """Sections 1 and 2; True if their goals are met."""
    w, h = size
    # 1. truth vs estimate --------------------------------------------------------------
    trajs = {
        "walk (1.4 m/s, bob, 10 Hz poses)": walk(args.seconds),
        "turn while walking (30 deg/s arc, irregular poses)": turn_walk(args.seconds),
        "pure rotation, yaw 30 deg/s (5 Hz poses)": pure_rotation(args.seconds, (0.0, 1.0, 0.0)),
        "pure rotation, oblique 30 deg/s (5 Hz poses)": pure_rotation(args.seconds, OBLIQUE),
    }
    print(
        "| trajectory | window median rel. error | p90 | median truth (deg/s) | goal <= 5 % |\n"
        "|---|---|---|---|---|"
    )
    ok = True
    results = {}
    for k, (name, tr) in enumerate(trajs.items()):
        csv = save_camera_csv(OUT / f"traj{k}.csv", tr)
        vid = OUT / f"traj{k}_{w}x{h}.mp4"
        vid, tpath, cfg = synthesize_trajectory(csv, vid, fps=30.0, size=size)
        scene = make_trajectory_scene(cfg, tr)
        times = load_truth(tpath).time_s
        wt = window_truth_dps(scene, grid, times)
        est = estimate(vid, grid)
        med, p90 = rel(est[1:], wt[1:])
        results[name] = (cfg, scene, tpath, wt, est)
        ok &= med <= GOAL_EST
        print(
            f"| {name} | {med:.4f} | {p90:.4f} | {np.median(wt[1:]):.1f} | "
            f"{'met' if med <= GOAL_EST else 'NOT met'} (ratio {med / GOAL_EST:.3f}) |",
            flush=True,
        )

    # 2. pure rotation vs the rotate scene ------------------------------------------------
    print(
        "\n| pure rotation | truth cells: max rel. diff | window truth: max rel. diff | "
        "estimates: median rel. diff | rotate scene's own median error | goal <= 0.1 % |\n"
        "|---|---|---|---|---|---|"
    )
    for name, axis in (
        ("pure rotation, yaw 30 deg/s (5 Hz poses)", (0.0, 1.0, 0.0)),
        ("pure rotation, oblique 30 deg/s (5 Hz poses)", OBLIQUE),
    ):
        cfg_t, _, tpath_t, wt_t, est_t = results[name]
        rcfg = SynthConfig(
            "rotate", seconds=cfg_t.seconds, fps=30.0, size=size, axis=axis, omega_dps=OMEGA
        )
        rvid = OUT / f"rotate_{'yaw' if axis[0] == 0 else 'oblique'}_{w}x{h}.mp4"
        rvid, rtpath = synthesize(rcfg, rvid)
        a, b = load_truth(tpath_t).speed_dps[1:], load_truth(rtpath).speed_dps[1:]
        m = b > 0.01 * b.max()  # cells on the axis move at ~0: relative diff is noise there
        cell = float(np.max(np.abs(a[m] - b[m]) / b[m]))
        rwt = window_truth_dps(make_scene(rcfg), grid, load_truth(rtpath).time_s)
        win = float(np.max(np.abs(wt_t[1:] - rwt[1:]) / rwt[1:]))
        rest = estimate(rvid, grid)
        emed, _ = rel(est_t[1:], rest[1:])
        rmed, _ = rel(rest[1:], rwt[1:])
        good = max(cell, win) <= GOAL_EQUAL
        ok &= good
        print(
            f"| {name.split(',')[1].strip()} | {cell:.2e} | {win:.2e} | {emed:.4f} | {rmed:.4f} | "
            f"{'met' if good else 'NOT met'} |",
            flush=True,
        )

    return ok


def speed(args, size) -> bool:
    """Section 3; True if its goal is met."""
    w, h = size
    ok = True
    # 3. speed vs coaster -----------------------------------------------------------------
    # (a) scene.render alone, one thread; (b) the whole call a user makes (CSV/scene set-up,
    # render on worker threads, H.264 encode, truth file). Rounds interleaved, the order
    # alternating (ABBA), so that load from other users hits both alike.
    nf = args.speed_frames
    ccfg = SynthConfig("coaster", seconds=nf / 30.0, fps=30.0, size=size)
    cscene = make_scene(ccfg)
    # The coaster's own ride as a camera CSV (poses at 60 Hz, the coaster's room): same
    # pictures, so the ratio measures the scene code, not the content (near walls cost
    # more to encode than far ones).
    tr = coaster_replica(cscene, (nf - 1) / 30.0)
    room = (*cscene.box.lo, *cscene.box.hi)
    wcfg = trajectory_config(tr, fps=30.0, size=size)
    wscene = make_trajectory_scene(wcfg, tr, room)
    assert wcfg.n_frames == ccfg.n_frames == nf
    times = np.arange(nf) / 30.0
    for sc in (wscene, cscene):  # warm caches (ray directions)
        sc.render(0.0)
    tm = (nf - 1) / 60.0 + 1 / 240  # mid-clip, between two poses
    same = np.abs(wscene.render(tm).astype(float) - cscene.render(tm)).mean()
    d = np.random.default_rng(0).normal(size=(4000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    tt = (np.arange(1, nf) - 0.5) / 30.0
    dev = [rel(wscene.speed_dps(t, d), cscene.speed_dps(t, d))[0] for t in tt]
    print(
        f"\ncoaster ride replayed from a 60 Hz camera CSV: mean |frame difference| "
        f"{same:.2f} grey levels; truth (median rel. diff, random rays) {np.median(dev):.2e}"
    )
    wcsv = save_camera_csv(OUT / "speed_coaster_ride.csv", tr)

    def render_all(sc):
        for x in times:
            sc.render(float(x))

    jobs = {
        "render": (lambda: render_all(wscene), lambda: render_all(cscene)),
        "synthesize": (
            lambda: synthesize_trajectory(
                wcsv, OUT / "speed_ride.mp4", fps=30.0, size=size, room_m=room
            ),
            lambda: synthesize(ccfg, OUT / "speed_coaster.mp4"),
        ),
    }
    print(
        f"\nspeed, {w}x{h} mono, {nf} frames per run, {args.rounds} interleaved rounds (ABBA), "
        "s/frame median (CPU = all threads of this process: insensitive to other users' load; "
        "wall = elapsed); ratio = coaster / trajectory per round"
    )
    end_to_end = {}
    for label, (fw, fc) in jobs.items():
        wall = {"w": [], "c": []}
        cpu = {"w": [], "c": []}
        for r in range(args.rounds):
            for key in ("w", "c") if r % 2 == 0 else ("c", "w"):
                fn = fw if key == "w" else fc
                t, c = time.perf_counter(), time.process_time()
                fn()
                cpu[key].append((time.process_time() - c) / nf)
                wall[key].append((time.perf_counter() - t) / nf)
        for what, d in (("CPU", cpu), ("wall", wall)):
            ratios = np.array(d["c"]) / np.array(d["w"])
            med = float(np.median(ratios))
            end_to_end[(label, what)] = med
            print(
                f"  {label:10s} {what:4s}: trajectory {np.median(d['w']):.4f}, coaster "
                f"{np.median(d['c']):.4f}; ratio {med:.3f} "
                f"(rounds {', '.join(f'{x:.3f}' for x in ratios)})",
                flush=True,
            )
    # The only per-frame work that differs between the two scenes: the poses the renderer
    # asks for and the truth row (45 x 90 cells; the trajectory adds its rotation and
    # translation parts). The rest (ray cast, texture lookups, encoding) is the same code.
    from simulator.sphere.geometry import lonlat_to_dir

    c = ccfg.truth_cell_deg
    lo_, la_ = np.meshgrid(
        np.radians(-180 + c * (np.arange(round(360 / c)) + 0.5)),
        np.radians(90 - c * (np.arange(round(180 / c)) + 0.5)),
    )
    cells = lonlat_to_dir(lo_, la_)
    rows = np.maximum((np.arange(nf) - 0.5) / 30.0, 0.5 / 30.0)

    def scene_work(sc):
        for t in rows:
            t = float(t)
            sc.rotation(t), sc.eye_origin(t, "mono")  # render_eye's poses
            sc.speed_dps(t, cells), sc.position(t), sc.rotation(t).as_quat()
            sc.omega_cam_dps(t), sc.eye_velocity_cam(t, "mono")
        sc.truth_extras(cells, rows)

    own = {"w": [], "c": []}
    for r in range(5 * args.rounds):
        for key in ("w", "c") if r % 2 == 0 else ("c", "w"):
            t = time.perf_counter()
            scene_work(wscene if key == "w" else cscene)
            own[key].append((time.perf_counter() - t) / nf)
    sw, sc_ = float(np.median(own["w"])), float(np.median(own["c"]))
    ok &= sc_ / sw >= 1.0
    print(
        f"  scene-specific work per frame (poses + truth row): trajectory {sw * 1e3:.2f} ms, "
        f"coaster {sc_ * 1e3:.2f} ms; ratio {sc_ / sw:.2f} (goal >= 1: "
        f"{'met' if sc_ / sw >= 1 else 'NOT met'})\n"
        f"  end to end (synthesize, CPU) ratio {end_to_end[('synthesize', 'CPU')]:.3f}: "
        "the same renderer and encoder, parity up to round-to-round noise"
    )
    return ok


if __name__ == "__main__":
    sys.exit(main())
