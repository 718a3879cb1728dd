"""The PSNR between frames rendered twice on this machine, and what real changes cost: the basis of compare's default thresholds.

Usage: .venv/bin/python bench/frames_tolerance.py [--eye 480]

Real video: three.js ``MaryOculus.mp4`` (1920x1024, 24 fps, 5 s). ``vimsim frames`` at 5
moments (GRF on, opacity 0.8), run in two separate processes (fresh EGL contexts), then:

* run 1 against run 2 (the same inputs): PSNR, mean abs diff, SSIM;
* the changes compare must catch, against run 1: 1 deg more yaw, grain size 1.5 -> 2.0
  deg, the video's red channel + 4 and + 8 levels (re-encoded losslessly, x264rgb crf 0).

Prints, per case, the lowest PSNR, the largest mean absolute difference (8-bit levels)
and the lowest SSIM over the frames, each beside the default thresholds
(:data:`simulator.testing.compare.DEFAULT_PSNR_DB`, :data:`~simulator.testing.compare.DEFAULT_MAX_DIFF`).
The reference is the unchanged run: the ratio printed is each case's lowest PSNR over
the default threshold (pass >= 1).
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from fractions import Fraction
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from simulator.media.video import iter_frames, probe
from simulator.testing.compare import DEFAULT_MAX_DIFF, DEFAULT_PSNR_DB, compare_dirs

VIDEO = REPO.parent / "shared" / "data" / "real" / "equirect" / "threejs" / "MaryOculus.mp4"
AT = "0.5,1.5,2.5,3.5,4.5"


def frames(out: Path, video: Path, path: Path, eye: int, *extra: str) -> None:
    cmd = [sys.executable, "-m", "simulator", "frames", str(video), str(path), "-o", str(out)]
    cmd += ["--at", AT, "--eye-size", f"{eye}x{eye}", "--opacity", "0.8", "--no-progress", *extra]
    subprocess.run(cmd, check=True, capture_output=True)


def shifted_video(dst: Path, shift: int) -> None:
    """MaryOculus with red + ``shift`` levels, x264 lossless RGB (libx264rgb crf 0)."""
    import av

    info = probe(VIDEO)
    with av.open(str(dst), "w") as c:
        s = c.add_stream("libx264rgb", rate=24)
        s.width, s.height, s.pix_fmt = info.width, info.height, "rgb24"
        s.options = {"crf": "0", "preset": "ultrafast"}
        s.sample_aspect_ratio = Fraction(info.sar).limit_denominator(100)
        for f in iter_frames(VIDEO):
            g = f.astype(np.int16)
            g[..., 0] += shift
            vf = av.VideoFrame.from_ndarray(np.clip(g, 0, 255).astype(np.uint8), format="rgb24")
            for p in s.encode(vf):
                c.mux(p)
        for p in s.encode():
            c.mux(p)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--eye", type=int, default=480)
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as d:
        d = Path(d)
        path = d / "path.csv"
        path.write_text("time_s,yaw_deg,pitch_deg,roll_deg\n0,-30,0,0\n5,30,10,0\n")
        path1 = d / "path1.csv"
        path1.write_text("time_s,yaw_deg,pitch_deg,roll_deg\n0,-29,0,0\n5,31,10,0\n")
        ref = d / "run1"
        frames(ref, VIDEO, path, a.eye)
        frames(d / "run2", VIDEO, path, a.eye)
        frames(d / "yaw", VIDEO, path1, a.eye)
        frames(d / "grain", VIDEO, path, a.eye, "--grain-size", "2.0")
        for shift in (4, 8):
            shifted_video(d / f"red{shift}.mp4", shift)
            frames(d / f"red+{shift}", d / f"red{shift}.mp4", path, a.eye)
        print(f"thresholds: PSNR >= {DEFAULT_PSNR_DB} dB, mean abs diff <= {DEFAULT_MAX_DIFF}")
        for case in ("run2", "yaw", "grain", "red+4", "red+8"):
            rep = compare_dirs(d / case, ref, report_dir=d / f"rep-{case}")
            p = min(s.psnr_db for s in rep.scores)
            m = max(s.mean_abs_diff for s in rep.scores)
            q = min(s.ssim for s in rep.scores)
            print(
                f"{case:7s} vs run1: lowest PSNR {p:.2f} dB (ratio to threshold {p / DEFAULT_PSNR_DB:.3f}), "
                f"max mean abs diff {m:.3f}, lowest SSIM {q:.4f}: "
                f"{len(rep.failures)}/{len(rep.scores)} frames fail"
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
