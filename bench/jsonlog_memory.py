"""Peak memory of reading a long one-line JSON head log (issue 41), as a ratio to its size.

Usage: .venv/bin/python bench/jsonlog_memory.py [--mb 94]

Writes a SIT-VR-shaped log (a JSON object keyed by clock timestamps, each entry the HMD's
rotation and position and a few other fields) of about ``--mb`` MB on one line, then reads
it through ``vimsim headpath convert --columns`` in a fresh process and prints that
process's peak resident memory (``ru_maxrss``), the file's size and their ratio, beside
the same for a bare interpreter that imports the reader (the fixed part). Goal: peak /
size <= 3 (was 2.6 GB for a 94 MB log: 28x).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
OUT = REPO / "bench" / "_out" / "jsonlog_memory"
MAP = "time=key,yaw=HMD.rot.y,pitch=-HMD.rot.x,roll=-HMD.rot.z"
FMT = "%Y%m%dZ-%H%M%S_%fZ"


def write_log(path: Path, mb: float) -> None:
    with open(path, "w") as fh:
        fh.write("{")
        k, size = 0, 1
        while size < mb * 1e6:
            ms = 686 + 11 * k
            key = (f"20210510Z-{20 + ms // 3_600_000:02d}{ms // 60_000 % 60:02d}"
                   f"{ms // 1000 % 60:02d}_{ms % 1000:03d}Z")  # fmt: skip
            entry = {"HMD": {"rot": {"x": (0.5 * k) % 360.0, "y": (0.75 * k) % 360.0, "z": 0.0},
                             "pos": {"x": 0.1, "y": 1.6, "z": -0.2}},
                     "scene": "sandwich", "buttons": [0, 1, 0]}  # fmt: skip
            text = ("," if k else "") + json.dumps(key) + ":" + json.dumps(entry, separators=(",", ":"))
            fh.write(text)
            size += len(text)
            k += 1
            if ms // 3_600_000 >= 3:
                break
        fh.write("}")


def peak_kib(args: list[str]) -> int:
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    subprocess.run([sys.executable, *args], check=True, env=env, stdout=subprocess.DEVNULL)
    after = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    return after  # the largest child so far: run the smaller first


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--mb", type=float, default=94.0)
    a = ap.parse_args()
    OUT.mkdir(parents=True, exist_ok=True)
    log = OUT / f"log{a.mb:g}.json"
    if not log.is_file():
        write_log(log, a.mb)
    size = log.stat().st_size
    base = peak_kib(["-c", "import simulator.traces.readers, simulator.cli"])
    peak = peak_kib(["-m", "simulator", "headpath", "convert", str(log), "-o",
                     str(OUT / "path.csv"), "--columns", MAP, "--time-format", FMT, "--quiet"])  # fmt: skip
    mib = 1 << 20
    print(f"log {size / mib:.1f} MiB (one line); bare interpreter + reader {base / 1024:.0f} MiB")
    print(f"JSON log peak RSS {peak / 1024:.0f} MiB / file size {size / mib:.1f} MiB: "
          f"{peak * 1024 / size:.2f}x (goal <= 3x); above the bare interpreter: "
          f"{(peak - base) * 1024 / size:.2f}x")
    return 0


if __name__ == "__main__":
    sys.exit(main())
