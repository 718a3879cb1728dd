"""Scaling of a render-heavy study: 8 renders (+ their EPOFs) with 1 and 2 workers, on the
local executor and on Ray (a local runtime, ``--executor ray``).

Figures: wall-clock ratio 1 worker / 2 workers per executor (goal >= 1.7x on 2 cores) and
the Ray overhead against the local executor at 2 workers (goal <= 10 %). Each is the whole
``vimsim study`` process (Ray's start-up included) and, beside it, the task phase alone
(``timings_s.tasks`` of study.json). The grid is made once before (cached), every run
recomputes all viewings (``--no-resume``) into a fresh folder; viewings.csv of all runs
must be identical. Clip: synthetic ``coaster`` scene, 4 s at 30 fps, 1024x512; eyes 480x480,
one llvmpipe thread per render task (its declared CPU).

Run: .venv/bin/python bench/study_scaling.py [--rounds N]
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


def setup() -> Path:
    from simulator.headpath import save_headpath_csv, synth
    from simulator.synth import SynthConfig, synthesize

    OUT.mkdir(parents=True, exist_ok=True)
    clip = OUT / "coaster.mp4"
    if not clip.is_file():
        synthesize(SynthConfig("coaster", seconds=4.0, fps=30, size=(1024, 512)), clip)
    for i in range(8):
        save_headpath_csv(OUT / f"P{i + 1:02d}.csv", synth("look-around", 4.5, rate_hz=60, seed=i))
    m = OUT / "study.toml"
    m.write_text("""[[videos]]
id = "coaster"
path = "coaster.mp4"
method = "sphere"

[[viewings]]
video = "coaster"
trace = "P*.csv"
participant = "{stem}"
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
    ap.add_argument("--rounds", type=int, default=1)
    args = ap.parse_args()
    m = setup()
    shutil.rmtree(OUT / "cache", ignore_errors=True)  # the clip may have changed
    study(m, "warmup", "local", 2)  # makes the cached grid
    ref = (OUT / "warmup" / "viewings.csv").read_bytes()
    res: dict[tuple[str, int], list[tuple[float, float]]] = {}
    load0 = os.getloadavg()[0]
    for _ in range(args.rounds):
        for ex in ("local", "ray"):
            for w in (1, 2):
                wall, s = study(m, f"{ex}{w}", ex, w)
                assert (OUT / f"{ex}{w}" / "viewings.csv").read_bytes() == ref
                res.setdefault((ex, w), []).append((wall, s["timings_s"]["tasks"]))
    med = {k: (statistics.median(a for a, _ in v), statistics.median(b for _, b in v))
           for k, v in res.items()}  # fmt: skip
    print(
        f"render-heavy study: 8 viewings rendered (480x480 per eye, 120 frames), median of "
        f"{args.rounds} round(s); load average {load0:.1f} before, {os.getloadavg()[0]:.1f} "
        "after (2 cores)"
    )
    for (ex, w), (wall, tasks) in sorted(med.items()):
        print(f"  {ex:5s} {w} worker(s): {wall:6.2f} s whole process, {tasks:6.2f} s tasks")
    for ex in ("local", "ray"):
        a, b = med[(ex, 1)], med[(ex, 2)]
        print(
            f"  scaling {ex:5s} 1 -> 2 workers: {a[0] / b[0]:.2f}x whole process, {a[1] / b[1]:.2f}x tasks (goal >= 1.7x)"
        )
    lw, rw = med[("local", 2)], med[("ray", 2)]
    print(
        f"  Ray overhead vs local at 2 workers: {100 * (rw[0] / lw[0] - 1):+.1f}% whole process, "
        f"{100 * (rw[1] / lw[1] - 1):+.1f}% tasks (goal <= 10%)"
    )
    print("  viewings.csv identical in every run")
    return 0


if __name__ == "__main__":
    sys.exit(main())
