"""8K sources: sphere-mode preprocess throughput against decoding alone, and peak memory against length.

Usage: .venv/bin/python bench/source_8k.py [--frames 300,3000] [--size 7680x3840]
    [--preset ultrafast] [--bitrate 120M] [--repeat 2] [--render 60,300]

Encodes up to 60 frames of an H.264 clip once (ffmpeg ``testsrc2`` panned, x264 at
``--preset``: ``ultrafast`` has no CABAC and no deblocking, the cheapest 8K decode there
is; a camera's or YouTube's stream decodes slower: ``--preset fast --bitrate 120M`` is
like an 8K 360 camera's H.264, CABAC, deblocking, B-frames, 120 Mbit/s) and loops it by stream copy to each
frame count N. In the same run:

- throughput: ``vimsim preprocess --method sphere`` frames/s over decoding alone (the same
  frames, the Y plane as sphere mode decodes it, FFmpeg's own thread choice: the fastest
  here), at the smallest and the largest N (a short clip's ratio includes the fixed setup:
  tile maps, window matrices) -- goal >= 0.8. At the smallest N, decoding and preprocess
  alternate ``--repeat`` times and the best of each counts (the machine is shared). Also
  the ratio of CPU time per frame (all threads): what the throughput ratio is when every
  core is busy (a loaded machine, or decoding alone already using all cores);
- memory: the peak RSS of a fresh process preprocessing N frames, for each N, and their
  ratio (largest / smallest; goal <= 1.2x), with the absolute peak; with ``--render``, the
  same for ``vimsim render`` (256x256 mono eye, GRF at 0.5, a static head) of clips of
  those lengths.

The machine is shared: ``--frames 60,240`` keeps the run to a few minutes (the figures
quoted in docs/sources.md say which counts were run).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from simulator.cli import BLAS_THREADS
from simulator.testing.reference import ffmpeg_exe

CHILD = r"""
import json, os, resource, sys, time
from simulator.media.source import Source
from simulator.preprocess import SphereConfig, preprocess_sphere
from simulator.sphere.windows import grid_preset
mode, path, out = sys.argv[1:4]
t0 = time.perf_counter()
src = Source.open(path)
if mode == "decode":
    n = sum(1 for _ in src.frames(fmt="gray"))
elif mode == "render":  # a static head, GRF at 0.5, 256x256 mono eye (memory: the frames in flight)
    from simulator.cli import main
    from simulator.traces.path import HeadPath, save_headpath_csv
    T = src.info.duration_s + 1.0
    save_headpath_csv(out + ".csv", HeadPath.from_angles_deg([0.0, T], [0.0, 0.0], [0.0, 0.0], [0.0, 0.0]))
    if main(["render", path, out + ".csv", "-o", out, "--opacity", "0.5", "--eye-size", "256x256",
             "--no-progress", "--quiet"]) != 0:
        sys.exit("render failed")
    n = src.info.n_frames
else:
    preprocess_sphere(src, out, grid=grid_preset("default"), config=SphereConfig(), progress=False)
    n = src.info.n_frames
dt = time.perf_counter() - t0
ru = resource.getrusage(resource.RUSAGE_SELF)
print(json.dumps({"n": n, "s": dt, "cpu": ru.ru_utime + ru.ru_stime, "rss_mb": ru.ru_maxrss / 1024,
                  "load": os.getloadavg()[0]}))
"""


def child(mode: str, path: Path, out: Path) -> dict:
    # OpenBLAS threads as the vimsim command sets them (simulator.cli), unless given
    env = {**os.environ}
    env.setdefault("OPENBLAS_NUM_THREADS", BLAS_THREADS)
    r = subprocess.run([sys.executable, "-c", CHILD, mode, str(path), str(out)],
                       capture_output=True, text=True, check=True, env=env)  # fmt: skip
    return json.loads(r.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--frames", default="300,3000")
    ap.add_argument("--size", default="7680x3840")
    ap.add_argument("--preset", default="ultrafast", help="x264 preset of the test clip")
    ap.add_argument("--bitrate", default=None,
                    help="x264 average bitrate of the test clip (e.g. 120M, an 8K 360 camera's "
                    "H.264; default: crf 28)")  # fmt: skip
    ap.add_argument("--repeat", type=int, default=2, help="alternations at the smallest N")
    ap.add_argument("--render", default="",
                    help="also render (256x256 mono eye, GRF) clips of these frame counts, e.g. "
                    "60,300: peak RSS against length")  # fmt: skip
    a = ap.parse_args()
    d = Path(tempfile.mkdtemp(prefix="vimsim-8k-"))
    try:
        run(a, d)
    finally:
        shutil.rmtree(d, ignore_errors=True)  # the clips (GBs at 3000 frames)


def run(a, d: Path) -> None:
    counts = sorted(int(v) for v in a.frames.split(","))
    clips = {}
    t0 = time.perf_counter()
    base = d / "base.mp4"  # encoded once (8K encoding is slow), then looped by stream copy
    nb = min(counts[0], 60)
    src = f"testsrc2=size={a.size}:rate=30,scroll=horizontal=0.002"
    rate = ["-crf", "28"] if a.bitrate is None else ["-b:v", a.bitrate, "-maxrate", a.bitrate,
                                                     "-bufsize", a.bitrate]  # fmt: skip
    subprocess.run([ffmpeg_exe(), "-v", "error", "-y", "-f", "lavfi", "-i", src, "-frames:v",
                    str(nb), "-c:v", "libx264", "-preset", a.preset, *rate, "-g", str(nb),
                    str(base)], check=True)  # fmt: skip
    for n in counts:
        clips[n] = d / f"c{n}.mp4"
        subprocess.run([ffmpeg_exe(), "-v", "error", "-y", "-stream_loop", str(-(-n // nb)), "-i",
                        str(base), "-frames:v", str(n), "-c", "copy", str(clips[n])],
                       check=True)  # fmt: skip
    print(f"made {len(counts)} clips of {a.size}, x264 {a.preset} {' '.join(rate)} ({', '.join(map(str, counts))} frames) "
          f"in {time.perf_counter() - t0:.0f} s")  # fmt: skip
    n0 = counts[0]
    runs = [(child("decode", clips[n0], d / "x.npz"), child("preprocess", clips[n0], d / "g.npz"))
            for _ in range(max(1, a.repeat))]  # fmt: skip
    decs = {n0: min((r[0] for r in runs), key=lambda r: r["s"])}
    pre = {n0: min((r[1] for r in runs), key=lambda r: r["s"])}
    for n in counts[1:]:
        decs[n] = child("decode", clips[n], d / "x.npz") if n == counts[-1] else None
        pre[n] = child("preprocess", clips[n], d / f"g{n}.npz")
    dec = decs[n0]
    for n, dn in decs.items():  # per count: a short clip's ratio includes the fixed setup
        if dn is None:
            continue
        fps_dec, fps_pre = dn["n"] / dn["s"], pre[n]["n"] / pre[n]["s"]
        cpu_dec, cpu_pre = 1e3 * dn["cpu"] / dn["n"], 1e3 * pre[n]["cpu"] / pre[n]["n"]
        print(f"{n} frames: decode alone {fps_dec:.2f} frames/s, sphere preprocess "
              f"{fps_pre:.2f} frames/s: ratio {fps_pre / fps_dec:.2f} (goal >= 0.8); CPU per "
              f"frame {cpu_dec:.1f} / {cpu_pre:.1f} ms: ratio {cpu_dec / cpu_pre:.2f}; load "
              f"{dn['load']:.1f} / {pre[n]['load']:.1f}")  # fmt: skip
    for n in counts:
        print(
            f"{n} frames: peak RSS {pre[n]['rss_mb']:.0f} MB ({pre[n]['n'] / pre[n]['s']:.2f} frames/s)"
        )
    r = pre[counts[-1]]["rss_mb"] / pre[n0]["rss_mb"]
    print(f"peak RSS {counts[-1]} / {n0} frames: {r:.3f}x (goal <= 1.2x); decode alone peak "
          f"{dec['rss_mb']:.0f} MB")  # fmt: skip
    rcounts = sorted(int(v) for v in a.render.split(",") if v)
    if rcounts:
        got = {}
        for n in rcounts:
            c = d / f"r{n}.mp4"
            subprocess.run([ffmpeg_exe(), "-v", "error", "-y", "-stream_loop", str(-(-n // nb)),
                            "-i", str(base), "-frames:v", str(n), "-c", "copy", str(c)],
                           check=True)  # fmt: skip
            got[n] = child("render", c, d / f"render{n}")
            print(f"render, {n} frames: peak RSS {got[n]['rss_mb']:.0f} MB "
                  f"({got[n]['n'] / got[n]['s']:.2f} frames/s)")  # fmt: skip
        r = got[rcounts[-1]]["rss_mb"] / got[rcounts[0]]["rss_mb"]
        print(f"render peak RSS {rcounts[-1]} / {rcounts[0]} frames: {r:.3f}x (goal <= 1.2x)")


if __name__ == "__main__":
    main()
