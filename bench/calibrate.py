"""vimsim calibrate on synthetic truth: held-out accuracy, what each feature adds, run time on 100 clips with cached grids, and ego per-axis accuracy.

1. **Held-out figures on synthetic truth.** ``--clips`` rotate clips (256x128, 6 frames at
   30 fps) in ``--groups`` scenes (texture seeds), each camera turning at random rates
   about its three axes (uniform 8..40 deg/s each); rating = |yaw| + 3 |pitch| + 5 |roll|
   plus Gaussian noise (``--noise`` x the ratings' SD). ``vimsim calibrate`` (GroupKFold):
   LCC, SROCC, RMSE with their bootstrap intervals; then the same cross-validation on
   subsets of the features (EPOF mean alone, EPOF + parts, per-axis rates, all): what
   each adds.
2. **Run time on 100 clips with cached grids** (goal <= 30 s): the same kind of clips,
   their grids made once (not timed); then ``python -m simulator calibrate`` as a
   subprocess (start-up included), against the reference measured in the same run:
   the feature extraction alone (load each grid and compute its features, in process).
   Printed as seconds and as the ratio calibrate / features.
3. **Ego per axis**: rotate clips (512x256, 10 frames) about each axis at 5-120 deg/s:
   error of the mean rate in %, the other axes' rates in deg/s; a 2 m/s walk
   (trajectory scene, no rotation): the largest per-frame rotation (translation leak),
   and the same walk turning right at 30 deg/s: yaw error in %.

    .venv/bin/python bench/calibrate.py [--clips 24] [--groups 6] [--noise 0.1]
        [--timing-clips 100] [--skip ego,timing,accuracy] [--ego-flow dis|farneback]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from simulator.discomfort.calibrate import calibrate, grid_for
from simulator.discomfort.features import feature_names, features_from_grid
from simulator.discomfort.fit import cross_validate
from simulator.media.gridfile import load_grid
from simulator.preprocess import preprocess_sphere
from simulator.sphere.windows import grid_preset
from simulator.synth import SynthConfig
from simulator.synth.clip import synthesize

WEIGHTS = np.array([1.0, 3.0, 5.0])  # yaw, pitch, roll
SUBSETS = {
    "EPOF mean alone": ["epof_mean_dps"],
    "EPOF mean + rot/trans parts": ["epof_mean_dps", "epof_rot_mean_dps", "epof_trans_mean_dps"],
    "angular speed alone": ["rotation_mean_dps"],
    "per-axis rates": ["yaw_rate_mean_dps", "pitch_rate_mean_dps", "roll_rate_mean_dps"],
    "all features": None,
}


def rotate_clip(path: Path, rates, *, size=(256, 128), frames=6, seed=0) -> Path:
    """Camera turning at ``rates`` = (yaw, pitch, roll) deg/s (scene axis = the content's)."""
    y, p, r = rates
    axis = np.array([p, -y, r], float)
    cfg = SynthConfig(scene="rotate", seconds=frames / 30, size=size, axis=tuple(axis),
                      omega_dps=float(np.linalg.norm(axis)), seed=seed)  # fmt: skip
    return synthesize(cfg, path)[0]


def rated_set(d: Path, n: int, groups: int, noise: float, seed: int = 0) -> Path:
    rng = np.random.default_rng(seed)
    rates = rng.uniform(8.0, 40.0, (n, 3))
    clean = rates @ WEIGHTS
    ratings = clean + rng.normal(0, noise * clean.std(), n)
    lines = ["video,rating,group"]
    for i in range(n):
        rotate_clip(d / f"c{i:03d}.mp4", rates[i], seed=i % groups)
        lines.append(f"c{i:03d}.mp4,{ratings[i]:.5f},scene{i % groups}")
    (d / "ratings.csv").write_text("\n".join(lines) + "\n")
    return d / "ratings.csv"


def accuracy(args, tmp: Path) -> None:
    d = tmp / "acc"
    d.mkdir()
    csv = rated_set(d, args.clips, args.groups, args.noise)
    res = calibrate(csv, d / "model.json")
    cv = res.model["cross_validation"]
    print(f"\n1. held-out on synthetic truth ({args.clips} clips, {args.groups} scenes, "
          f"noise {args.noise:g} SD; rule |yaw| + 3|pitch| + 5|roll|), {cv['scheme']}:")  # fmt: skip
    for k in ("srocc", "lcc", "rmse"):
        lo, hi = cv[f"{k}_ci"]
        print(f"   {k.upper():6s} {cv[k]:.3f}  95 % CI [{lo:.3f}, {hi:.3f}]")
    w = {f["name"]: f["coef"] / f["scale"] for f in res.model["features"]}
    print("   coef per deg/s: yaw {:.3f}, pitch {:.3f}, roll {:.3f} (rule 1, 3, 5; the "
          "block-max twins share the weight)".format(
              *(w[f"{a}_rate_mean_dps"] + w[f"{a}_rate_block_max_dps"] for a in ("yaw", "pitch", "roll"))))  # fmt: skip
    rows = [ln.split(",") for ln in (d / "model.features.csv").read_text().splitlines()]
    head, rows = rows[0], rows[1:]
    names = feature_names()
    X = np.array([[float(r[head.index(n)]) for n in names] for r in rows])
    y = np.array([float(r[head.index("rating")]) for r in rows])
    g = np.array([r[head.index("group")] for r in rows])
    print("   what each feature set gives (same folds):")
    for label, subset in SUBSETS.items():
        cols = [names.index(n) for n in (subset or names)]
        s = cross_validate(X[:, cols], y, g).summary
        print(f"     {label:30s} SROCC {s['srocc']:.3f} [{s['srocc_ci'][0]:.2f}, "
              f"{s['srocc_ci'][1]:.2f}]  RMSE {s['rmse']:.3g}")  # fmt: skip


def timing(args, tmp: Path) -> None:
    d = tmp / "time"
    d.mkdir()
    t0 = time.perf_counter()
    csv = rated_set(d, args.timing_clips, 10, args.noise, seed=1)
    videos = sorted(d.glob("c*.mp4"))
    for v in videos:  # the cache, made once (not timed)
        grid_for(v, d / "model.grids")
    made = time.perf_counter() - t0
    t0 = time.perf_counter()
    feats = [features_from_grid(load_grid(grid_for(v, d / "model.grids"))) for v in videos]
    t_feat = time.perf_counter() - t0
    assert len(feats) == len(videos)
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "simulator", "calibrate", str(csv), "-o",
                    str(d / "model.json"), "--no-progress"], check=True, cwd=REPO,
                   stdout=subprocess.DEVNULL)  # fmt: skip
    t_cal = time.perf_counter() - t0
    print(f"\n2. calibrate on {len(videos)} clips with cached grids (clips and grids made in "
          f"{made:.1f} s, not timed):")  # fmt: skip
    print(f"   vimsim calibrate (subprocess, start-up included): {t_cal:.2f} s (goal <= 30 s)")
    print(f"   reference, feature extraction alone (in process):  {t_feat:.2f} s")
    print(f"   ratio calibrate / features: {t_cal / t_feat:.2f}")


def ego(tmp: Path, flow: str = "dis") -> None:
    from simulator.synth.camera_path import CameraTrajectory
    from simulator.synth.trajectory import synthesize_trajectory

    print(f"\n3. ego per axis (rotate 512x256, 10 frames, flow {flow}): mean rate error %")
    speeds = (5.0, 10.0, 20.0, 30.0, 60.0, 120.0)
    print("   axis   " + "".join(f"{s:>9g}" for s in speeds) + "   (deg/s)")
    for k, axis in enumerate(("yaw", "pitch", "roll")):
        errs, cross = [], []
        for s in speeds:
            rates = np.zeros(3)
            rates[k] = s
            v = rotate_clip(tmp / f"{axis}.mp4", rates, size=(512, 256), frames=10)
            g = load_grid(
                preprocess_sphere(v, tmp / f"{axis}.npz", grid=grid_preset("default"), flow=flow)
            )
            om = g.extras["ego_omega_dps"][1:].astype(float)
            r = np.column_stack([om[:, 1], -om[:, 0], -om[:, 2]]).mean(axis=0)
            errs.append((r[k] - s) / s * 100)
            cross.append(np.abs(np.delete(r, k)).max())
        print(f"   {axis:6s} " + "".join(f"{e:+9.1f}" for e in errs)
              + f"   other axes <= {max(cross):.2f} deg/s")  # fmt: skip
    t = np.arange(0.0, 12 / 30, 1 / 60)
    pos = np.column_stack([0 * t, 0 * t, 2.0 * t])
    for name, yaw in (("walk 2 m/s", 0.0), ("walk 2 m/s turning 30 deg/s", 30.0)):
        traj = CameraTrajectory.from_poses_deg(t, pos, yaw * t, 0 * t, 0 * t, source=name)
        v = synthesize_trajectory(traj, tmp / "walk.mp4", size=(512, 256))[0]
        g = load_grid(
            preprocess_sphere(v, tmp / "walk.npz", grid=grid_preset("default"), flow=flow)
        )
        om = g.extras["ego_omega_dps"][1:].astype(float)
        if yaw == 0:
            print(f"   {name}: rotation read (translation leak) max {np.linalg.norm(om, axis=1).max():.2f}"
                  f" deg/s, mean {np.linalg.norm(om, axis=1).mean():.2f} deg/s (goal < 1)")  # fmt: skip
        else:
            print(f"   {name}: yaw rate error {(om[:, 1].mean() - yaw) / yaw * 100:+.1f} %, "
                  f"pitch/roll {np.abs(om[:, [0, 2]].mean(axis=0)).max():.2f} deg/s")  # fmt: skip


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--clips", type=int, default=24)
    ap.add_argument("--groups", type=int, default=6)
    ap.add_argument("--noise", type=float, default=0.1)
    ap.add_argument("--timing-clips", type=int, default=100)
    ap.add_argument("--skip", default="", help="comma list of: accuracy, timing, ego")
    ap.add_argument("--ego-flow", default="dis", help="flow of the ego section (default dis)")
    args = ap.parse_args()
    skip = set(filter(None, args.skip.split(",")))
    with tempfile.TemporaryDirectory(prefix="vimsim-bench-calibrate-") as tmp:
        if "accuracy" not in skip:
            accuracy(args, Path(tmp))
        if "timing" not in skip:
            timing(args, Path(tmp))
        if "ego" not in skip:
            ego(Path(tmp), args.ego_flow)
    return 0


if __name__ == "__main__":
    sys.exit(main())
