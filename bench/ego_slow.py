"""Ego per axis at slow and fast rates, this tree against another (``--before DIR``), with the preprocess cost of both measured in the same run.

Rotate clips (512x256, ``--frames`` frames at 30 fps, H.264 crf ``--crf``; made once by this
tree) turn the camera at 5-120 deg/s about its yaw, pitch and roll axes. Each tree runs
``preprocess_sphere`` (default grid, default flow) on every clip in a subprocess of its own
(``PYTHONPATH`` = the tree), the two trees interleaved ``--repeats`` times; printed: the
error of the mean rate about the turning axis in % of the truth (rows 1.., as ``vimsim ego``
reports them), the largest rate about the other axes, the mean speed field over the sphere
against the truth's (omega * pi / 4), and the CPU seconds of the preprocessing alone
(clips decoded and flowed, process start-up excluded) with the ratio this / before.

    .venv/bin/python bench/ego_slow.py --before /tmp/old-tree [--crf 16] [--frames 10]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SPEEDS = (5.0, 10.0, 20.0, 30.0, 60.0, 120.0)
AXES = {"yaw": (0.0, -1.0, 0.0), "pitch": (1.0, 0.0, 0.0), "roll": (0.0, 0.0, 1.0)}

_CHILD = r"""
import json, math, sys, time
import numpy as np
from simulator.media.gridfile import load_grid
from simulator.preprocess import preprocess_sphere
from simulator.sphere.windows import grid_preset
clips = json.loads(sys.argv[1])
out = {}
cpu = {"slow": 0.0, "fast": 0.0}
lat = np.radians(90 - 4 * (np.arange(45) + 0.5))
for name, path in clips.items():
    t0 = time.process_time()
    g = load_grid(preprocess_sphere(path, path + ".npz", grid=grid_preset("default"),
                                    field_dtype="float32"))
    cpu["slow" if float(name.split(":")[1]) <= 20 else "fast"] += time.process_time() - t0
    om = g.extras["ego_omega_dps"][1:].astype(float)
    f = np.asarray(g.field_dps[:], float)[1:]
    w = np.cos(lat)[None, :, None] * np.ones_like(f)
    rates = np.column_stack([om[:, 1], -om[:, 0], -om[:, 2]]).mean(axis=0)
    out[name] = {"rates": rates.tolist(), "field": float((f * w).sum() / w.sum())}
print(json.dumps({"cpu_s": cpu, "clips": out}))
"""


def make_clips(d: Path, crf: int, frames: int) -> dict[str, str]:
    sys.path.insert(0, str(REPO))
    from simulator.synth import SynthConfig
    from simulator.synth.clip import synthesize

    clips = {}
    for axis, vec in AXES.items():
        for s in SPEEDS:
            cfg = SynthConfig(scene="rotate", seconds=frames / 30, size=(512, 256), axis=vec,
                              omega_dps=s)  # fmt: skip
            clips[f"{axis}:{s:g}"] = str(synthesize(cfg, d / f"{axis}{s:g}.mp4", crf=crf)[0])
    return clips


def run_tree(tree: Path, clips: dict[str, str]) -> dict:
    env = {**os.environ, "PYTHONPATH": str(tree), "OPENBLAS_NUM_THREADS": "1"}
    r = subprocess.run([sys.executable, "-c", _CHILD, json.dumps(clips)], env=env, cwd=tree,
                       check=True, capture_output=True, text=True)  # fmt: skip
    return json.loads(r.stdout.strip().splitlines()[-1])


def table(label: str, res: dict) -> None:
    import math

    print(
        f"\n{label}: error of the mean rate about the turning axis, % (field: mean speed / truth)"
    )
    print("   axis   " + "".join(f"{s:>8g}" for s in SPEEDS) + "   other axes max (deg/s)")
    for k, axis in enumerate(AXES):
        errs, fld, cross = [], [], []
        for s in SPEEDS:
            c = res["clips"][f"{axis}:{s:g}"]
            errs.append((c["rates"][k] - s) / s * 100)
            fld.append(c["field"] / (s * math.pi / 4))
            cross.append(max(abs(c["rates"][j]) for j in range(3) if j != k))
        print(f"   {axis:6s} " + "".join(f"{e:+8.1f}" for e in errs) + f"   {max(cross):.2f}")
        print("   field  " + "".join(f"{x:8.3f}" for x in fld))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--before", type=Path, required=True, help="the other tree (a checkout)")
    ap.add_argument("--crf", type=int, default=16)
    ap.add_argument("--frames", type=int, default=10)
    ap.add_argument("--repeats", type=int, default=2)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="vimsim-bench-ego-slow-") as tmp:
        clips = make_clips(Path(tmp), args.crf, args.frames)
        cpu: dict = {"before": [], "this": []}
        for _ in range(args.repeats):  # interleaved: the machine's load hits both alike
            res_b = run_tree(args.before.resolve(), clips)
            res_t = run_tree(REPO, clips)
            cpu["before"].append(res_b["cpu_s"])
            cpu["this"].append(res_t["cpu_s"])
    print(f"rotate clips 512x256, {args.frames} frames at 30 fps, crf {args.crf}; default flow")
    table(f"before ({args.before})", res_b)
    table("this tree", res_t)
    print(f"\npreprocess CPU, best of {args.repeats} interleaved runs (all runs: {cpu}):")
    for part, label in (("slow", "5-20 deg/s (9 clips)"), ("fast", "30-120 deg/s (9 clips)")):
        b = min(c[part] for c in cpu["before"])
        t = min(c[part] for c in cpu["this"])
        print(f"   {label:24s} before {b:.2f} s, this {t:.2f} s, ratio this / before {t / b:.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
