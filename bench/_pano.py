"""The real hand-held clip of the render and opacity benches (three.js ``pano.mp4``) and
its default grid, made once with ``vimsim preprocess`` and cached in ``outputs/bench15/``."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
REAL = REPO.parent / "shared" / "data" / "real"
VIDEO = REAL / "equirect" / "threejs" / "pano.mp4"
TRACES = REAL / "headtraces" / "avtrack360" / "Head_rotation"
CACHE = REPO / "outputs" / "bench15"


def pano_grid() -> Path:
    """``CACHE/pano.npz``: ``vimsim preprocess`` of :data:`VIDEO` with the default options
    (made here the first time, ~3 min)."""
    CACHE.mkdir(parents=True, exist_ok=True)
    gp = CACHE / "pano.npz"
    if not gp.exists():
        cmd = [sys.executable, "-m", "simulator", "preprocess", str(VIDEO), "-o", str(gp),
               "--method", "paper"]  # fmt: skip
        subprocess.run(cmd, check=True)
    return gp


#: The real head-trace file of the 48-user benches (360VidStr, users 1-48).
USERS48 = REAL / "headtraces" / "aggregated_360vidstr" / "AggregatedDataset" / "33.txt"


def loop_study(out: Path) -> Path:
    """``out/study.toml``: the 48 users of :data:`USERS48` watching :data:`VIDEO` looped to
    4120 frames (``out/pano_loop.mp4``, made the first time). The loop is re-encoded with
    fresh timestamps: a stream copy repeats a timestamp at each seam (the real clip hides one
    frame behind its edit list), which vimsim refuses."""
    import imageio_ffmpeg

    out.mkdir(parents=True, exist_ok=True)
    video = out / "pano_loop.mp4"
    if not video.is_file():
        subprocess.run([imageio_ffmpeg.get_ffmpeg_exe(), "-y", "-v", "error", "-stream_loop", "22",
                        "-i", str(VIDEO), "-frames:v", "4120", "-vf", "setpts=N/FRAME_RATE/TB",
                        "-c:v", "libx264", "-preset", "ultrafast", "-crf", "18", str(video)],
                       check=True)  # fmt: skip
    manifest = out / "study.toml"
    manifest.write_text(f"""[[videos]]
id = "sandwich-loop"
path = "{video}"
method = "sphere"

[[viewings]]
video = "sandwich-loop"
trace = "{USERS48}"
user = "all"
""")
    return manifest
