"""Grain layouts of a GRF, one table entry each: ``random`` (uniform, seeded; the paper's) and ``fibonacci`` (the authors' Unity layout).

A layout turns a :class:`simulator.mitigation.grf.GrfConfig` into unit grain centres in the
world frame (+x right, +y up, +z forward; lon = atan2(x, z), lat = asin(y)):

- ``random``: :func:`simulator.mitigation.grf.grain_count` grains placed uniformly on the
  sphere with ``config.seed``; their union blocks ``config.density`` of it on average.
- ``fibonacci``: the authors' system (docs/parity.md): a Fibonacci sphere of
  ``n = round(180 * 360 / grain_deg^2)`` points, a random half kept (seeded here: their
  Unity random draw cannot be reproduced). ``density`` is not used: the blocked fraction
  follows from the grain size (about 55.7 % for 0.5 deg grains).

A new layout is one function and one entry in :data:`LAYOUTS`.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

__all__ = ["GRAIN_LAYOUTS", "LAYOUTS", "fibonacci_count", "fibonacci_sphere", "layout_centers"]


def fibonacci_sphere(n: int) -> NDArray[np.float64]:
    """``n`` unit vectors on a Fibonacci sphere, world frame (+x right, +y up, +z forward),
    shape (n, 3): ``y = 1 - 2 (i + 0.5) / n`` and longitude ``i`` times the golden angle."""
    i = np.arange(int(n), dtype=np.float64)
    y = 1.0 - 2.0 * (i + 0.5) / n
    r = np.sqrt(np.maximum(0.0, 1.0 - y * y))
    lon = i * math.pi * (3.0 - math.sqrt(5.0))
    return np.stack([r * np.sin(lon), y, r * np.cos(lon)], axis=-1)


def fibonacci_count(grain_deg: float) -> tuple[int, int]:
    """``(points, grains)`` of the Fibonacci layout: ``round(180 * 360 / grain_deg^2)``
    points on the sphere, half of them (rounded down) kept as grains."""
    n = round(180.0 * 360.0 / (float(grain_deg) ** 2))
    return n, n // 2


def _random(config, n: int) -> NDArray[np.float64]:
    rng = np.random.default_rng(config.seed)
    z = rng.uniform(-1.0, 1.0, n)
    lon = rng.uniform(-math.pi, math.pi, n)
    s = np.sqrt(1.0 - z * z)
    # z uniform in [-1, 1] is uniform on the sphere; the axis it runs along is world +y.
    return np.stack([s * np.sin(lon), z, s * np.cos(lon)], axis=-1)


def _fibonacci(config, n: int) -> NDArray[np.float64]:
    pts, kept = fibonacci_count(config.grain_deg)
    keep = np.sort(np.random.default_rng(config.seed).choice(pts, kept, replace=False))
    return np.ascontiguousarray(fibonacci_sphere(pts)[keep])


#: layout name -> ``(centres of (config, grain count), grain count of config or None)``;
#: None: :func:`simulator.mitigation.grf.grain_count` (the density's count).
LAYOUTS: dict[str, tuple[Callable, Callable | None]] = {
    "random": (_random, None),
    "fibonacci": (_fibonacci, lambda config: fibonacci_count(config.grain_deg)[1]),
}
GRAIN_LAYOUTS: tuple[str, ...] = tuple(LAYOUTS)


def layout_centers(config, n: int) -> NDArray[np.float64]:
    """The ``n`` grain centres of ``config.layout``, shape (n, 3), float64, read-only."""
    centers = LAYOUTS[config.layout][0](config, n)
    centers.setflags(write=False)
    return centers
