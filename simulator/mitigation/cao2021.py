"""The authors' running system (Cao et al.'s Unity code): nearest-window flow with its list indexing, a fixed px/frame opacity scale, and 0.5 deg Fibonacci grains.

The paper (and vimsim's ``paper`` preset) describes overlap-weighted EPOF, per-video
10th/90th percentiles, 1.5 deg grains and a 36-80 deg soft cutout. The authors' Unity
project runs something else, reproduced here exactly as the ``cao2021-code`` preset
(docs/parity.md):

- **Nearest window.** Head yaw / pitch in degrees (yaw + right, pitch + up), each wrapped
  to (-180, 180]. Yaw candidates ``ceil(yaw/s)*s`` and ``floor(yaw/s)*s`` (``s`` = the
  grid's yaw step, 15), each above ``180 - s`` moved by -360 and below ``-(180 - s)`` by
  +360; pitch candidates ``ceil`` and ``floor`` of ``pitch/s_p`` times ``s_p``. In each axis
  the candidate with the smaller plain absolute difference wins (so a yaw in (165, 180) uses
  the 165 window, never -180; yaw exactly 180 uses -180). A tie (yaw exactly between two
  centres) goes to the ``ceil`` candidate: the issue text does not say, vimsim chooses.
  Pitch candidates outside the grid's rows are clamped to its first / last row (the
  authors' grid has the poles, so this never happens there).
- **List indexing.** Their reader takes the number after the comma of every non-empty line
  of a window's CSV, the header ``,0`` included, so a window's list is
  ``[0, row 0, row 1, ...]``; at video frame ``k`` (0-based) the flow is ``list[k-1]``, i.e.
  row ``k - 2``, and 0 for ``k < 1`` and beyond the list.
- **Fixed scale.** Opacity = clamp((flow - 0.18) / (53.73 - 0.18), 0, 1), flow in window
  px/frame, the same two numbers (``percentileData.csv``) for every video.
- **Grains.** Black grains of 0.5 deg on a Fibonacci sphere of ``n = 180 * 360 / size^2``
  points, a random half kept (seeded here), alpha = opacity, no cutout.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from simulator.core.errors import InputError
from simulator.mitigation.grf import GrainField, GrfConfig
from simulator.mitigation.layouts import fibonacci_sphere

__all__ = [
    "CAO_GRAIN_DEG",
    "CAO_HIGH_PX",
    "CAO_LOW_PX",
    "FixedPxRule",
    "cao_grain_field",
    "cao_grf_config",
    "fibonacci_sphere",
    "list_row",
    "nearest_flow",
    "nearest_window",
]

#: ``percentileData.csv`` of the authors' data: opacity 0 at 0.18, 1 at 53.73 window px/frame.
CAO_LOW_PX = 0.18
CAO_HIGH_PX = 53.73
#: Grain size of their Unity overlay, degrees (the paper says 1.5).
CAO_GRAIN_DEG = 0.5


@dataclass(frozen=True)
class FixedPxRule:
    """Opacity from a window's flow in px/frame on one fixed scale for every video:
    ``clamp((flow - low_px) / (high_px - low_px), 0, 1)`` (defaults: the authors' file)."""

    low_px: float = CAO_LOW_PX
    high_px: float = CAO_HIGH_PX

    def __post_init__(self) -> None:
        lo, hi = self.low_px, self.high_px
        if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
            raise InputError(
                f"fixed px/frame opacity scale needs finite low < high; got {lo}, {hi}"
            )

    def __call__(self, flow_px) -> NDArray[np.float64]:
        f = np.asarray(flow_px, np.float64)
        return np.clip((f - self.low_px) / (self.high_px - self.low_px), 0.0, 1.0)

    def describe(self) -> dict:
        return {"rule": "cao2021-code", "scale": "fixed-px", "low_px": self.low_px,
                "high_px": self.high_px}  # fmt: skip


def _wrap180(a: NDArray) -> NDArray:
    """Angles in degrees wrapped to (-180, 180]."""
    w = np.mod(a + 180.0, 360.0) - 180.0  # [-180, 180)
    return np.where(w == -180.0, 180.0, w)


def _check_grid(yaw_centres, pitch_centres, yaw_step: float, pitch_step: float) -> None:
    ks = np.asarray(yaw_centres, float) / yaw_step
    kp = np.asarray(pitch_centres, float) / pitch_step
    if np.abs(ks - np.round(ks)).max() > 1e-6 or np.abs(kp - np.round(kp)).max() > 1e-6:
        raise InputError(
            f"the nearest-window rule needs window centres on multiples of the steps "
            f"({yaw_step:g} deg yaw, {pitch_step:g} deg pitch); this grid's are not"
        )


def nearest_window(
    yaw_deg, pitch_deg, yaw_centres_deg, pitch_centres_deg, *, yaw_step_deg=15.0,
    pitch_step_deg=15.0,
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:  # fmt: skip
    """``(pitch_index, yaw_index)`` of the window the authors' runtime reads for each pose.

    Parameters
    ----------
    yaw_deg, pitch_deg : array_like, degrees (broadcast together); yaw + right, pitch + up
    yaw_centres_deg : ndarray, shape (Y,), the grid's yaw centres, degrees, multiples of
        ``yaw_step_deg`` in [-180, 180)
    pitch_centres_deg : ndarray, shape (P,), increasing multiples of ``pitch_step_deg``
    yaw_step_deg, pitch_step_deg : float, keyword-only, degrees (15 and 15 for theirs)

    Returns
    -------
    (p, y) : int64 arrays of the broadcast shape, indices into the centre arrays
    """
    s, sp = float(yaw_step_deg), float(pitch_step_deg)
    yc = np.asarray(yaw_centres_deg, float)
    pc = np.asarray(pitch_centres_deg, float)
    _check_grid(yc, pc, s, sp)
    yaw, pitch = np.broadcast_arrays(_wrap180(np.asarray(yaw_deg, float)),
                                     _wrap180(np.asarray(pitch_deg, float)))  # fmt: skip
    edge = 180.0 - s
    cands = []
    for c in (np.ceil(yaw / s) * s, np.floor(yaw / s) * s):
        cands.append(np.where(c > edge, c - 360.0, np.where(c < -edge, c + 360.0, c)))
    up, lo = cands
    ycen = np.where(np.abs(yaw - up) <= np.abs(yaw - lo), up, lo)
    pup, plo = np.ceil(pitch / sp) * sp, np.floor(pitch / sp) * sp
    pcen = np.where(np.abs(pitch - pup) <= np.abs(pitch - plo), pup, plo)
    pcen = np.clip(pcen, pc[0], pc[-1])
    n_yaw = round(360.0 / s)
    lut = np.full(n_yaw, -1, np.int64)  # yaw centre (in steps, mod 360 deg) -> column
    lut[np.mod(np.round(yc / s).astype(np.int64), n_yaw)] = np.arange(len(yc))
    yi = lut[np.mod(np.round(ycen / s).astype(np.int64), n_yaw)]
    if np.any(yi < 0):
        missing = np.unique(ycen[yi < 0])[:3].tolist()
        raise InputError(f"the grid has no window at yaw {missing} deg (nearest-window rule)")
    pi = np.clip(np.searchsorted(pc, pcen - 1e-9), 0, len(pc) - 1)
    return pi.astype(np.int64), yi


def list_row(frames, n_rows: int) -> NDArray[np.int64]:
    """The CSV row (0-based) their reader gives at each video frame ``k``: ``k - 2``, or -1
    (flow 0) for ``k < 2`` (``k = 1`` reads the header ``,0``) and past the ``n_rows`` rows."""
    r = np.asarray(frames, np.int64) - 2
    return np.where((r >= 0) & (r < int(n_rows)), r, -1)


def nearest_flow(
    pof, frames, yaw_deg, pitch_deg, yaw_centres_deg, pitch_centres_deg, *, yaw_step_deg=15.0,
    pitch_step_deg=15.0,
) -> NDArray[np.float64]:  # fmt: skip
    """The flow their runtime reads: the nearest window's value of row ``k - 2`` at video
    frame ``k`` (0 before frame 2 and past the rows), in ``pof``'s unit.

    pof : ndarray, shape (T, P, Y) (a grid's ``pof_px`` for their px/frame measure)
    frames : array_like of int, video frame of each query (0-based)
    yaw_deg, pitch_deg : array_like, degrees; broadcast with ``frames``
    """
    pof = np.asarray(pof)
    p, y = nearest_window(yaw_deg, pitch_deg, yaw_centres_deg, pitch_centres_deg,
                          yaw_step_deg=yaw_step_deg, pitch_step_deg=pitch_step_deg)  # fmt: skip
    k, p, y = np.broadcast_arrays(np.asarray(frames, np.int64), p, y)
    r = list_row(k, pof.shape[0])
    out = pof[np.maximum(r, 0), p, y].astype(np.float64)
    return np.where(r >= 0, out, 0.0)


def cao_grf_config(*, grain_deg: float = CAO_GRAIN_DEG, seed: int = 0) -> GrfConfig:
    """Their grains as a :class:`~simulator.mitigation.grf.GrfConfig`: ``grain_deg`` grains
    on the ``fibonacci`` layout (:mod:`simulator.mitigation.layouts`), no cutout (0..1e-6
    deg: alpha is the opacity everywhere but a point); ``density`` is not used."""
    return GrfConfig(grain_deg=grain_deg, density=0.5, inner_deg=0.0, outer_deg=1e-6,
                     seed=seed, layout="fibonacci")  # fmt: skip


@functools.lru_cache(maxsize=4)
def cao_grain_field(*, grain_deg: float = CAO_GRAIN_DEG, seed: int = 0) -> GrainField:
    """Their grain layout (:func:`cao_grf_config`): a Fibonacci sphere of
    ``round(180 * 360 / grain_deg^2)`` points, a random half kept (``seed``; their Unity
    random draw cannot be reproduced), grains of ``grain_deg`` diameter. Centres read-only."""
    return GrainField.from_config(cao_grf_config(grain_deg=grain_deg, seed=seed))
