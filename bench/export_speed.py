"""Cost of one ``Epof`` call of the exported C# runtime in Mono, with Python's beside it.

Goal: one call at most 50 us in paper mode (264 windows) and 20 us from a sphere-mode field.
Data: the real 360 video three.js ``pano.mp4`` (188 frames, preprocessed in sphere mode once
into bench/_out/export/, with the paper-mode window matrix derived from the same field) and
a real head trace (Corbillon et al. MMSys'18 user 1, its first 7.5 s resampled at 90 Hz,
a headset's frame rate). Poses: that trace in order (in sphere mode the weight cache then
hits whenever the head moved less than 0.5 deg) and uniformly random poses (every call a
cache miss: the worst case). Python: the fastest per-call path of the same computation
(``ViewportOverlaps.epof`` on one frame, ``ViewportQuery.query`` on a prepared field),
timed in the same run; the ratio Mono / Python is printed beside each figure. Also prints
the export's size against the grid file's (float16: at most the npz).

    .venv/bin/python bench/export_speed.py [--calls 60000]
"""

from __future__ import annotations

import argparse
import os
import shutil
import struct
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from simulator.epof import ViewportQuery, viewport_overlaps
from simulator.export import export_unity
from simulator.media.gridfile import load_grid, require_field
from simulator.preprocess import preprocess_sphere
from simulator.sphere.cells import Frustum
from simulator.sphere.windows import grid_preset
from simulator.traces.readers import load_headpath

REPO = Path(__file__).resolve().parents[1]
REAL = REPO.parent / "shared" / "data" / "real"
VIDEO = REAL / "equirect" / "threejs" / "pano.mp4"
TRACE = REAL / "headtraces" / "corbillon_mmsys18_multiviewpoint" / "user1_quaternion.txt"
OUT = REPO / "bench" / "_out" / "export"
CS = REPO / "simulator" / "export" / "unity" / "VimsimEpof.cs"
HARNESS = REPO / "tests" / "cs" / "EpofHarness.cs"
GOAL_US = {"paper": 50.0, "sphere": 20.0}


def grid_file() -> Path:
    """The sphere-mode grid of pano.mp4 (made once; ~15 s)."""
    OUT.mkdir(parents=True, exist_ok=True)
    g = OUT / "pano_sphere.npz"
    if not g.exists():
        preprocess_sphere(VIDEO, g, grid=grid_preset("default"), progress=False)
    return g


def head_queries(fps: float, duration_s: float, path: Path) -> tuple:
    """The real trace at 90 Hz over the video: (t, yaw, pitch, roll) written for the harness."""
    hp = load_headpath(TRACE)
    t = np.arange(0.0, min(duration_s, hp.end_s - hp.start_s), 1 / 90.0)
    y, p, r = hp.sample_angles_deg(t + hp.start_s)
    rec = np.zeros(len(t), dtype=[("t", "<f8"), ("y", "<f4"), ("p", "<f4"), ("r", "<f4")])
    rec["t"], rec["y"], rec["p"], rec["r"] = t, y, p, r
    path.write_bytes(struct.pack("<i", len(t)) + rec.tobytes())
    return t, y.astype(np.float32), p.astype(np.float32), r.astype(np.float32)


def random_poses(n: int, seed: int, duration_s: float):
    """The harness's random poses (same ranges): yaw uniform, pitch uniform on the sphere,
    roll within +-30 deg, times uniform over the video."""
    rng = np.random.default_rng(seed)
    t = rng.uniform(0, duration_s, n)
    y = rng.uniform(-180, 180, n)
    p = np.degrees(np.arcsin(rng.uniform(-1, 1, n)))
    r = rng.uniform(-30, 30, n)
    return t, y, p, r


def mono_bench(exe: Path, export_dir: Path, calls: int, queries: Path) -> dict:
    r = subprocess.run(
        ["mono", str(exe), "bench", str(export_dir), str(calls), "1", str(queries)],
        capture_output=True,
        text=True,
        check=True,
    )
    out = {}
    for line in r.stdout.splitlines():
        k, _, v = line.partition(" ")
        out[k] = v
    return out


def _timed(fn, n: int) -> tuple[float, float]:
    """(wall us, CPU us) per call of ``fn(i)`` for i < n."""
    w0, c0 = time.perf_counter(), time.process_time()
    for i in range(n):
        fn(i)
    return (time.perf_counter() - w0) / n * 1e6, (time.process_time() - c0) / n * 1e6


def _frames(grid, t) -> np.ndarray:
    return np.minimum((np.asarray(t) * grid.fps + 1e-6).astype(int), grid.n_frames - 1)


def python_paper(grid, queries, n: int) -> tuple[float, float]:
    """us per call: ViewportOverlaps.epof on one frame (the scalar fast path)."""
    vo = viewport_overlaps(grid.grid, grid.hfov_deg, grid.vfov_deg)
    pof = grid.pof_dps
    t, y, p, r = queries
    f = _frames(grid, t)
    vo.epof(pof[f[0]], float(y[0]), float(p[0]), float(r[0]))  # warm

    def one(i):
        return vo.epof(pof[f[i]], float(y[i]), float(p[i]), float(r[i]))

    return _timed(one, min(n, len(t)))


def python_sphere(grid, queries, n: int) -> tuple[float, float]:
    """us per call: ViewportQuery.query on a prepared (doubled) field, fresh weight cache."""
    field, cells = require_field(grid)
    q = ViewportQuery(cells.cell_deg, Frustum.symmetric(grid.hfov_deg, grid.vfov_deg))
    d = ViewportQuery.doubled(field)
    t, y, p, r = queries
    f = _frames(grid, t)

    def one(i):
        return q.query(d[f[i]], float(y[i]), float(p[i]), float(r[i]))

    return _timed(one, min(n, len(t)))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--calls", type=int, default=60000, help="random-pose calls in Mono (CPU time ticks 10 ms)"
    )
    ap.add_argument("--python-calls", type=int, default=2000)
    args = ap.parse_args()
    if shutil.which("mcs") is None or shutil.which("mono") is None:
        print(
            "mcs/mono not found: run `make sysdeps` (Debian mono-mcs mono-runtime)", file=sys.stderr
        )
        return 1
    exe = OUT / "harness.exe"
    gpath = grid_file()
    subprocess.run(["mcs", "-optimize+", f"-out:{exe}", str(CS), str(HARNESS)], check=True)
    grid = load_grid(gpath)
    dur = grid.n_frames / grid.fps
    qpath = OUT / "trace_queries.bin"
    trace = head_queries(grid.fps, dur, qpath)
    rand = random_poses(args.python_calls, 1, dur)
    print(
        f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores (others share this machine)"
    )
    print(
        f"grid {gpath.name}: {grid.n_frames} frames at {grid.fps:g} fps; trace: {len(trace[0])} poses at 90 Hz"
    )
    print(
        "per call, microseconds: wall clock and this process's CPU time (CPU is the cost; wall "
        "includes waiting for the shared cores)"
    )
    print(f"{'mode':7s} {'poses':7s} {'Mono wall':>10s} {'Mono CPU':>9s} {'Python wall':>12s} "
          f"{'Python CPU':>11s} {'Mono/Python (CPU)':>18s}  goal (CPU)")  # fmt: skip
    ok = True
    for mode in ("paper", "sphere"):
        xdir = OUT / f"x_{mode}"
        res = export_unity(grid, xdir, method=mode, dtype="float16")
        m = mono_bench(exe, xdir, args.calls, qpath)
        fn = python_paper if mode == "paper" else python_sphere
        py = {
            "random": fn(grid, rand, args.python_calls),
            "trace": fn(grid, trace, args.python_calls),
        }
        mono = {
            "random": (float(m["random_us"]), float(m["random_cpu_us"])),
            "trace": (float(m["path_us"]), float(m["path_cpu_us"])),
        }
        if mode == "sphere":
            print(
                f"        (sphere: {float(m['cached_cpu_us']):.2f} us CPU when the pose's weight bin "
                f"is cached, {float(m['random_cpu_us']):.2f} when it is not)"
            )
        for kind in ("random", "trace"):
            (mw, mc), (pw, pc) = mono[kind], py[kind]
            good = mc <= GOAL_US[mode]
            ok &= good
            print(
                f"{mode:7s} {kind:7s} {mw:10.2f} {mc:9.2f} {pw:12.2f} {pc:11.2f} {mc / pc:18.3f}  "
                f"<= {GOAL_US[mode]:g} us: {'yes' if good else 'NO'}"
            )
        extra = f"; trace: {m['path_bins']} weight bins computed" if mode == "sphere" else ""
        print(
            f"        load {float(m['load_ms']):.0f} ms{extra}; float16 export "
            f"{res.file_bytes / 1024:.0f} KiB = {res.file_bytes / res.grid_bytes:.3f} x the grid "
            f"file ({res.grid_bytes / 1024:.0f} KiB): "
            f"{'ok' if res.file_bytes <= res.grid_bytes else 'TOO BIG'}"
        )
        ok &= res.file_bytes <= res.grid_bytes
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
