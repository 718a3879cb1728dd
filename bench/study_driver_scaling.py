"""The study driver's scaling in viewings (issue 41): 500 and 2000 small viewings.

Usage: .venv/bin/python bench/study_driver_scaling.py [--small 500] [--factor 4] [--workers 2]

A 10-frame clip (synthetic ``rotate``, 128x64), its grid made once (cached); a manifest of
``--small`` scripted viewers and one of ``--factor`` times as many; each run in a fresh
process into a fresh folder. Prints the wall time of each whole ``vimsim study``, the
driver's own CPU time (``timings_s.cpu_driver`` of study.json) and their ratios, measured
in the same run. Goal: the large / small wall ratio <= 4 (linear: the factor).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
OUT = REPO / "bench" / "_out" / "study_driver"


def manifest(clip: Path, n: int) -> Path:
    m = OUT / f"study{n}.toml"
    m.write_text(f'[[videos]]\nid = "clip"\npath = "{clip}"\nwindow_size = 64\n\n'
                 f'[[viewings]]\nvideo = "clip"\nviewers = {{n = {n}}}\n')  # fmt: skip
    return m


def run(m: Path, workers: int) -> tuple[float, dict]:
    out = OUT / f"out_{m.stem}"
    shutil.rmtree(out, ignore_errors=True)
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "simulator", "study", str(m), "-o", str(out),
                    "--workers", str(workers), "--cache-dir", str(OUT / "cache"), "--no-progress"],
                   check=True, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)  # fmt: skip
    wall = time.perf_counter() - t0
    return wall, json.loads((out / "study.json").read_text())


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--small", type=int, default=500)
    ap.add_argument("--factor", type=int, default=4)
    ap.add_argument("--workers", type=int, default=2)
    a = ap.parse_args()
    from simulator.synth import SynthConfig, synthesize

    OUT.mkdir(parents=True, exist_ok=True)
    clip = OUT / "clip10.mp4"
    if not clip.is_file():
        synthesize(SynthConfig("rotate", seconds=1.0, fps=10, size=(128, 64)), clip)
    run(manifest(clip, 2), a.workers)  # the grid, cached for both runs
    res = {}
    for n in (a.small, a.small * a.factor):
        wall, s = run(manifest(clip, n), a.workers)
        assert s["counts"]["ok"] == n, s["counts"]
        t = s["timings_s"]
        res[n] = (wall, t["cpu_driver"])
        print(f"{n:6d} viewings: wall {wall:6.1f} s, driver CPU {t['cpu_driver']:6.1f} s, "
              f"plan {t['plan']:.1f} s, tasks {t['tasks']:.1f} s, outputs {t['outputs']:.1f} s",
              flush=True)  # fmt: skip
    (w0, c0), (w1, c1) = res[a.small], res[a.small * a.factor]
    print(f"study {a.small * a.factor} / {a.small} viewings: wall {w1 / w0:.2f}x, driver CPU "
          f"{c1 / c0:.2f}x (goal <= {a.factor}x)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
