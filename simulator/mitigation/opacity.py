"""The GRF opacity rule: EPOF (deg/s) to opacity 0..1 (absolute deg/s by default, the paper's per-video percentiles, comfort).

:class:`OpacityRule` and its builders, :func:`ease`, :func:`comfort_rule` and
:func:`rule_from_options` (the one builder from CLI or manifest options); re-exported by
:mod:`simulator.mitigation.grf` beside the grain layout it drives.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from simulator.core.choices import OPACITY_RULE_DEFAULT, OPACITY_RULES, OPACITY_SOURCES
from simulator.core.errors import InputError
from simulator.media.coverage import coverage_masks
from simulator.media.gridfile import GridFile
from simulator.mitigation.bands import ABSOLUTE_HIGH_DPS, ABSOLUTE_LOW_DPS

__all__ = [
    "COMFORT_EASE_IN_S",
    "COMFORT_EASE_OUT_S",
    "RULE_OPTIONS",
    "OpacityRule",
    "comfort_rule",
    "ease",
    "rule_from_options",
]

#: Ease-in / ease-out times (seconds for a full 0 -> 1 / 1 -> 0 change) of the eased rules
#: (absolute, the CLI's default, and comfort, :func:`comfort_rule`); measured in docs/epof.md
#: (bench/opacity_flicker.py): grains come in fast and leave slowly.
COMFORT_EASE_IN_S = 0.4
COMFORT_EASE_OUT_S = 1.5


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
    the paper's rule, unsmoothed; the CLI's default is absolute (:func:`rule_from_options`).

    ``low_dps`` and ``high_dps`` (both or neither) make the rule **absolute**: opacity 0 at
    ``low_dps``, 1 at ``high_dps`` deg/s whatever the video (the named bands of
    :mod:`simulator.mitigation.bands`); the percentiles and ``source`` are then unused.
    The paper's rule is relative: every video gets grains in its own top tenth of flow.
    ``name``: the rule's name in :data:`~simulator.core.choices.OPACITY_RULES` ("" = by its
    fields: ``absolute``, ``paper`` or ``comfort``), recorded by :meth:`describe`.
    """

    low_pct: float = 10.0
    high_pct: float = 90.0
    source: str = "grid"
    smoothing_s: float = 0.0
    ease_in_s: float = 0.0
    ease_out_s: float = 0.0
    low_dps: float | None = None
    high_dps: float | None = None
    name: str = ""

    def __post_init__(self) -> None:
        if self.name and self.name not in OPACITY_RULES:
            raise InputError(f"opacity rule: expected one of {', '.join(OPACITY_RULES)}; got {self.name!r}")
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

    @property
    def label(self) -> str:
        """The rule's name: ``name``, else ``absolute`` / ``paper`` / ``comfort`` by its fields."""
        return self.name or ("absolute" if self.is_absolute else "paper" if self.is_paper else "comfort")

    def describe(self) -> dict:
        """The rule's settings, for summary.json and CSV headers (``name``: :attr:`label`)."""
        return {
            "name": self.label,
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
    """The comfort opacity rule: the paper's percentiles with ease-in
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
    """The one opacity-rule builder from options: by default (:data:`OPACITY_RULE_DEFAULT`)
    ``"absolute"``, the eased rule between ``low_dps`` and ``high_dps`` deg/s (defaults: the
    bands' :data:`ABSOLUTE_LOW_DPS`, :data:`ABSOLUTE_HIGH_DPS`; given with another rule they
    are refused); ``"comfort"`` the eased percentile rule (easing: :func:`comfort_rule`'s
    unless ``ease_in``/``ease_out`` are given); ``"paper"`` the paper's unsmoothed rule.

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
    source, kind = get("opacity_source") or "grid", get("opacity_rule") or OPACITY_RULE_DEFAULT
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
        return OpacityRule(low, high, source, name=kind)
    ease_in = COMFORT_EASE_IN_S if ease_in is None else ease_in
    ease_out = COMFORT_EASE_OUT_S if ease_out is None else ease_out
    return OpacityRule(low, high, source, smooth or 0.0, ease_in, ease_out,
                       low_dps=lo_dps, high_dps=hi_dps, name=kind)  # fmt: skip
