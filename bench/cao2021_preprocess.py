"""Paper-mode preprocessing with ``--grid cao2021`` (312 windows of 1600 x 1440 px) as a ratio to
the ``default`` grid (264 windows of 256 x 256 px), on the same 10 s clip, in the same run.

The clip: 10 s of the synthetic coaster at 30 fps, 1024 x 512. Each grid runs in a fresh
process (``preprocess_video``, DIS ultrafast, ``--threads``, the map cache off: maps built
in the run); the steady time per frame comes from the ``on_frame`` hook (first row to last)
over the first ``--frames`` rows, the start-up (maps built) from launch to the first row.
Printed: both, the ratio cao2021 / default per frame, and the 10 s clip's extrapolated time.
The default grid also runs on the whole clip unless ``--frames`` covers it.

    .venv/bin/python bench/cao2021_preprocess.py [--frames 6] [--threads 2]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from simulator.synth import SynthConfig, synthesize

SECONDS, FPS = 10.0, 30.0

_CHILD = """
import json, sys, time
t0 = float(sys.argv[1])
from simulator.preprocess import preprocess_video
from simulator.sphere.windows import grid_preset
stamps = []
n = int(sys.argv[5])
preprocess_video(sys.argv[2], sys.argv[3], grid=grid_preset(sys.argv[4]), threads=int(sys.argv[6]),
                 progress=False, cache=False, end_s=n / 30.0,
                 on_frame=lambda r: stamps.append(time.time()))
print(json.dumps({"first": stamps[0] - t0, "per_frame": (stamps[-1] - stamps[0]) / (len(stamps) - 1),
                  "rows": len(stamps), "whole": time.time() - t0}))
"""


def _run(vid: Path, out: Path, grid: str, frames: int, threads: int) -> dict:
    r = subprocess.run([sys.executable, "-c", _CHILD, repr(time.time()), str(vid), str(out), grid,
                        str(frames), str(threads)], capture_output=True, text=True, check=False,
                       env={**os.environ, "OPENBLAS_NUM_THREADS": "1"})  # fmt: skip
    if r.returncode:
        raise SystemExit(f"{grid}: {r.stderr.strip()[-400:]}")
    return json.loads(r.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--frames", type=int, default=6, help="rows measured for cao2021 (default 6)")
    ap.add_argument("--threads", type=int, default=2)
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        vid = d / "coaster.mp4"
        synthesize(SynthConfig("coaster", SECONDS, FPS, (1024, 512)), vid)
        n_all = int(SECONDS * FPS)
        ref = _run(vid, d / "default.npz", "default", n_all, a.threads)
        cao = _run(vid, d / "cao.npz", "cao2021", a.frames, a.threads)
    ratio = cao["per_frame"] / ref["per_frame"]
    print(
        f"default grid (264 x 256^2 px): {ref['per_frame'] * 1e3:.1f} ms/frame, first row after "
        f"{ref['first']:.1f} s, whole 10 s clip {ref['whole']:.1f} s ({ref['rows']} rows)"
    )
    print(
        f"cao2021 grid (312 x 1600x1440 px): {cao['per_frame'] * 1e3:.0f} ms/frame over "
        f"{cao['rows']} rows, first row after {cao['first']:.1f} s (maps built)"
    )
    print(
        f"ratio cao2021 / default: {ratio:.1f}x per frame; 10 s clip extrapolated: "
        f"{cao['first'] + cao['per_frame'] * (n_all - 1):.0f} s vs {ref['whole']:.1f} s "
        f"({(cao['first'] + cao['per_frame'] * (n_all - 1)) / ref['whole']:.1f}x)"
    )


if __name__ == "__main__":
    main()
