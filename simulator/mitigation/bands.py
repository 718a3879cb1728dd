"""Named flow bands in deg/s: what a given EPOF means, with the source of each band.

EPOF is the mean angular speed of the image in the viewport (deg/s of visual angle). The
closest published stimuli are optokinetic drums and rotating panoramas, whose whole field
turns at one angular speed, so their speeds are read here as EPOF values. The bands'
edges (deg/s) and sources (docs/screen.md gives the references in full):

- ``calm`` below 5: below the slowest yaw rotation used to induce circular vection in
  Nesti et al. 2015 (Exp Brain Res 233, 5, 15, 30, 45, 60 deg/s); a convention, not a
  measured threshold of sickness.
- ``vection`` 5 to 30: the range in which a rotating natural scene induces complete
  circular vection (Nesti et al. 2015: at every speed tested, after about 10 s).
- ``provocative`` 30 to 60: an optokinetic drum at 5 rpm = 30 deg/s brings on motion
  sickness symptoms within minutes (Bonato, Bubka & Story 2005, Aviat Space Environ Med
  76:823).
- ``strong`` 60 and above: 10 rpm = 60 deg/s, the speed of the classic drum studies of
  vection-induced sickness (Hu et al. 1989, Aviat Space Environ Med 60:411; Bonato et al.
  2003, 74:315).

The absolute opacity rule's defaults (:data:`ABSOLUTE_LOW_DPS`, :data:`ABSOLUTE_HIGH_DPS`)
are the edges of the vection and provocative bands: no grains in a calm video, full
grains where drums sicken.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = [
    "ABSOLUTE_HIGH_DPS",
    "ABSOLUTE_LOW_DPS",
    "BANDS",
    "Band",
    "band_of",
    "draw_bands",
    "rule_text",
    "share_above",
]


@dataclass(frozen=True)
class Band:
    """A named range of flow, ``lo_dps <= flow < hi_dps`` (deg/s), with its source."""

    name: str
    lo_dps: float
    hi_dps: float
    colour: str
    source: str


BANDS: tuple[Band, ...] = (
    Band("calm", 0.0, 5.0, "#d9f0d3",
         "convention: below the slowest vection stimulus of Nesti et al. 2015 (5 deg/s)"),
    Band("vection", 5.0, 30.0, "#fff2b2",
         "Nesti et al. 2015, Exp Brain Res: circular vection at 5-60 deg/s"),
    Band("provocative", 30.0, 60.0, "#fdd0a2",
         "Bonato et al. 2005, Aviat Space Environ Med 76:823: drum at 30 deg/s sickens"),
    Band("strong", 60.0, math.inf, "#fcae91",
         "Hu et al. 1989; Bonato et al. 2003: drums at 60 deg/s (10 rpm)"),
)  # fmt: skip

#: The absolute opacity rule's default thresholds (deg/s): opacity 0 at the vection
#: band's lower edge, 1 at the provocative band's.
ABSOLUTE_LOW_DPS = 5.0
ABSOLUTE_HIGH_DPS = 30.0


def rule_text(rule: dict | None) -> str:
    """An opacity rule in a few words for tables and pages: ``absolute 5-30 deg/s``,
    ``paper P10-P90``, ``comfort P10-P90``; ``rule`` is an ``OpacityRule.describe()`` dict
    (``name``) or a study's ``[epof]`` options (``opacity_rule``); "" for None. A record
    from before rules had names says ``relative``."""
    if not rule:
        return ""
    name = rule.get("name") or rule.get("opacity_rule")
    if rule.get("scale") == "absolute" or (name == "absolute" and rule.get("low_dps") is not None):
        return f"{name or 'absolute'} {rule['low_dps']:g}-{rule['high_dps']:g} deg/s"
    return f"{name or 'relative'} P{rule.get('low_pct', 10):g}-P{rule.get('high_pct', 90):g}"


def band_of(flow_dps: float) -> str:
    """The name of the band holding ``flow_dps`` (deg/s)."""
    for b in BANDS:
        if b.lo_dps <= flow_dps < b.hi_dps:
            return b.name
    return BANDS[0].name


def share_above(flow_dps, *, keep=None) -> dict[str, float]:
    """Share of samples at or above each band's lower edge (``keep``: a mask of the
    samples counted, e.g. not artefacts), keyed ``share_ge_<band>``; the first band
    (everything) is left out."""
    e = np.asarray(flow_dps, np.float64)
    if keep is not None:
        e = e[np.asarray(keep, bool)]
    out = {}
    for b in BANDS[1:]:
        out[f"share_ge_{b.name}"] = float(np.mean(e >= b.lo_dps)) if e.size else math.nan
    return out


def draw_bands(ax, *, labels: bool = True) -> None:
    """Shade the bands behind a matplotlib axes whose y axis is flow in deg/s, each named
    at the right edge (the axes' limits are kept)."""
    y0, y1 = ax.get_ylim()
    for b in BANDS:
        lo, hi = max(b.lo_dps, y0), min(b.hi_dps, y1)
        if hi <= lo:
            continue
        ax.axhspan(lo, hi, color=b.colour, alpha=0.45, lw=0, zorder=0)
        if labels:
            ax.annotate(b.name, xy=(1.0, (lo + hi) / 2), xycoords=("axes fraction", "data"),
                        xytext=(4, 0), textcoords="offset points", va="center", fontsize=7,
                        color="0.3", annotation_clip=False)  # fmt: skip
    ax.set_ylim(y0, y1)
