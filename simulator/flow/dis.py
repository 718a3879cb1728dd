"""The OpenCV DIS flow backend (Kroeger et al. 2016), preset ``ultrafast`` by default.

``dis:fast`` and ``dis:medium`` select the other presets; the default was chosen from
measured accuracy and speed, see ``docs/preprocess.md``. ``dis:PRESET+refineN`` adds N
variational-refinement iterations per scale (``dis:ultrafast+refine5``: sub-pixel motion
read better, ~20 % more sphere-mode preprocessing time; ``docs/ego.md``). Deterministic; thread-safe (one
DIS object per thread). The ``ultrafast`` and ``fast`` presets stop at finest scale 2
(flow computed at 1/4 resolution, then upsampled bilinearly): their native stride is 2.
"""

from __future__ import annotations

import threading

import cv2

from simulator.core.choices import DISPreset
from simulator.core.errors import InputError
from simulator.flow.base import FlowBackend, register

__all__ = ["DIS_PRESETS", "DISFlow"]

DIS_PRESETS: dict[str, int] = {
    "ultrafast": cv2.DISOPTICAL_FLOW_PRESET_ULTRAFAST,
    "fast": cv2.DISOPTICAL_FLOW_PRESET_FAST,
    "medium": cv2.DISOPTICAL_FLOW_PRESET_MEDIUM,
}


@register
class DISFlow(FlowBackend):
    """OpenCV DIS optical flow (deterministic; one DIS object per calling thread).

    Parameters
    ----------
    preset : ``"ultrafast"`` (default), ``"fast"`` or ``"medium"``
    refine : variational-refinement iterations (0..100), None = the preset's own
    """

    name = "dis"
    thread_safe = True

    def __init__(self, preset: DISPreset = "ultrafast", refine: int | None = None):
        if preset not in DIS_PRESETS:
            raise InputError(
                f"unknown DIS preset {preset!r}; expected one of {', '.join(DIS_PRESETS)}"
            )
        if refine is not None and not (0 <= int(refine) <= 100):
            raise InputError(f"DIS refinement must be 0..100 iterations; got {refine}")
        self.preset = preset
        self.refine = None if refine is None else int(refine)
        self.params = {"preset": preset, "opencv": cv2.__version__}
        if self.refine is not None:
            self.params["refine"] = self.refine
        self._local = threading.local()

    @property
    def native_stride(self) -> int:
        """2 for ``ultrafast`` and ``fast`` (finest scale 2), 1 for ``medium``."""
        return 2 if self.preset in ("ultrafast", "fast") else 1

    @classmethod
    def from_spec(cls, arg: str, size: tuple[int, int] | None) -> DISFlow:
        """``dis``, ``dis:PRESET`` or ``dis:PRESET+refineN``."""
        preset, plus, extra = (arg or "ultrafast").partition("+")
        if not plus:
            return cls(preset)  # type: ignore[arg-type]
        n = extra.removeprefix("refine")
        if not extra.startswith("refine") or not n.isdigit():
            raise InputError(
                f"--flow dis:{arg}: expected dis:PRESET+refineN (N iterations), e.g. "
                "dis:ultrafast+refine5"
            )
        return cls(preset, int(n))  # type: ignore[arg-type]

    def _dis(self):
        d = getattr(self._local, "dis", None)
        if d is None:
            d = cv2.DISOpticalFlow_create(DIS_PRESETS[self.preset])
            if self.refine is not None:
                d.setVariationalRefinementIterations(self.refine)
            self._local.dis = d
        return d

    def _pair(self, a, b):
        return self._dis().calc(a, b, None)
