"""Granulated rest frames (GRFs): grain layout, soft cutout and opacity (paper 4.2.2).

A GRF is a field of black discs ("grains") fixed to the user's body, i.e. to the world
frame (+x right, +y up, +z forward; lon = atan2(x, z), lat = asin(y)), so that grains
move neither with the head nor with the video. A head-fixed soft circular cutout keeps
the centre of the view clear::

    cutout(ecc) = clamp((ecc - inner_deg) / (outer_deg - inner_deg), 0, 1)

with ``ecc`` the angle in degrees between a pixel's ray and the view centre (defaults:
transparent within 18 deg = the 36 deg inner FOV, opaque beyond 40 deg = the 80 deg outer
FOV). The final grain alpha is ``cutout(ecc) * opacity`` where ``opacity`` is the
EPOF-driven opacity (0..1) of the frame.

Density is the **blocked fraction** of the visual field. Grains are placed uniformly at
random on the sphere (seeded), and they overlap, so ``n`` grains of solid angle ``a``
block ``1 - (1 - a / 4 pi)^n`` of the sphere on average; :func:`grain_count` inverts that.

For the renderer, :meth:`GrainField.buckets` sorts grains into cells of latitude bands
(cells about ``cell_deg`` wide) so that a fragment shader finds the few grains near a
ray in constant time.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from simulator.core.errors import InputError
from simulator.mitigation.layouts import GRAIN_LAYOUTS, LAYOUTS, layout_centers
from simulator.mitigation.opacity import (  # the rule the grains' opacity follows
    COMFORT_EASE_IN_S,
    COMFORT_EASE_OUT_S,
    RULE_OPTIONS,
    OpacityRule,
    comfort_rule,
    rule_from_options,
)

__all__ = [
    "COMFORT_EASE_IN_S",
    "COMFORT_EASE_OUT_S",
    "RULE_OPTIONS",
    "GrainBuckets",
    "GrainField",
    "GrfConfig",
    "OpacityRule",
    "comfort_rule",
    "cutout_alpha",
    "grain_count",
    "rule_from_options",
]



@dataclass(frozen=True)
class GrfConfig:
    """Parameters of a granulated rest frame (degrees; defaults = the paper's).

    grain_deg : angular diameter of one grain, degrees (1.5)
    density : blocked fraction of the visual field, overlaps counted once, in (0, 1) (0.5)
    inner_deg : cutout radius (from the view centre) inside which grains are fully
        transparent, degrees (18 = half of the 36 deg inner FOV)
    outer_deg : radius beyond which grains are fully opaque, degrees (40 = half of the
        80 deg outer FOV); alpha is linear in eccentricity between the two
    seed : seed of the grain layout (same seed, same grains)
    distance_m : grain distance in metres for stereo parallax; ``None`` = at infinity
        (identical for both eyes)
    ipd_m : interpupillary distance in metres, used only with ``distance_m``
    layout : where the grains lie (:mod:`simulator.mitigation.layouts`): ``random``
        (the paper's) or ``fibonacci`` (the authors' Unity layout; ``density`` unused)
    """

    grain_deg: float = 1.5
    density: float = 0.5
    inner_deg: float = 18.0
    outer_deg: float = 40.0
    seed: int = 0
    distance_m: float | None = None
    ipd_m: float = 0.063
    layout: str = "random"

    def __post_init__(self) -> None:
        if self.layout not in GRAIN_LAYOUTS:
            raise InputError(
                f"GRF layout must be one of {', '.join(GRAIN_LAYOUTS)}; got {self.layout!r}"
            )
        if not (0.0 < self.grain_deg <= 30.0):
            raise InputError(
                f"GRF grain size must be degrees in (0, 30], e.g. 1.5; got {self.grain_deg}"
            )
        if not (0.0 < self.density < 1.0):
            raise InputError(
                f"GRF density must be a blocked fraction in (0, 1), e.g. 0.5; got {self.density}"
            )
        if not (0.0 <= self.inner_deg < self.outer_deg <= 180.0):
            raise InputError(
                f"GRF cutout needs 0 <= inner < outer <= 180 degrees, e.g. 18 and 40; "
                f"got {self.inner_deg} and {self.outer_deg}"
            )
        if int(self.seed) != self.seed or self.seed < 0:
            raise InputError(f"GRF seed must be an integer >= 0; got {self.seed}")
        if self.distance_m is not None and not (
            self.distance_m > 0 and math.isfinite(self.distance_m)
        ):
            raise InputError(f"GRF grain distance must be metres > 0; got {self.distance_m}")
        if not (0.0 <= self.ipd_m < 1.0):
            raise InputError(
                f"interpupillary distance must be metres in [0, 1), e.g. 0.063; got {self.ipd_m}"
            )

    @property
    def grain_solid_angle_sr(self) -> float:
        """Solid angle of one grain, steradians: ``2 pi (1 - cos(grain/2))``."""
        return 2.0 * math.pi * (1.0 - math.cos(math.radians(self.grain_deg) / 2.0))


def grain_count(config: GrfConfig) -> int:
    """Number of uniformly placed grains whose union blocks ``config.density`` of the sphere.

    Each of ``n`` independent uniform grains misses a given direction with probability
    ``1 - a / 4 pi`` (``a``: grain solid angle), so the expected blocked fraction is
    ``1 - (1 - a / 4 pi)^n`` (``~ 1 - exp(-n a / 4 pi)``); solved for ``n`` and rounded.
    A layout with its own count (``fibonacci``) gives that instead.
    """
    if LAYOUTS[config.layout][1] is not None:
        return int(LAYOUTS[config.layout][1](config))
    p = config.grain_solid_angle_sr / (4.0 * math.pi)
    return max(1, round(math.log1p(-config.density) / math.log1p(-p)))


def cutout_alpha(ecc_deg, config: GrfConfig = GrfConfig()) -> NDArray[np.float64]:
    """Head-fixed soft cutout: 0 within ``inner_deg``, 1 beyond ``outer_deg``, linear between.

    ``ecc_deg``: eccentricity (angle from the view centre), degrees, any shape.
    """
    e = np.asarray(ecc_deg, float)
    return np.clip((e - config.inner_deg) / (config.outer_deg - config.inner_deg), 0.0, 1.0)


@dataclass(frozen=True)
class GrainBuckets:
    """Grains sorted into sphere cells, the layout the fragment shader reads.

    The sphere is cut into ``n_bands`` latitude bands of ``cell_rad`` radians from the
    south pole (band ``j`` covers lat in ``[-pi/2 + j cell, -pi/2 + (j+1) cell)``); band
    ``j`` has ``bands[j, 1]`` cells of equal longitude width starting at lon = -pi,
    numbered from ``bands[j, 0]``. Cell ``c`` lists ``entries[cell_start[c]:cell_start[c+1]]``:
    every grain whose disc, grown by ``margin_rad``, reaches into the cell.

    bands : ndarray, shape (n_bands, 2), int32 (first cell, cell count)
    cell_start : ndarray, shape (n_cells + 1,), int32
    entries : ndarray, shape (n_entries, 4), float32 (x, y, z world unit vector, chord
        radius ``2 sin(r / 2)`` of the disc edge)
    """

    cell_rad: float
    bands: NDArray[np.int32]
    cell_start: NDArray[np.int32]
    entries: NDArray[np.float32]

    @property
    def n_bands(self) -> int:
        return int(self.bands.shape[0])


@dataclass(frozen=True)
class GrainField:
    """A seeded, world-fixed grain layout.

    centers : ndarray, shape (n, 3), float64, read-only
        Unit grain centres in the world frame (+x right, +y up, +z forward).
    radius_rad : angular radius of every grain, radians
    """

    config: GrfConfig
    centers: NDArray[np.float64]
    radius_rad: float

    @classmethod
    def from_config(cls, config: GrfConfig = GrfConfig()) -> GrainField:
        """Place :func:`grain_count` grains by ``config.layout`` with ``config.seed``."""
        return _field_cached(config)

    def buckets(self, margin_rad: float, *, cell_deg: float | None = None) -> GrainBuckets:
        """Sort the grains into cells (see :class:`GrainBuckets`).

        ``margin_rad`` grows each disc for the lookup (half a pixel's angular footprint
        plus slack, so that antialiased edges find their grain); ``cell_deg`` defaults to
        half the grain diameter (about 2 grains per cell for the paper's GRF).
        """
        cell = math.radians(cell_deg if cell_deg is not None else self.config.grain_deg / 2.0)
        return _buckets(self.centers, self.radius_rad + float(margin_rad), self.radius_rad, cell)


@functools.lru_cache(maxsize=8)
def _field_cached(config: GrfConfig) -> GrainField:
    centers = layout_centers(config, grain_count(config))
    return GrainField(config, centers, math.radians(config.grain_deg) / 2.0)


def _band_layout(cell: float) -> NDArray[np.int64]:
    n_bands = math.ceil(math.pi / cell - 1e-9)
    lo = -math.pi / 2 + np.arange(n_bands) * cell
    hi = np.minimum(lo + cell, math.pi / 2)
    # Width measured at the band edge nearest the equator: cells are >= cell wide there.
    edge = np.where(lo * hi <= 0, 0.0, np.minimum(np.abs(lo), np.abs(hi)))
    n_lon = np.maximum(1, np.floor(2 * math.pi * np.cos(edge) / cell)).astype(np.int64)
    first = np.concatenate([[0], np.cumsum(n_lon)[:-1]])
    return np.stack([first, n_lon], axis=-1)


def _buckets(centers: NDArray, reach: float, radius: float, cell: float) -> GrainBuckets:
    bands = _band_layout(cell)
    n_bands = bands.shape[0]
    n_cells = int(bands[-1].sum())
    lat = np.arcsin(np.clip(centers[:, 1], -1.0, 1.0))
    lon = np.arctan2(centers[:, 0], centers[:, 2])
    # Widest longitude half-extent of a cap of angular radius `reach` centred at `lat`.
    cos_lat = np.cos(lat)
    polar = np.abs(lat) + reach >= math.pi / 2 - 1e-9
    dlon = np.where(
        polar, math.pi, np.arcsin(np.clip(math.sin(reach) / np.maximum(cos_lat, 1e-12), 0, 1))
    )
    b0 = np.clip(np.floor((lat - reach + math.pi / 2) / cell), 0, n_bands - 1).astype(np.int64)
    b1 = np.clip(np.floor((lat + reach + math.pi / 2) / cell), 0, n_bands - 1).astype(np.int64)
    cell_ids: list[NDArray] = []
    grain_ids: list[NDArray] = []
    for j in range(n_bands):
        sel = np.nonzero((b0 <= j) & (b1 >= j))[0]
        if sel.size == 0:
            continue
        first, n_lon = int(bands[j, 0]), int(bands[j, 1])
        full = dlon[sel] >= math.pi
        w = 2 * math.pi / n_lon
        c0 = np.floor((lon[sel] - dlon[sel] + math.pi) / w).astype(np.int64)
        c1 = np.floor((lon[sel] + dlon[sel] + math.pi) / w).astype(np.int64)
        count = np.where(full | (c1 - c0 + 1 >= n_lon), n_lon, c1 - c0 + 1)
        c0 = np.where(count == n_lon, 0, c0)
        gid = np.repeat(sel, count)
        offs = np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count)
        cid = first + np.mod(np.repeat(c0, count) + offs, n_lon)  # wraps at the +-180 deg seam
        cell_ids.append(cid)
        grain_ids.append(gid)
    cid = np.concatenate(cell_ids) if cell_ids else np.zeros(0, np.int64)
    gid = np.concatenate(grain_ids) if grain_ids else np.zeros(0, np.int64)
    order = np.argsort(cid, kind="stable")
    cid, gid = cid[order], gid[order]
    counts = np.bincount(cid, minlength=n_cells)
    cell_start = np.concatenate([[0], np.cumsum(counts)]).astype(np.int32)
    entries = np.empty((gid.size, 4), np.float32)
    entries[:, :3] = centers[gid]
    entries[:, 3] = 2.0 * math.sin(radius / 2.0)  # chord radius: |p - c| at the disc edge
    out = GrainBuckets(cell, bands.astype(np.int32), cell_start, entries)
    for a in (out.bands, out.cell_start, out.entries):
        a.setflags(write=False)
    return out
