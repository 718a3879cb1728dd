"""Testing: pytest helpers for visual regression (goldens), frame-folder comparison, and references nobody here wrote (ffmpeg v360, brute-force overlaps).
"""

from simulator.testing.goldens import (
    UPDATE_ENV,
    assert_frames_match,
    render_frames,
)

__all__ = [
    "UPDATE_ENV",
    "assert_frames_match",
    "render_frames",
]
