"""Speed of the geometry core beside ffmpeg's v360, same machine, same run.

Usage: .venv/bin/python bench/geometry_speed.py

Figures (ms per frame, best of N after a warm-up; sampling maps cached as in real use):
  - one 256x256 view, 107 deg, from a 2048x1024 RGB frame   (anchor: v360 1.9 ms)
  - one 1440x1600 view, 107 deg, from a 2048x1024 RGB frame (anchor: v360 29.8 ms)
  - the full 264-window grid (default preset) at 256x256 gray (goal <= 150 ms)
v360 is timed here too: ffmpeg runs N copies of the frame from a raw file with and
without the v360 filter; (difference) / N excludes process start-up and file reading.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]

from simulator.media import video
from simulator.sphere import geometry
from simulator.sphere.windows import WindowExtractor, grid_preset
from simulator.testing.reference import v360_time_ms

PETRA = REPO.parent / "shared" / "data" / "real" / "equirect" / "vrview" / "petra.jpg"
ANCHOR_V360_MS = {(256, 256): 1.9, (1440, 1600): 29.8}
GOAL_GRID_MS = 150.0


def best_ms(fn, n: int) -> float:
    fn()
    best = float("inf")
    for _ in range(n):
        t = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t)
    return best * 1e3


def main() -> int:
    rgb = video.read_frame(PETRA)  # 2048x1024
    gray = np.ascontiguousarray(rgb[..., 1])
    H, W = rgb.shape[:2]
    print(f"frame {W}x{H}; views 107 deg FOV, yaw 30 pitch 10")
    for size in ((256, 256), (1440, 1600)):
        mx, my = geometry.perspective_map((W, H), size, 30, 10, 0, 107, 107)
        n = 20 if size[0] < 1000 else 5
        t_cubic = best_ms(lambda mx=mx, my=my: geometry.sample_equirect(rgb, mx, my), n)
        t_lag = best_ms(
            lambda mx=mx, my=my: geometry.sample_equirect(rgb, mx, my, interp="lagrange"),
            max(3, n // 4),
        )
        t_full = best_ms(
            lambda size=size: geometry.extract_view(rgb, 30, 10, 0, hfov_deg=107, size=size),
            max(3, n // 4),
        )
        t_v360 = v360_time_ms(rgb, size=size, hfov_deg=107, n=40 if size[0] < 1000 else 10)
        anchor = ANCHOR_V360_MS[size]
        print(f"view {size[0]}x{size[1]} RGB:")
        print(
            f"  v360 here            {t_v360:7.1f} ms  (anchor {anchor} ms, ratio {t_v360 / anchor:.2f})"
        )
        for label, t in (("ours cubic, cached map", t_cubic), ("ours lagrange, cached map", t_lag),
                         ("ours cubic incl. map", t_full)):  # fmt: skip
            print(
                f"  {label:25s}{t:7.1f} ms  (ratio to v360 anchor {t / anchor:.2f}, to v360 here {t / t_v360:.2f})"
            )
    grid = grid_preset("default", size=(256, 256))
    t = time.perf_counter()
    ex = WindowExtractor(grid, (W, H))
    t_build = (time.perf_counter() - t) * 1e3
    t_grid = best_ms(lambda: ex(gray), 10)
    print(f"grid {grid.n_windows} windows 256x256 gray, cubic: {t_grid:.1f} ms per frame "
          f"(goal <= {GOAL_GRID_MS:g} ms, ratio {t_grid / GOAL_GRID_MS:.2f}); maps built once in {t_build:.0f} ms")  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
