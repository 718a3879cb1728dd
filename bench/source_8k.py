"""8K sources: sphere-mode preprocess throughput against decoding alone, and peak memory against length.

Usage: .venv/bin/python bench/source_8k.py [--frames 300,3000] [--size 7680x3840]

Encodes up to 60 frames of an H.264 clip once (ffmpeg ``testsrc2`` panned, ultrafast) and
loops it by stream copy to each frame count N. In the same run:

- throughput: ``vimsim preprocess --method sphere`` frames/s over decoding alone (the same
  frames, the Y plane as sphere mode decodes it), at the smallest and the largest N (a
  short clip's ratio includes the fixed setup: tile maps, window matrices) -- goal >= 0.8;
- memory: the peak RSS of a fresh process preprocessing N frames, for each N, and their
  ratio (largest / smallest; goal <= 1.2x), with the absolute peak.

The machine is shared: ``--frames 60,240`` keeps the run to a few minutes (the figures
quoted in docs/sources.md say which counts were run).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from simulator.testing.reference import ffmpeg_exe

CHILD = r"""
import json, resource, sys, time
from simulator.media.source import Source
from simulator.preprocess import SphereConfig, preprocess_sphere
from simulator.sphere.windows import grid_preset
mode, path, out = sys.argv[1:4]
t0 = time.perf_counter()
src = Source.open(path)
if mode == "decode":
    n = sum(1 for _ in src.frames(fmt="gray"))
else:
    preprocess_sphere(src, out, grid=grid_preset("default"), config=SphereConfig(), progress=False)
    n = src.info.n_frames
dt = time.perf_counter() - t0
print(json.dumps({"n": n, "s": dt, "rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
"""


def child(mode: str, path: Path, out: Path) -> dict:
    r = subprocess.run([sys.executable, "-c", CHILD, mode, str(path), str(out)],
                       capture_output=True, text=True, check=True)  # fmt: skip
    return json.loads(r.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--frames", default="300,3000")
    ap.add_argument("--size", default="7680x3840")
    a = ap.parse_args()
    counts = sorted(int(v) for v in a.frames.split(","))
    d = Path(tempfile.mkdtemp(prefix="vimsim-8k-"))
    clips = {}
    t0 = time.perf_counter()
    base = d / "base.mp4"  # encoded once (8K encoding is slow), then looped by stream copy
    nb = min(counts[0], 60)
    src = f"testsrc2=size={a.size}:rate=30,scroll=horizontal=0.002"
    subprocess.run([ffmpeg_exe(), "-v", "error", "-y", "-f", "lavfi", "-i", src, "-frames:v",
                    str(nb), "-c:v", "libx264", "-preset", "ultrafast", "-crf", "28", "-g", str(nb),
                    str(base)], check=True)  # fmt: skip
    for n in counts:
        clips[n] = d / f"c{n}.mp4"
        subprocess.run([ffmpeg_exe(), "-v", "error", "-y", "-stream_loop", str(-(-n // nb)), "-i",
                        str(base), "-frames:v", str(n), "-c", "copy", str(clips[n])],
                       check=True)  # fmt: skip
    print(f"made {len(counts)} clips of {a.size} ({', '.join(map(str, counts))} frames) "
          f"in {time.perf_counter() - t0:.0f} s")  # fmt: skip
    n0 = counts[0]
    decs = {n: child("decode", clips[n], d / "x.npz") for n in (n0, counts[-1])}
    pre = {n: child("preprocess", clips[n], d / f"g{n}.npz") for n in counts}
    dec = decs[n0]
    for n, dn in decs.items():  # per count: a short clip's ratio includes the fixed setup
        fps_dec, fps_pre = dn["n"] / dn["s"], pre[n]["n"] / pre[n]["s"]
        print(f"{n} frames: decode alone {fps_dec:.2f} frames/s, sphere preprocess "
              f"{fps_pre:.2f} frames/s: ratio {fps_pre / fps_dec:.2f} (goal >= 0.8)")  # fmt: skip
    for n in counts:
        print(
            f"{n} frames: peak RSS {pre[n]['rss_mb']:.0f} MB ({pre[n]['n'] / pre[n]['s']:.2f} frames/s)"
        )
    r = pre[counts[-1]]["rss_mb"] / pre[n0]["rss_mb"]
    print(f"peak RSS {counts[-1]} / {n0} frames: {r:.3f}x (goal <= 1.2x); decode alone peak "
          f"{dec['rss_mb']:.0f} MB")  # fmt: skip


if __name__ == "__main__":
    main()
