"""Synthetic media for the tests: the one writer of test clips and the frame patterns they use.

Every clip is encoded by the package's own :class:`simulator.media.video.VideoWriter`
(H.264, yuv420p), so a test's video is what ``vimsim`` itself would write. Frames are
``(h, w, 3)`` uint8 RGB, top row first; sizes are ``(width, height)``.
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

import numpy as np

__all__ = ["gray_frames", "noise_frames", "write_clip"]


def write_clip(path, frames: Iterable[np.ndarray], fps: float = 10.0, *, preset: str = "ultrafast",
               crf: int = 18, **writer) -> Path:  # fmt: skip
    """Encode ``frames`` (at least one) into ``path`` at ``fps``; ``preset``, ``crf`` and
    ``writer`` go to :class:`simulator.media.video.VideoWriter` (``crf=0``: lossless luma,
    for tests that read pixel values back)."""
    from simulator.media.video import VideoWriter

    it = iter(frames)
    first = np.asarray(next(it))
    h, w = first.shape[:2]
    with VideoWriter(path, fps, (w, h), preset=preset, crf=crf, **writer) as wr:
        wr.write(first)
        for f in it:
            wr.write(f)
    return Path(path)


def noise_frames(n: int, size=(128, 64), seed: int = 0):
    """``n`` frames of uniform noise (seeded: the same frames every run)."""
    rng = np.random.default_rng(seed)
    for _ in range(n):
        yield rng.integers(0, 256, (size[1], size[0], 3), dtype=np.uint8)


def gray_frames(levels: Iterable[int], size=(128, 64)):
    """One uniform gray frame per level (0..255): a frame's brightness can name it."""
    for v in levels:
        yield np.full((size[1], size[0], 3), v, np.uint8)
