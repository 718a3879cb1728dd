"""Cost of ``vimsim frames`` for 10 moments beside a full ``vimsim render`` of the same video.

Usage: .venv/bin/python bench/frames_speed.py [--seconds 40] [--eye 480] [--moments 10]

Same run, same H.264 video (petra.jpg panning, 1024x512, 30 fps, x264 default key frames),
same head path and settings (GRF on at opacity 0.8, mono), wall clock, set-up included:

* full: :func:`simulator.viewing.job.render_viewing` (what ``vimsim render`` runs: every
  frame decoded, rendered and encoded, x264 veryfast);
* frames: :func:`simulator.viewing.frames.render_frames` at ``--moments`` times spread over the
  video (seek-decoded, rendered, PNG).

Prints both in seconds and the ratio frames / full; the goal: at most 0.10.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from simulator.media import video
from simulator.mitigation.grf import GrfConfig
from simulator.render import RenderConfig, create_context
from simulator.viewing.frames import render_frames
from simulator.viewing.job import render_viewing

REAL = REPO.parent / "shared" / "data" / "real" / "equirect"
GOAL = 0.10


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=40.0)
    ap.add_argument("--eye", type=int, default=480)
    ap.add_argument("--moments", type=int, default=10)
    a = ap.parse_args()
    fps = 30
    n = int(a.seconds * fps)
    import cv2

    img = cv2.resize(video.read_frame(REAL / "vrview/petra.jpg"), (1024, 512))
    ctx = create_context()
    cfg = RenderConfig(eye_size=(a.eye, a.eye), grf=GrfConfig())
    with tempfile.TemporaryDirectory() as d:
        d = Path(d)
        vid = d / "clip.mp4"
        with video.VideoWriter(vid, fps, (1024, 512), preset="ultrafast", crf=20) as w:
            for i in range(n):
                w.write(np.roll(img, 2 * i, axis=1))
        path = d / "path.csv"
        half = a.seconds / 2
        path.write_text(
            f"time_s,yaw_deg,pitch_deg,roll_deg\n0,-60,0,0\n{half},0,5,0\n{a.seconds},60,10,0\n"
        )
        times = list(np.linspace(0.5, a.seconds - 0.5, a.moments).round(3))
        # Full render first: the frames run then finds the same warm shader cache.
        t0 = time.perf_counter()
        render_viewing(vid, path, d / "full", config=cfg, opacity=0.8, ctx=ctx)
        t_full = time.perf_counter() - t0
        t_frames = []
        for k in range(2):
            t0 = time.perf_counter()
            render_frames(vid, path, d / f"frames{k}", at=times, config=cfg, opacity=0.8, ctx=ctx)
            t_frames.append(time.perf_counter() - t0)
        print("frames runs (s):", [round(t, 2) for t in t_frames])
        t_frames = max(t_frames)  # the slower of two runs
    ratio = t_frames / t_full
    print(
        f"frames ({a.moments} moments of a {a.seconds:g} s {fps} fps 1024x512 video, "
        f"{a.eye}x{a.eye} eye): {t_frames:.2f} s; full render of it: {t_full:.2f} s; "
        f"ratio {ratio:.3f} (goal <= {GOAL:.2f}): {'OK' if ratio <= GOAL else 'MISSED'}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
