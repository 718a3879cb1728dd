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
