"""A study as a lab runs it: two synthetic videos, 48 users of one dataset file on
one, single traces on the other, two conditions, renders for a subset with start/end/review,
one trace known to warn. Times ``vimsim study --dry-run`` (goal <= 1 s for 48 users) and the
run, and checks that the warnings are counted and attributed to the right viewing.

Reference measured in the same run: a bare Python process importing what any dry run
must import (numpy, scipy's rotations, PyAV), so the dry run's figure is printed as a
ratio to that floor on this machine (the shared machine's load moves wall times a lot;
CPU seconds are printed too), and the dry run as a share of the whole study.

Run: .venv/bin/python bench/study_lab.py
"""

from __future__ import annotations

import csv
import json
import os
import resource
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
REAL = REPO.parent / "shared" / "data" / "real"
TRACE = REAL / "headtraces" / "aggregated_360vidstr" / "AggregatedDataset" / "33.txt"
OUT = REPO / "bench" / "_out" / "study_lab"
VIMSIM = [str(Path(sys.executable).with_name("vimsim"))]

MANIFEST = """
[study]
name = "lab"

[[videos]]
id = "coaster"
path = "coaster.mp4"
window_size = 64

[[videos]]
id = "rotate"
path = "rotate.mp4"
window_size = 64

[[viewings]]
video = "coaster"
trace = "33.txt"
user = "1-24"
condition = "GR"
render = [1, 2]
start = 2.0
end = 5.0
review = true

[[viewings]]
video = "coaster"
trace = "33.txt"
user = "25-48"
condition = "NR"

[[viewings]]
video = "rotate"
trace = "single/G*.csv"
participant = "{stem}"
condition = "GR"

[[viewings]]
video = "rotate"
trace = "single/N*.csv"
participant = "{stem}"
condition = "NR"

[render]
eye_size = "128x128"
"""


CPU: dict[str, list[float]] = {}


def run(argv: list[str], name: str = "") -> tuple[float, subprocess.CompletedProcess]:
    """Wall seconds of a command (its CPU seconds, user + sys, into CPU[name])."""
    r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    p = subprocess.run(argv, capture_output=True, text=True, check=False)
    wall = time.perf_counter() - t0
    r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    CPU.setdefault(name, []).append(r1.ru_utime - r0.ru_utime + r1.ru_stime - r0.ru_stime)
    return wall, p


def setup() -> Path:
    d = OUT / "in"
    if d.exists():
        shutil.rmtree(d)
    (d / "single").mkdir(parents=True)
    for name, scene in (("coaster", "coaster"), ("rotate", "rotate")):
        subprocess.run([*VIMSIM, "synth", str(d / f"{name}.mp4"), "--scene", scene,
                        "--seconds", "10", "--fps", "10", "--size", "256x128", "--quiet"],
                       check=True)  # fmt: skip
    shutil.copy(TRACE, d / "33.txt")
    from simulator.traces.path import save_headpath_csv, synth

    for i, c in enumerate("GGNN"):
        save_headpath_csv(d / "single" / f"{c}{i}.csv", synth("look-around", 12, seed=i))
    # known to warn: degrees column holding radians (RadiansWarning), condition NR
    hp = synth("sine", 12.0, rate_hz=30, yaw_amp=150.0, yaw_freq=0.2)
    y, p, _ = hp.sample_angles_deg(hp.times_s)
    rows = "".join(f"{a:.4f},{np.radians(b):.5f},{np.radians(c):.5f},0\n"
                   for a, b, c in zip(hp.times_s, y, p))  # fmt: skip
    (d / "single" / "N9_radians.csv").write_text("time_s,yaw_deg,pitch_deg,roll_deg\n" + rows)
    (d / "study.toml").write_text(MANIFEST)
    return d


def main() -> int:
    d = setup()
    out, cache = OUT / "o", OUT / "cache"
    for p in (out, cache):
        shutil.rmtree(p, ignore_errors=True)
    args = [*VIMSIM, "study", str(d / "study.toml"), "-o", str(out), "--cache-dir", str(cache)]
    floor = [sys.executable, "-c", "import numpy, scipy.spatial.transform, av"]
    ref = min(run(floor, "ref")[0] for _ in range(3))
    dry = []
    for _ in range(3):
        s, p = run([*args, "--dry-run"], "dry")
        assert p.returncode == 0, p.stderr
        dry.append(s)
    dry_s = min(dry)
    print(p.stdout.splitlines()[-1])
    assert not out.exists(), "the dry run wrote the output folder"
    run_s, p = run(args)
    assert p.returncode == 0, p.stderr
    final = p.stdout.splitlines()[-1]
    print(final)
    s = json.loads((out / "study.json").read_text())
    with open(out / "viewings.csv", newline="") as fh:
        rows = {r["viewing"]: r for r in csv.DictReader(fh)}
    warned = {k: r["warnings"] for k, r in rows.items() if r["warnings"]}
    # attribution: each warning names its own trace (and user)
    for k, text in warned.items():
        r = rows[k]
        own = Path(r["trace"]).name + (f":user{r['user']}" if r["user"] else "")
        assert all(own in w for w in text.split(" | ")), (k, text)
    assert "RADIANS" in warned.get("rotate-N9_radians-NR", ""), warned
    assert s["counts"]["with_warnings"] == len(warned)
    assert f"{len(warned)} with warnings" in final
    console = [ln for ln in p.stderr.splitlines() if ": warning: " in ln]
    n_render = sum(1 for w in s["outputs"]["videos"]) and len(list((out / "render").iterdir()))
    rsum = json.loads((out / "render" / "coaster-33_user01-GR" / "summary.json").read_text())
    # resume: nothing recomputed, warnings kept
    res_s, p2 = run(args)
    assert "0 failed" in p2.stdout and f"{len(warned)} with warnings" in p2.stdout
    print(f"viewings {s['counts']['viewings']}, with warnings {len(warned)} "
          f"({', '.join(sorted(warned))}), console warning lines {len(console)}, "
          f"renders {n_render} ({rsum['frames_written']} frames each, review "
          f"{bool(rsum['review'])})")  # fmt: skip
    print(f"dry run {dry_s:.2f} s wall, {min(CPU['dry']):.2f} s CPU (goal <= 1 s; runs "
          f"{', '.join(f'{x:.2f}' for x in dry)}); import floor {ref:.2f} s wall, "
          f"{min(CPU['ref']):.2f} s CPU: dry run = {dry_s / ref:.2f}x the floor "
          f"({min(CPU['dry']) / min(CPU['ref']):.2f}x in CPU); load {os.getloadavg()[0]:.1f}")
    print(f"run {run_s:.1f} s (cold cache, 2 preprocesses, 53 EPOFs, 2 renders); dry run = "
          f"{dry_s / run_s:.3f} of the run; resumed run {res_s:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
