"""The OpenCV DIS flow backend (Kroeger et al. 2016), preset ``ultrafast`` by default.

``dis:fast`` and ``dis:medium`` select the other presets; the default was chosen from
measured accuracy and speed, see ``docs/preprocess.md``. Deterministic; thread-safe (one
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
    """

    name = "dis"
    thread_safe = True

    def __init__(self, preset: DISPreset = "ultrafast"):
        if preset not in DIS_PRESETS:
            raise InputError(
                f"unknown DIS preset {preset!r}; expected one of {', '.join(DIS_PRESETS)}"
            )
        self.preset = preset
        self.params = {"preset": preset, "opencv": cv2.__version__}
        self._local = threading.local()

    @property
    def native_stride(self) -> int:
        """2 for ``ultrafast`` and ``fast`` (finest scale 2), 1 for ``medium``."""
        return 2 if self.preset in ("ultrafast", "fast") else 1

    @classmethod
    def from_spec(cls, arg: str, size: tuple[int, int] | None) -> DISFlow:
        """``dis`` or ``dis:PRESET``."""
        return cls(arg or "ultrafast")  # type: ignore[arg-type]

    def _dis(self):
        d = getattr(self._local, "dis", None)
        if d is None:
            d = cv2.DISOpticalFlow_create(DIS_PRESETS[self.preset])
            self._local.dis = d
        return d

    def _pair(self, a, b):
        return self._dis().calc(a, b, None)
