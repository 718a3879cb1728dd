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

from simulator.core.choices import OPACITY_RULES, OPACITY_SOURCES
from simulator.core.errors import InputError
from simulator.media.coverage import coverage_masks
from simulator.media.gridfile import GridFile
from simulator.mitigation.bands import ABSOLUTE_HIGH_DPS, ABSOLUTE_LOW_DPS
from simulator.mitigation.layouts import GRAIN_LAYOUTS, LAYOUTS, layout_centers

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

#: Ease-in / ease-out times (seconds for a full 0 -> 1 / 1 -> 0 change) of the comfort
#: opacity rule, the CLI's default (:func:`comfort_rule`); measured in docs/epof.md
#: (bench/opacity_flicker.py): grains come in fast and leave slowly.
COMFORT_EASE_IN_S = 0.4
COMFORT_EASE_OUT_S = 1.5


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


# ------------------------------------------------------------------------- opacity


@dataclass(frozen=True)
class OpacityRule:
    """GRF opacity from EPOF (paper 4.2.2).

    Opacity = clamp((EPOF - lo) / (hi - lo), 0, 1) with ``lo``/``hi`` the ``low_pct`` /
    ``high_pct`` percentiles of the flow of ``source``: ``"grid"`` = every window of
    every frame of the grid file (the paper's "whole video"; only the windows the
    projection covers, e.g. VR180's front half), ``"viewing"`` = this
    viewing's EPOF. ``smoothing_s`` > 0 applies a causal exponential smoothing with that
    time constant (seconds) to the opacity; 0 (default) = none.

    ``ease_in_s`` / ``ease_out_s`` > 0 then limit how fast the opacity may rise / fall:
    a full change 0 -> 1 takes at least ``ease_in_s`` seconds, 1 -> 0 at least
    ``ease_out_s`` (a slew-rate limit, as the ease-in / ease-out times of Unity XR
    Interaction Toolkit's tunneling vignette); 0 = no limit. All zero (the default) is
    the paper's rule, unsmoothed; :func:`comfort_rule` is the CLI's default.

    ``low_dps`` and ``high_dps`` (both or neither) make the rule **absolute**: opacity 0 at
    ``low_dps``, 1 at ``high_dps`` deg/s whatever the video (the named bands of
    :mod:`simulator.mitigation.bands`); the percentiles and ``source`` are then unused.
    The paper's rule is relative: every video gets grains in its own top tenth of flow.
    """

    low_pct: float = 10.0
    high_pct: float = 90.0
    source: str = "grid"
    smoothing_s: float = 0.0
    ease_in_s: float = 0.0
    ease_out_s: float = 0.0
    low_dps: float | None = None
    high_dps: float | None = None

    def __post_init__(self) -> None:
        if (self.low_dps is None) != (self.high_dps is None):
            raise InputError("absolute opacity rule needs both --low-dps and --high-dps")
        if self.low_dps is not None:
            lo, hi = self.low_dps, self.high_dps
            if not (math.isfinite(lo) and math.isfinite(hi) and 0.0 <= lo):
                raise InputError(
                    f"--low-dps / --high-dps must be finite deg/s >= 0; got {lo}, {hi}"
                )
            if not lo < hi:
                raise InputError(f"--low-dps ({lo:g}) must be below --high-dps ({hi:g}) deg/s")
        if not (0.0 <= self.low_pct < self.high_pct <= 100.0):
            raise InputError(
                f"opacity percentiles must satisfy 0 <= low < high <= 100; got {self.low_pct}, {self.high_pct}"
            )
        if self.source not in OPACITY_SOURCES:
            raise InputError(f"opacity source must be grid or viewing; got {self.source!r}")
        if not (self.smoothing_s >= 0.0 and math.isfinite(self.smoothing_s)):
            raise InputError(f"opacity smoothing must be >= 0 seconds; got {self.smoothing_s}")
        for name, v in (("ease-in", self.ease_in_s), ("ease-out", self.ease_out_s)):
            if not (v >= 0.0 and math.isfinite(v)):
                raise InputError(f"opacity {name} time must be >= 0 seconds; got {v}")

    @property
    def is_absolute(self) -> bool:
        """True when the thresholds are fixed deg/s (``low_dps``/``high_dps``)."""
        return self.low_dps is not None

    @property
    def is_paper(self) -> bool:
        """True for the paper's rule: no smoothing, no easing."""
        return self.smoothing_s == 0 and self.ease_in_s == 0 and self.ease_out_s == 0

    def describe(self) -> dict:
        """The rule's settings, for summary.json and CSV headers."""
        return {
            "low_pct": self.low_pct,
            "high_pct": self.high_pct,
            "source": self.source,
            "smoothing_s": self.smoothing_s,
            "ease_in_s": self.ease_in_s,
            "ease_out_s": self.ease_out_s,
            "rule": "paper" if self.is_paper else "eased",
            **(
                {"scale": "absolute", "low_dps": self.low_dps, "high_dps": self.high_dps}
                if self.is_absolute
                else {}
            ),
        }

    def fit(self, grid: GridFile | None, epof_dps, *, keep=None) -> tuple[float, float]:
        """``(lo, hi)`` thresholds in deg/s: the absolute ones, or percentiles of the grid's
        flow or of this viewing's EPOF. ``keep`` (bool, one per grid row for source
        ``grid``, one per EPOF sample for ``viewing``) leaves rows out, e.g. artefacts.

        Source ``grid`` takes the windows the source's projection covers (all of them but
        for e.g. VR180, :mod:`simulator.media.coverage`): an uncovered window has no flow
        measured (stored as 0 deg/s), and counting it would pull both thresholds down
        (VR180: the low one to 0)."""
        if self.is_absolute:
            return float(self.low_dps), float(self.high_dps)
        if self.source == "grid":
            if grid is None:
                raise InputError("opacity source 'grid' needs the grid file")
            pof = grid.pof_dps
            if keep is not None and len(keep) == len(pof) and not np.all(keep):
                pof = np.asarray(pof)[np.asarray(keep, bool)]
            wins, _ = coverage_masks(grid.meta)
            if wins is not None and wins.shape == tuple(pof.shape[1:]) and wins.any():
                pof = np.asarray(pof)[:, wins]  # (T, covered windows)
            vals = np.array(pof, np.float64).ravel()  # our own copy
        else:
            vals = np.asarray(epof_dps, np.float64)
            if keep is not None and len(keep) == len(vals):
                vals = vals[np.asarray(keep, bool)]
            vals = np.array(vals, np.float64).ravel()
        finite = np.isfinite(vals)
        if not finite.all():
            vals = vals[finite]
        if vals.size == 0:
            raise InputError("no finite flow values to take opacity percentiles from")
        # One working copy (long videos): partitioned in place, the same values selected.
        lo, hi = np.percentile(vals, [self.low_pct, self.high_pct], overwrite_input=True)
        return float(lo), float(hi)

    def __call__(self, epof_dps, thresholds_dps: tuple[float, float], *, fps: float | None = None):
        """Opacity in [0, 1] of each EPOF value (deg/s), shape of ``epof_dps``.

        ``fps`` (frames per second of the samples) is needed only when smoothing or easing.
        """
        lo, hi = thresholds_dps
        e = np.asarray(epof_dps, np.float64)
        if hi > lo:
            op = np.clip((e - lo) / (hi - lo), 0.0, 1.0)
        else:  # constant flow: a step at the threshold
            op = (e > lo).astype(np.float64)
        if self.smoothing_s > 0 and op.size > 1:
            if not fps:
                raise InputError("opacity smoothing needs the frame rate")
            a = 1.0 - math.exp(-1.0 / (fps * self.smoothing_s))
            sm = np.empty_like(op)
            acc = op.flat[0]
            for i, x in enumerate(op.ravel()):
                acc = acc + a * (x - acc)
                sm.flat[i] = acc
            op = sm
        if (self.ease_in_s > 0 or self.ease_out_s > 0) and op.size > 1:
            if not fps:
                raise InputError("opacity easing needs the frame rate")
            op = ease(op, fps, self.ease_in_s, self.ease_out_s)
        return op


def ease(op, fps: float, ease_in_s: float, ease_out_s: float) -> NDArray[np.float64]:
    """Slew-rate limit of a per-frame opacity series (causal): per frame it rises by at
    most ``1 / (fps * ease_in_s)`` and falls by at most ``1 / (fps * ease_out_s)``
    (0 = unlimited). Starts at the first value; shape kept."""
    x = np.asarray(op, np.float64)
    flat = x.ravel()
    up = math.inf if ease_in_s <= 0 else 1.0 / (fps * ease_in_s)
    down = math.inf if ease_out_s <= 0 else 1.0 / (fps * ease_out_s)
    out = np.empty_like(flat)
    acc = float(flat[0]) if flat.size else 0.0
    for i, v in enumerate(flat.tolist()):
        d = v - acc
        acc = acc + (min(d, up) if d > 0 else max(d, -down))
        out[i] = acc
    return out.reshape(x.shape)


def comfort_rule(**overrides) -> OpacityRule:
    """The CLI's default opacity rule: the paper's percentiles with ease-in
    :data:`COMFORT_EASE_IN_S` and ease-out :data:`COMFORT_EASE_OUT_S` (no smoothing);
    ``overrides`` replace fields. ``OpacityRule()`` is the paper's unsmoothed rule."""
    kw = {"ease_in_s": COMFORT_EASE_IN_S, "ease_out_s": COMFORT_EASE_OUT_S, **overrides}
    return OpacityRule(**kw)


#: The option names :func:`rule_from_options` reads (``vimsim epof``'s and ``render``'s
#: ``--low-pct`` ... ``--opacity-rule``; a manifest's ``[epof]`` keys).
RULE_OPTIONS = (
    "low_pct",
    "high_pct",
    "opacity_source",
    "opacity_rule",
    "smooth",
    "ease_in",
    "ease_out",
    "low_dps",
    "high_dps",
)


def rule_from_options(get, label) -> OpacityRule:
    """The one opacity-rule builder from options: the eased comfort rule by default
    (:func:`comfort_rule`'s easing unless ``ease_in``/``ease_out`` are given),
    ``opacity_rule = "paper"`` the paper's unsmoothed rule, ``"absolute"`` the eased rule
    between ``low_dps`` and ``high_dps`` deg/s (defaults: the bands' :data:`ABSOLUTE_LOW_DPS`,
    :data:`ABSOLUTE_HIGH_DPS`; given with another rule they are refused).

    get : ``get(name)`` -> the option's value or None (not given), for the names of
        :data:`RULE_OPTIONS`; label : ``label(name)`` -> the option as the caller spells it
        (``--ease-in``, ``[epof] ease_in``), for the one-line InputError of a bad value.
    """

    def value(name, default, lo=0.0, hi=None):
        v = get(name)
        if v is None:
            return default
        ok = isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
        if not ok or v < lo or (hi is not None and v > hi):
            rng = f"[{lo:g}, {hi:g}]" if hi is not None else f">= {lo:g}"
            raise InputError(f"{label(name)}: expected a number {rng}; got {v!r}")
        return float(v)

    low, high = value("low_pct", 10.0, hi=100.0), value("high_pct", 90.0, hi=100.0)
    if not low < high:
        raise InputError(
            f"{label('low_pct')}: {low:g} must be below {label('high_pct')} ({high:g})"
        )
    source, kind = get("opacity_source") or "grid", get("opacity_rule") or "comfort"
    for name, v, choices in (("opacity_source", source, OPACITY_SOURCES),
                             ("opacity_rule", kind, OPACITY_RULES)):  # fmt: skip
        if v not in choices:
            raise InputError(f"{label(name)}: expected one of {', '.join(choices)}; got {v!r}")
    lo_dps, hi_dps = value("low_dps", None), value("high_dps", None)
    if kind != "absolute" and (lo_dps is not None or hi_dps is not None):
        given = label("low_dps" if lo_dps is not None else "high_dps")
        raise InputError(f"{given} needs {label('opacity_rule')} absolute")
    if kind == "absolute":
        lo_dps = ABSOLUTE_LOW_DPS if lo_dps is None else lo_dps
        hi_dps = ABSOLUTE_HIGH_DPS if hi_dps is None else hi_dps
        if not lo_dps < hi_dps:
            raise InputError(
                f"{label('low_dps')} ({lo_dps:g}) must be below {label('high_dps')} "
                f"({hi_dps:g}) deg/s"
            )
    smooth, ease_in, ease_out = (value(n, None) for n in ("smooth", "ease_in", "ease_out"))
    if kind == "paper":
        given = [label(n) for n, v in (("smooth", smooth), ("ease_in", ease_in),
                                       ("ease_out", ease_out)) if v is not None]  # fmt: skip
        if given:
            raise InputError(
                f"{label('opacity_rule')} paper is the unsmoothed rule; drop "
                f"{', '.join(given)} or use comfort"
            )
        return OpacityRule(low, high, source)
    return OpacityRule(
        low,
        high,
        source,
        smooth or 0.0,
        COMFORT_EASE_IN_S if ease_in is None else ease_in,
        COMFORT_EASE_OUT_S if ease_out is None else ease_out,
        low_dps=lo_dps,
        high_dps=hi_dps,
    )
