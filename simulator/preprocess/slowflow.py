"""Sphere mode's default flow: DIS ultrafast, with variational refinement on the frame pairs whose content moved less than a few pixels in the previous pair.

DIS ultrafast matches 8 px patches at 1/4 of the tile's resolution; where the content moves
by a pixel or less per frame its flow is a fraction of a pixel at that scale, and its
speed then wobbles by +-10-25 % from frame to frame (with the codec's frame types),
a large share of a small speed. OpenCV's variational refinement (a brightness-constancy
and smoothness energy minimised from the DIS flow) reads such motion better, but costs
most of the flow's time again. :class:`SlowRefine` pays it only where it matters: a frame
pair is refined when the median displacement of every tile's pixels in the *previous*
pair was below :data:`SLOW_PX` (motion is smooth from one frame to the next; the first
pair of a run is not refined), so fast footage costs what it did, and slow footage at
most the cost of ``--flow dis:ultrafast+refine5``; a still camera (every tile below
:data:`STILL_PX`: nothing moves for the refinement to read better) is not refined
either. All six tiles or none: refining only
the slow tiles of a frame (the poles of a turning camera) mixes two flows whose small
biases differ, which drags the rotation fit (3 m room: omega error 1.1 -> 2.0 %);
measured in ``bench/flow_at_speed.py``, ``docs/ego.md``.

Only the default ``dis`` / ``dis:ultrafast`` flow is made adaptive; a flow given with its
own refinement (``dis:PRESET+refineN``), another preset or backend runs as given.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from simulator.flow.dis import DISFlow

__all__ = ["SLOW_ITERATIONS", "SLOW_PX", "STILL_PX", "SlowRefine", "slow_refine_desc"]

#: A frame pair is refined when every tile's median displacement in the previous pair was
#: below this (tile pixels per frame: 1/2 pixel at DIS ultrafast's 1/4 scale).
SLOW_PX = 2.0
#: ... unless every tile's median displacement was below this: a still camera (the flow's
#: noise), where nothing moves for the refinement to read better and it would cost ~25 %
#: more time.
STILL_PX = 0.1
#: Variational-refinement iterations per DIS scale on a slow frame pair.
SLOW_ITERATIONS = 5


def _adaptive(backend) -> bool:
    return isinstance(backend, DISFlow) and backend.preset == "ultrafast" and backend.refine is None


def slow_refine_desc(backend, desc: dict) -> dict:
    """The grid meta's ``flow`` entry of ``backend`` as sphere mode runs it: ``desc`` plus
    ``refine_slow`` where the refinement is adaptive."""
    if not _adaptive(backend):
        return desc
    return {
        **desc,
        "refine_slow": {"below_px": SLOW_PX, "from_px": STILL_PX, "iterations": SLOW_ITERATIONS},
    }


class SlowRefine:
    """Flow of consecutive stacks of tiles, refined when every tile moved slowly in the
    previous call (module docstring); ``backend(prev, cur)`` as given where it is not the
    default DIS ultrafast. One instance per video (it remembers the previous pair)."""

    def __init__(self, backend):
        self.backend = backend
        self._refined = DISFlow("ultrafast", SLOW_ITERATIONS) if _adaptive(backend) else None
        self._last: NDArray[np.float32] | None = None

    def __call__(self, prev: NDArray[np.uint8], cur: NDArray[np.uint8]) -> NDArray[np.float32]:
        if self._refined is None:
            return np.asarray(self.backend(prev, cur), np.float32)
        top = None if self._last is None else float(self._last.max())
        slow = top is not None and STILL_PX <= top < SLOW_PX
        fl = (self._refined if slow else self.backend)(prev, cur)
        sub = fl[:, 2::8, 2::8]
        mag = np.sqrt(sub[..., 0] ** 2 + sub[..., 1] ** 2).reshape(len(fl), -1)
        self._last = np.median(mag, axis=1)
        return fl
