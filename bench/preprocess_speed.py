"""Throughput of ``vimsim preprocess`` on a 2048x1024 H.264 video, default grid, as a
ratio to the DIS-only floor measured in the same run (issues 3 and 19).

The floor: OpenCV DIS alone on the 264 pre-extracted window pairs per frame, on a pool of
``--threads`` threads (default 2), nothing else running in this process. Then one fresh
process runs ``preprocess_video`` on the whole clip and reports, through its ``on_frame``
hook, the time from its launch to the first grid row (start-up: imports, probe, hash,
maps, the first two frames) and the steady rate; the process's whole wall time gives
the end-to-end rate. Goals (issue 19): steady / floor >= 0.75, whole / floor >= 0.6,
first row within 2 s of launch. Then a per-stage CPU profile (one caller thread).

    .venv/bin/python bench/preprocess_speed.py [--frames 120] [--flow dis] [--threads 2]
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np
from PIL import Image
from preprocess_accuracy import OUT, PANO, make_rotation_video

from simulator.flow import make_backend
from simulator.preprocess import WindowFlowReducer, reduce_stride
from simulator.video import iter_frames
from simulator.windows import WindowExtractor, grid_preset

GOAL_STEADY, GOAL_WHOLE, GOAL_START_S = 0.75, 0.6, 2.0

_CHILD = """
import json, sys, time
t_launch = float(sys.argv[1])
from simulator.preprocess import preprocess_video
from simulator.windows import grid_preset
stamps, cpu = [], []
preprocess_video(sys.argv[2], sys.argv[3], grid=grid_preset("default", size=(int(sys.argv[6]),) * 2),
                 flow=sys.argv[4], threads=int(sys.argv[5]) or None, progress=False,
                 on_frame=lambda r: (stamps.append(time.time()), cpu.append(time.process_time())))
print(json.dumps({"first": stamps[0] - t_launch, "stamps": [t - stamps[0] for t in stamps],
                  "cpu": (cpu[-1] - cpu[0]) / (len(cpu) - 1)}))
"""


def floor_rate(wins: list, flow: str, threads: int) -> tuple[float, float]:
    """``(frames/s, CPU s per frame)`` of the flow alone on consecutive window stacks (one
    DIS per thread)."""
    be = make_backend(flow)
    n = wins[0].shape[0]
    bounds = np.linspace(0, n, 4 * threads + 1).astype(int)
    chunks = list(itertools.pairwise(bounds))

    def pair(i: int, c: tuple[int, int]):
        return be(wins[i - 1][c[0] : c[1]], wins[i][c[0] : c[1]])

    with ThreadPoolExecutor(threads) as pool:
        list(pool.map(lambda c: pair(1, c), chunks))  # warm-up: one DIS object per thread
        t, c = time.perf_counter(), time.process_time()
        for i in range(1, len(wins)):
            list(pool.map(lambda c, i=i: pair(i, c), chunks))
        n = len(wins) - 1
        return n / (time.perf_counter() - t), (time.process_time() - c) / n


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=120)
    ap.add_argument("--flow", default="dis")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--window-size", type=int, default=256)
    args = ap.parse_args(argv)
    if not PANO.is_file():
        print(f"skip: {PANO} not found", file=sys.stderr)
        return 0
    OUT.mkdir(parents=True, exist_ok=True)
    vid = OUT / f"speed_{args.frames}f.mp4"
    if not vid.exists():
        img = np.asarray(Image.open(PANO).convert("RGB").resize((2048, 1024), Image.LANCZOS))
        make_rotation_video(vid, img, (0.3, 1.0, 0.1), 30.0, 30.0, args.frames)
    grid = grid_preset("default", size=(args.window_size, args.window_size))
    load0 = os.getloadavg()[0]
    ex = WindowExtractor(grid, (2048, 1024))
    n = min(args.frames, 11)
    frames = [np.array(f) for f in iter_frames(vid, fmt="gray", end=n)]
    wins = [ex(f, interp="linear").reshape(grid.n_windows, *grid.size[::-1]) for f in frames]
    floor, floor_cpu = floor_rate(wins, args.flow, args.threads)

    t_launch = time.time()
    res = subprocess.run(
        [
            sys.executable,
            "-c",
            _CHILD,
            repr(t_launch),
            str(vid),
            str(OUT / "speed.npz"),
            args.flow,
            str(args.threads),
            str(args.window_size),
        ],
        capture_output=True,
        text=True,
        check=True,
    )
    whole_s = time.time() - t_launch
    child = json.loads(res.stdout.strip().splitlines()[-1])
    st = child["stamps"]
    steady = (len(st) - 1) / (st[-1] - st[0])
    whole = args.frames / whole_s
    floor2, floor_cpu2 = floor_rate(wins, args.flow, args.threads)  # again: load changes
    print(
        f"input {vid.name}: 2048x1024 H.264, {args.frames} frames; grid {grid.n_windows} windows "
        f"of {grid.size[0]}x{grid.size[1]} px; flow {args.flow}, {args.threads} threads; "
        f"reduction stride {reduce_stride(make_backend(args.flow))}"
    )
    print(
        f"load average {load0:.1f} before, {os.getloadavg()[0]:.1f} after "
        f"({os.cpu_count()} CPUs; other processes share them)"
    )
    print(
        f"floor (DIS alone on the window pairs): {floor:.2f} frames/s (again after: {floor2:.2f})"
    )
    fl = (floor + floor2) / 2
    print(
        f"steady: {steady:.2f} frames/s = {1000 / steady:.0f} ms/frame; "
        f"ratio to floor {steady / fl:.2f} (goal >= {GOAL_STEADY})"
    )
    print(
        f"whole process ({args.frames} frames, launch to exit): {whole_s:.1f} s = "
        f"{whole:.2f} frames/s; ratio to floor {whole / fl:.2f} (goal >= {GOAL_WHOLE})"
    )
    fc = (floor_cpu + floor_cpu2) / 2
    print(
        f"CPU per frame: floor {fc * 1000:.0f} ms, preprocess {child['cpu'] * 1000:.0f} ms; "
        f"ratio {fc / child['cpu']:.2f} (the steady ratio on 2 otherwise idle cores if both "
        "stay busy; independent of the load)"
    )
    print(
        f"start-up, launch to first grid row: {child['first']:.2f} s "
        f"(goal <= {GOAL_START_S:g} s; no map cache: maps are built every run)"
    )

    # Per-stage profile, one thread, mean over the frames.
    be = make_backend(args.flow)
    red = WindowFlowReducer(grid.size, grid.hfov_deg, grid.vfov_deg, stride=reduce_stride(be))
    n = min(args.frames, 10)
    clock = time.process_time
    t = clock()
    frames = [np.array(f) for f in iter_frames(vid, fmt="gray", end=n)]
    t_dec = (clock() - t) / n
    t = clock()
    wins = [ex(f, interp="linear").reshape(grid.n_windows, *grid.size[::-1]) for f in frames]
    t_ext = (clock() - t) / n
    t_flow = t_red = 0.0
    for i in range(1, n):
        t = clock()
        fl = be(wins[i - 1], wins[i])
        t_flow += clock() - t
        t = clock()
        red(fl, 30.0)
        t_red += clock() - t
    t_flow /= n - 1
    t_red /= n - 1
    print("stage profile (CPU ms/frame, all threads; one caller thread):")
    for name, v in (
        ("decode (Y plane)", t_dec),
        ("extract (bilinear)", t_ext),
        ("flow", t_flow),
        ("reduce (deg/s, px)", t_red),
    ):
        print(f"  {name:<22}{v * 1000:8.1f}")
    print(f"  {'sum':<22}{(t_dec + t_ext + t_flow + t_red) * 1000:8.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
