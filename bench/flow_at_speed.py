"""Flow at speed and at any depth, split into rotation and translation, today against after, in one run.

Clips: ``vimsim synth --scene trajectory`` renders (textured room, analytic truth) at 30 fps
of camera paths sampled at 60 Hz (two poses per frame interval: the truth row, taken at
the interval's middle, is the motion of the whole interval):

- rotations: yaw ramp 0 -> 300 deg/s, oblique axis (1, 2, 0.5) ramp 0 -> 300 deg/s;
- translation-heavy: a 5 m/s run down a 3 m wide corridor, a 4 m/s strafe 1.5 m from a
  wall (looking at it), a 3 m/s vertical climb 1 m from a wall, a 2 m/s walk 1 m from
  both walls with +-30 deg yaw turns at 1 Hz (188 deg/s peak);
- rooms of 3, 20, 60 and 100 m mean depth (cubes around the camera), same motion
  (1.4 m/s walk + 30 deg/s yaw);
- a still camera.

Measured, each against the analytic truth (same cell grid, same viewport integral
:func:`simulator.epof.exact.viewport_epof`):

1. forward-viewport (107 deg, yaw = pitch = 0) mean of the sphere field / truth's, per
   frame: median and p10 per clip, and over the frames whose truth is > 60 deg/s;
2. estimated camera angular velocity (grid ``ego_omega_dps``) vs the truth's
   ``omega_cam_dps``: median error / |omega|; deg/s when still;
3. translational EPOF part (``epof_trans_dps``, forward viewport) vs the truth's
   (viewport mean of ``speed_trans_dps``): median ratio; its share of the EPOF (median
   over frames: on a pure rotation, the split's leak);
4. the real hand-held clip (shared data, threejs/pano.mp4): rotation estimate vs an
   independent one (Shi-Tomasi + Lucas-Kanade tracks on 6 cube faces, OpenCV's essential
   matrix and recoverPose per face, ``bench/_ego_reference.py``): median difference,
   deg/s, frame by frame and on 5-frame means;
5. cost: sphere-mode preprocess seconds, after / today, same clips, same run.

"today" = the code before this change (``--today DIR``, a checkout of it; by default commit
``TODAY_COMMIT`` unpacked with ``git archive`` into a temporary folder: run through its CLI with
``PYTHONPATH``); "after" = this worktree. Both run as subprocesses
(``python -m simulator preprocess --method sphere``), timed the same way.

    .venv/bin/python bench/flow_at_speed.py [--seconds 2] [--size 512x256] [--today DIR]
        [--only NAME,...] [--no-real] [--after-flow dis:ultrafast+refine5]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from simulator.epof.exact import viewport_epof
from simulator.media.gridfile import load_grid
from simulator.synth.camera_path import CameraTrajectory
from simulator.synth.trajectory import synthesize_trajectory

OUT = REPO / "bench" / "_out" / "flow_at_speed"
REAL = REPO.parent / "shared" / "data" / "real" / "equirect" / "threejs" / "pano.mp4"
HZ = 30.0  # pose sampling: at frame times (each frame interval one constant motion)
TEXTURE_M: dict[str, float] = {}  # metres per texture width, where not the default 3


def _t(seconds: float) -> np.ndarray:
    return np.arange(0.0, seconds + 1e-9, 1.0 / HZ)


def _spin(t, axis, peak_dps, seconds):
    """Camera rotations about a fixed axis, rate ramping linearly 0 -> peak."""
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    ang = np.radians(peak_dps) * t * t / (2.0 * seconds)
    return Rotation.from_rotvec(a[None] * ang[:, None])


def _traj(t, pos, rot, name) -> CameraTrajectory:
    return CameraTrajectory(t, np.asarray(pos, float), rot, source=name)


def clips(seconds: float) -> dict:
    """name -> (trajectory, room corners or None, kind)."""
    t = _t(seconds)
    z0 = np.zeros((t.size, 3))
    ident = Rotation.identity(t.size)
    out = {}
    out["yaw-300"] = (_traj(t, z0, _spin(t, (0, 1, 0), 300, seconds), "yaw"), None, "rotation")
    out["oblique-300"] = (
        _traj(t, z0, _spin(t, (1, 2, 0.5), 300, seconds), "oblique"),
        None,
        "rotation",
    )
    L = 5.0 * seconds
    run = np.column_stack([0 * t, 0 * t, 5.0 * t])
    out["run-corridor"] = (_traj(t, run, ident, "run"), (-1.5, -1.5, -3, 1.5, 1.5, L + 4), "trans")
    S = 4.0 * seconds
    strafe = np.column_stack([4.0 * t, 0 * t, 0 * t])
    out["strafe-wall"] = (
        _traj(t, strafe, ident, "strafe"),
        (-4, -1.6, -4, S + 4, 2.4, 1.5),
        "trans",
    )
    C = 3.0 * seconds
    climb = np.column_stack([0 * t, 3.0 * t, 0 * t])
    out["climb-wall"] = (_traj(t, climb, ident, "climb"), (-4, -2, -4, 4, C + 2, 1.0), "trans")
    W = 2.0 * seconds
    walk = np.column_stack([0 * t, 0.03 * np.sin(4 * np.pi * t), 2.0 * t])
    yaw = 30.0 * np.sin(2 * np.pi * 1.0 * t)
    rot = Rotation.from_euler("y", yaw[:, None], degrees=True)
    out["walk-turns"] = (_traj(t, walk, rot, "walk-turns"), (-1, -1.6, -3, 1, 2.4, W + 4), "trans")
    for d in (3, 20, 60, 100):
        s = d / 0.6 / 2.0  # a cube of side S has a mean depth ~0.6 S from its centre
        p = np.column_stack([0 * t, 0 * t, 1.4 * t - 0.7 * seconds])
        r = Rotation.from_euler("y", 30.0 * t[:, None], degrees=True)
        out[f"room-{d}m"] = (_traj(t, p, r, f"room {d} m"), (-s, -s, -s, s, s, s), "room")
        TEXTURE_M[f"room-{d}m"] = 3.0 * max(1.0, d / 20.0)  # texture seen at one angular scale
    out["still"] = (_traj(t, z0, ident, "still"), None, "still")
    return out


def render(name, traj, room, size) -> Path:
    vid = OUT / f"{name}.mp4"
    if not vid.exists():
        tex = TEXTURE_M.get(name, 3.0)
        synthesize_trajectory(
            traj, vid, room_m=room, size=size, fps=30.0, interp="linear", texture_m=tex
        )
    return vid


AFTER_FLOW: list[str] = []  # extra preprocess options of "after" (--after-flow)


def preprocess(vid: Path, tag: str, pythonpath: str, method: str = "sphere") -> tuple[Path, float]:
    """Run ``python -m simulator preprocess`` of the tree ``pythonpath``; returns the grid
    and the child's CPU seconds (user + system: wall time on a shared machine swings)."""
    g = (OUT / f"{vid.stem}.{tag}.{method}.npz").resolve()
    vid = Path(vid).resolve()
    env = dict(os.environ, PYTHONPATH=pythonpath)
    cmd = [sys.executable, "-m", "simulator", "preprocess", str(vid), "-o", str(g)]
    cmd += ["--method", method, "--no-progress", "--threads", "2"]
    if tag == "after":
        cmd += AFTER_FLOW
    if g.exists():
        g.unlink()
    c0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    # cwd = the tree to run: ``python -m`` puts the working directory first on sys.path
    r = subprocess.run(cmd, check=False, env=env, capture_output=True, text=True, cwd=pythonpath)
    c1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    if r.returncode:
        raise SystemExit(f"{tag} preprocess of {vid} failed: {r.stderr.strip()[-400:]}")
    return g, (c1.ru_utime - c0.ru_utime) + (c1.ru_stime - c0.ru_stime)


def truth_arrays(vid: Path) -> dict:
    with np.load(OUT / f"{vid.stem}.truth.npz", allow_pickle=False) as z:
        d = {k: z[k] for k in z.files}
    d["meta"] = json.loads(str(d["meta"]))
    return d


def forward(field, cell_deg) -> np.ndarray:
    return viewport_epof(field, cell_deg, 0.0, 0.0, 0.0, hfov_deg=107.0)


def ratios(est, tru):
    ok = tru > 1.0
    return est[ok] / tru[ok], tru[ok]


def summary(r, tru) -> dict:
    """median / p10 of est / truth per frame, and over the frames > 60 deg/s."""
    if r.size == 0:
        return {}
    fast = tru > 60.0
    s = {"median": float(np.median(r)), "p10": float(np.percentile(r, 10)), "n": int(r.size)}
    if fast.sum() >= 3:
        s["fast_median"] = float(np.median(r[fast]))
        s["fast_p10"] = float(np.percentile(r[fast], 10))
        s["fast_n"] = int(fast.sum())
    return s


def omega_error(g, tru) -> dict:
    """|estimate - truth| of the camera's angular velocity: median deg/s, and median
    relative to |truth| over the frames turning faster than 5 deg/s."""
    est = np.asarray(g.extras["ego_omega_dps"], float)[1:]
    ref = np.asarray(tru["meta"]["trajectory"]["omega_cam_dps"], float)[1:]
    err = np.linalg.norm(est - ref, axis=1)
    mag = np.linalg.norm(ref, axis=1)
    moving = mag > 5.0
    out = {"abs_median_dps": float(np.median(err)), "truth_median_dps": float(np.median(mag))}
    if moving.sum() >= 3:
        out["rel_median"] = float(np.median(err[moving] / mag[moving]))
    return out


def trans_part(grid, tru, cell) -> dict:
    """Median of the forward viewport's epof_trans_dps / the truth's translational part,
    the truth split by the same rule (simulator.epof.parts: s * s_t / (s_r + s_t))."""
    from simulator.epof.parts import viewport_parts

    T = grid.n_frames
    z = np.zeros(T)
    rot, trans = viewport_parts(grid, z, z, z, hfov_deg=107.0, vfov_deg=107.0)
    tot = rot + trans
    on = tot > 1.0
    # the translational part's share of the EPOF: a pure rotation's is the split's leak
    share = {"trans_share_median": float(np.median(trans[on] / tot[on]))} if on.sum() >= 3 else {}
    s, sr, st = (np.asarray(tru[k], np.float64) for k in ("speed_dps", "speed_rot_dps", "speed_trans_dps"))
    both = sr + st
    t_part = s * np.where(both > 0, st / np.where(both > 0, both, 1.0), 0.5)
    tt = forward(t_part, cell)
    tr = forward(s - t_part, cell)
    out = dict(share)
    ok = tt > 1.0
    if ok.sum() >= 3:
        out["trans_ratio_median"] = float(np.median(trans[ok] / tt[ok]))
    ok = tr > 1.0
    if ok.sum() >= 3:
        out["rot_ratio_median"] = float(np.median(rot[ok] / tr[ok]))
    return out


def _smooth(x, k=5):
    ker = np.ones(k) / k
    return np.column_stack([np.convolve(x[:, i], ker, mode="same") for i in range(x.shape[1])])


def real_clip(max_frames: int | None) -> dict:
    """Rotation estimate on the real clip vs an independent OpenCV feature-track fit."""
    from bench._ego_reference import feature_rotation_dps

    if not REAL.is_file():
        return {"skipped": f"{REAL} not found"}
    g, _ = preprocess(REAL, "after", str(REPO))
    est = np.asarray(load_grid(g).extras["ego_omega_dps"], float)
    ref, ok = feature_rotation_dps(REAL, max_frames=max_frames)
    n = min(len(est), len(ref))
    est, ref, ok = est[1:n], ref[1:n], ok[1:n]
    d = np.linalg.norm(est - ref, axis=1)[ok]
    ds = np.linalg.norm(_smooth(est) - _smooth(ref), axis=1)[2:-2][ok[2:-2]]
    return {
        "frames": int(d.size),
        "median_diff_dps": float(np.median(d)),
        "median_diff_5frame_mean_dps": float(np.median(ds)),
        "median_ref_dps": float(np.median(np.linalg.norm(ref[ok], axis=1))),
        "median_est_dps": float(np.median(np.linalg.norm(est[ok], axis=1))),
    }


def _fmt(x):
    return round(x, 4) if isinstance(x, float) else x


def measure_clip(name, traj, room, kind, size, today) -> tuple[dict, dict]:
    vid = render(name, traj, room, size)
    tru = truth_arrays(vid)
    cell = float(tru["meta"]["config"]["truth_cell_deg"])
    ft = forward(tru["speed_dps"], cell)
    row, cost = {"kind": kind}, {}
    for tag, pp in (("today", today), ("after", str(REPO))):
        g, cpu = preprocess(vid, tag, pp)
        cost[tag] = cpu
        grid = load_grid(g)
        fe = forward(grid.field_dps, float(grid.meta["field"]["cell_deg"]))
        row[tag] = summary(*ratios(fe, ft))
        if tag == "after":
            row["after"]["omega"] = omega_error(grid, tru)
            row["after"].update(trans_part(grid, tru, cell))
    if kind == "trans":  # paper mode (unchanged by this change): its forward window's POF
        g, _ = preprocess(vid, "after", str(REPO), method="paper")
        pg = load_grid(g)
        p0 = int(np.argmin(np.abs(pg.pitch_deg)))
        y0 = int(np.argmin(np.abs(pg.yaw_deg)))
        row["paper"] = summary(*ratios(pg.pof_dps[:, p0, y0].astype(float), ft))
    return row, cost


#: The last commit before the flow-at-speed change (same flow algorithms as main had then).
TODAY_COMMIT = "35875b5"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seconds", type=float, default=2.0)
    ap.add_argument("--size", default="512x256")
    ap.add_argument("--today", default=None, help=f"a checkout of 'today' (default: {TODAY_COMMIT})")
    ap.add_argument("--only", default="")
    ap.add_argument("--no-real", action="store_true")
    ap.add_argument("--real-frames", type=int, default=0, help="0: the whole real clip")
    ap.add_argument("--after-flow", default="", help="--flow of 'after' (default: its default)")
    a = ap.parse_args()
    if a.today is None:  # the code before this change, from this repository's history
        a.today = tempfile.mkdtemp(prefix="vimsim-today-")
        arch = subprocess.run(["git", "-C", str(REPO), "archive", TODAY_COMMIT],
                              check=True, capture_output=True).stdout  # fmt: skip
        subprocess.run(["tar", "-x", "-C", a.today], input=arch, check=True)
    if a.after_flow:
        AFTER_FLOW[:] = ["--flow", a.after_flow]
    size = tuple(int(v) for v in a.size.split("x"))
    OUT.mkdir(parents=True, exist_ok=True)
    sel = {s for s in a.only.split(",") if s}
    rows, cost = {}, {"today": 0.0, "after": 0.0}
    for name, (traj, room, kind) in clips(a.seconds).items():
        if sel and name not in sel:
            continue
        row, c = measure_clip(name, traj, room, kind, size, a.today)
        for k in cost:
            cost[k] += c[k]
        rows[name] = row
        print(name, json.dumps(row, default=_fmt), flush=True)
    if cost["today"] > 0:
        print(
            f"cost: sphere-mode preprocess CPU after / today = {cost['after'] / cost['today']:.3f} "
            f"({cost['after']:.1f} s / {cost['today']:.1f} s over {len(rows)} clips)"
        )
    if not a.no_real:
        print("real:", json.dumps(real_clip(a.real_frames or None), default=_fmt))
    (OUT / "results.json").write_text(json.dumps({"clips": rows, "cost_cpu_s": cost}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
