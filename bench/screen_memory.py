"""Peak memory of ``vimsim screen``'s worker processes against video length (issue 41).

Usage: .venv/bin/python bench/screen_memory.py [--short 300] [--factor 10] [--viewers 8]

Makes two small clips of the same content (synthetic ``rotate`` scene, 128x64, 30 fps),
``--short`` frames and ``--factor`` times as many, screens each in a fresh process (2
workers, a fresh grid cache: the preprocess runs in a worker too) and polls every worker's
peak resident memory (``VmHWM`` of ``/proc/<pid>/status``; workers are the command's
session processes that are not its own children). Prints both peaks and their ratio,
measured in the same run. Goal: long / short <= 1.2.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
OUT = REPO / "bench" / "_out" / "screen_memory"


def _procs(sid: int) -> dict[int, int]:
    """{pid: ppid} of the live processes of session ``sid``."""
    found = {}
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                stat = (d / "stat").read_text()
            except OSError:
                continue
            f = stat[stat.rindex(")") + 2 :].split()
            if int(f[3]) == sid and f[0] != "Z":
                found[int(d.name)] = int(f[1])
    return found


def _hwm_kib(pid: int) -> int:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1])
    except OSError:
        pass
    return 0


def screen_peak(clip: Path, viewers: int) -> tuple[int, int]:
    """(peak KiB of any worker, peak KiB of the driver) of one screening."""
    out, cache = OUT / f"out_{clip.stem}", OUT / f"cache_{clip.stem}"
    shutil.rmtree(out, ignore_errors=True)
    shutil.rmtree(cache, ignore_errors=True)
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    p = subprocess.Popen([sys.executable, "-m", "simulator", "screen", str(clip), "-o", str(out),
                          "--viewers", str(viewers), "--workers", "2", "--cache-dir", str(cache),
                          "--no-progress"], env=env, start_new_session=True,
                         stdout=subprocess.DEVNULL)  # fmt: skip
    workers: dict[int, int] = {}
    driver = 0
    while p.poll() is None:
        for pid, ppid in _procs(p.pid).items():
            if pid == p.pid:
                driver = max(driver, _hwm_kib(pid))
            elif ppid != p.pid:  # forked by the fork server: a pool worker
                workers[pid] = max(workers.get(pid, 0), _hwm_kib(pid))
        time.sleep(0.1)
    assert p.returncode == 0, p.returncode
    return max(workers.values(), default=0), driver


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--short", type=int, default=300, help="frames of the short clip")
    ap.add_argument("--factor", type=int, default=10)
    ap.add_argument("--viewers", type=int, default=8)
    a = ap.parse_args()
    from simulator.synth import SynthConfig, synthesize

    OUT.mkdir(parents=True, exist_ok=True)
    peaks = {}
    for n in (a.short, a.short * a.factor):
        clip = OUT / f"rotate{n}.mp4"
        if not clip.is_file():
            synthesize(SynthConfig("rotate", seconds=n / 30, fps=30, size=(128, 64)), clip)
        t0 = time.perf_counter()
        peaks[n] = screen_peak(clip, a.viewers)
        print(f"{n:6d} frames: worker peak {peaks[n][0] / 1024:7.1f} MiB, driver peak "
              f"{peaks[n][1] / 1024:7.1f} MiB ({time.perf_counter() - t0:.0f} s)", flush=True)  # fmt: skip
    lo, hi = peaks[a.short][0], peaks[a.short * a.factor][0]
    print(f"screen worker peak RSS {a.short * a.factor} / {a.short} frames: {hi / lo:.2f}x "
          "(goal <= 1.2x)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
