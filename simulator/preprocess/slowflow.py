"""Sphere mode's default flow: DIS ultrafast, computed at twice its resolution (finest scale 1, no variational refinement) on the frame pairs whose content moved less than a few pixels in the previous pair.

DIS ultrafast matches 8 px patches and stops at 1/4 of the tile's resolution; where the
content moves by a pixel or less per frame its flow is a fraction of a pixel at that scale:
the speed wobbles by +-10-25 % from frame to frame and the camera's rate reads 3-5 % high
at 5 deg/s. :class:`SlowFine` then computes the flow down to 1/2 of the tile's resolution
(DIS finest scale 1: the same motion is twice as many pixels there), only where it
matters: a frame pair is read finely when the median displacement of every tile's pixels
in the *previous* pair was below :data:`SLOW_PX` (motion is smooth from one frame to the
next; the first pair of a run is plain), so fast footage costs what it did; a still camera
(every tile below :data:`STILL_PX`: nothing moves to be read better) stays plain too. All
six tiles or none: mixing two flows whose small biases differ in one frame drags the
rotation fit (3 m room: omega error 1.1 -> 2.0 %).

This replaced 5 iterations of OpenCV's variational refinement on those pairs: the
refinement reads sub-pixel motion *too fast*, by 10-18 % at 5 deg/s, 11-13 % at 10 and
4-5 % at 20 (the rate about each axis and the speed field alike, on lossless and crf 16
rotate clips; ``bench/calibrate.py``, ``docs/ego.md``).

Only the default ``dis`` / ``dis:ultrafast`` flow is made adaptive; a flow given with its
own refinement (``dis:PRESET+refineN``), another preset or backend runs as given.
"""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray

from simulator.flow.dis import DISFlow

__all__ = ["SLOW_PX", "SLOW_SCALE", "STILL_PX", "SlowFine", "slow_flow_desc"]

#: A frame pair is read finely when every tile's median displacement in the previous pair
#: was below this (tile pixels per frame: 1/2 pixel at DIS ultrafast's 1/4 scale).
SLOW_PX = 2.0
#: ... unless every tile's median displacement was below this: a still camera (the flow's
#: noise), where nothing moves to be read better.
STILL_PX = 0.1
#: DIS's finest scale on a slow frame pair (1: flow at 1/2 of the tile's resolution;
#: ultrafast's own is 2, 1/4).
SLOW_SCALE = 1


def _adaptive(backend) -> bool:
    return isinstance(backend, DISFlow) and backend.preset == "ultrafast" and backend.refine is None


def slow_flow_desc(backend, desc: dict) -> dict:
    """The grid meta's ``flow`` entry of ``backend`` as sphere mode runs it: ``desc`` plus
    ``fine_slow`` where the finer flow of slow pairs is adaptive."""
    if not _adaptive(backend):
        return desc
    return {
        **desc,
        "fine_slow": {"below_px": SLOW_PX, "from_px": STILL_PX, "finest_scale": SLOW_SCALE},
    }


class _FineDIS(DISFlow):
    """DIS ultrafast down to finest scale :data:`SLOW_SCALE`, no variational refinement."""

    def _dis(self):
        d = getattr(self._local, "dis", None)
        if d is None:
            d = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_ULTRAFAST)
            d.setFinestScale(SLOW_SCALE)
            self._local.dis = d
        return d


class SlowFine:
    """Flow of consecutive stacks of tiles, read at twice DIS's resolution when every tile
    moved slowly in the previous call (module docstring); ``backend(prev, cur)`` as given
    where it is not the default DIS ultrafast. One instance per video (it remembers the
    previous pair)."""

    def __init__(self, backend):
        self.backend = backend
        self._fine = _FineDIS("ultrafast") if _adaptive(backend) else None
        self._last: NDArray[np.float32] | None = None

    def __call__(self, prev: NDArray[np.uint8], cur: NDArray[np.uint8]) -> NDArray[np.float32]:
        if self._fine is None:
            return np.asarray(self.backend(prev, cur), np.float32)
        top = None if self._last is None else float(self._last.max())
        slow = top is not None and STILL_PX <= top < SLOW_PX
        fl = (self._fine if slow else self.backend)(prev, cur)
        sub = fl[:, 2::8, 2::8]
        mag = np.sqrt(sub[..., 0] ** 2 + sub[..., 1] ** 2).reshape(len(fl), -1)
        self._last = np.median(mag, axis=1)
        return fl
