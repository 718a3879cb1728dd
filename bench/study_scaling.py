"""Scaling of a render-heavy study: 8 renders (+ their EPOFs) with 1 and 2 workers, on the
local executor and on Ray (a local runtime, ``--executor ray``).

Figures: wall-clock ratio 1 worker / 2 workers per executor (goal >= 1.7x on 2 cores) and
the Ray overhead against the local executor at 2 workers (goal <= 10 %). Each is the whole
``vimsim study`` process (Ray's start-up included) and, beside it, the task phase alone
(``timings_s.tasks`` of study.json), and the executor's own fixed cost (start-up and
shut-down: the whole process less tasks and outputs). The grid is made once before
(cached), every run recomputes all viewings (``--no-resume``) into a fresh folder;
viewings.csv of all runs must be identical. Rounds alternate the four runs; medians.
Clip: synthetic ``coaster`` scene, ``--seconds`` (default 8) at 30 fps, 1024x512; eyes
480x480; each render task declares one CPU and keeps to it (``[render] cpus = 1``).

Run: .venv/bin/python bench/study_scaling.py [--rounds N] [--seconds S]
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
OUT = REPO / "bench" / "_out" / "study_scaling"
VIMSIM = [str(Path(sys.executable).with_name("vimsim"))]


def setup(seconds: float) -> Path:
    from simulator.synth import SynthConfig, synthesize
    from simulator.traces.path import save_headpath_csv, synth

    OUT.mkdir(parents=True, exist_ok=True)
    clip = OUT / f"coaster{seconds:g}s.mp4"
    if not clip.is_file():
        synthesize(SynthConfig("coaster", seconds=seconds, fps=30, size=(1024, 512)), clip)
    for i in range(8):
        save_headpath_csv(
            OUT / f"P{i + 1:02d}.csv", synth("look-around", seconds + 0.5, rate_hz=60, seed=i)
        )
    m = OUT / "study.toml"
    m.write_text(f"""[[videos]]
id = "coaster"
path = "{clip.name}"
method = "sphere"

[[viewings]]
video = "coaster"
trace = "P*.csv"
participant = "{{stem}}"
render = true

[render]
eye_size = "480x480"
cpus = 1
""")
    return m


def study(m: Path, name: str, executor: str, workers: int) -> tuple[float, dict]:
    out = OUT / name
    shutil.rmtree(out, ignore_errors=True)
    env = {**os.environ, "RAY_USAGE_STATS_ENABLED": "0"}
    t0 = time.perf_counter()
    subprocess.run([*VIMSIM, "study", str(m), "-o", str(out), "--cache-dir", str(OUT / "cache"),
                    "--executor", executor, "--workers", str(workers), "--no-resume", "--no-progress"],
                   check=True, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)  # fmt: skip
    wall = time.perf_counter() - t0
    s = json.loads((out / "study.json").read_text())
    assert s["counts"]["ok"] == 8 and s["counts"]["renders"] == 8, s["counts"]
    return wall, s


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--seconds", type=float, default=8.0, help="clip length (s)")
    args = ap.parse_args()
    m = setup(args.seconds)
    shutil.rmtree(OUT / "cache", ignore_errors=True)  # the clip may have changed
    study(m, "warmup", "local", 2)  # makes the cached grid
    ref = (OUT / "warmup" / "viewings.csv").read_bytes()
    res: dict[tuple[str, int], list[tuple[float, float]]] = {}
    load0 = os.getloadavg()[0]
    runs = [(ex, w) for ex in ("local", "ray") for w in (1, 2)]
    for r in range(args.rounds):
        for ex, w in runs[r % 4 :] + runs[: r % 4]:  # each round starts one run later
            wall, s = study(m, f"{ex}{w}", ex, w)
            assert (OUT / f"{ex}{w}" / "viewings.csv").read_bytes() == ref
            t = s["timings_s"]
            fixed = wall - t["tasks"] - t["outputs"]  # process start, executor up/down
            res.setdefault((ex, w), []).append((wall, t["tasks"], fixed))
    med = {k: tuple(statistics.median(r[i] for r in v) for i in range(3)) for k, v in res.items()}
    n_frames = round(args.seconds * 30)
    print(
        f"render-heavy study: 8 viewings rendered (480x480 per eye, {n_frames} frames), median of "
        f"{args.rounds} round(s); load average {load0:.1f} before, {os.getloadavg()[0]:.1f} "
        "after (2 cores)"
    )
    for (ex, w), (wall, tasks, fixed) in sorted(med.items()):
        each = ", ".join(f"{a:.1f}" for a, _, _ in res[(ex, w)])
        print(
            f"  {ex:5s} {w} worker(s): {wall:6.2f} s whole process, {tasks:6.2f} s tasks, "
            f"{fixed:5.2f} s start-up and shut-down (rounds: {each} s)"
        )
    for ex in ("local", "ray"):
        a, b = med[(ex, 1)], med[(ex, 2)]
        print(
            f"  scaling {ex:5s} 1 -> 2 workers: {a[0] / b[0]:.2f}x whole process, {a[1] / b[1]:.2f}x tasks (goal >= 1.7x)"
        )
    lw, rw = med[("local", 2)], med[("ray", 2)]
    print(
        f"  Ray overhead vs local at 2 workers: {100 * (rw[0] / lw[0] - 1):+.1f}% whole process, "
        f"{100 * (rw[1] / lw[1] - 1):+.1f}% tasks (goal <= 10%); Ray's fixed cost "
        f"{rw[2] - lw[2]:+.2f} s"
    )
    print("  viewings.csv identical in every run")
    return 0


if __name__ == "__main__":
    sys.exit(main())
