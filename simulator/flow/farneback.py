"""The OpenCV Farneback flow backend: slower than DIS, for comparison.
"""

from __future__ import annotations

from typing import ClassVar

import cv2

from simulator.core.errors import InputError
from simulator.flow.base import FlowBackend, register

__all__ = ["FarnebackFlow"]


@register
class FarnebackFlow(FlowBackend):
    """OpenCV Farneback dense flow (pyramid 0.5, 3 levels, window 15, 3 iterations,
    poly_n 5, poly_sigma 1.2)."""

    name = "farneback"
    thread_safe = True
    _ARGS: ClassVar[dict] = {
        "pyr_scale": 0.5,
        "levels": 3,
        "winsize": 15,
        "iterations": 3,
        "poly_n": 5,
        "poly_sigma": 1.2,
    }

    @classmethod
    def from_spec(cls, arg: str, size: tuple[int, int] | None) -> FarnebackFlow:
        """``farneback`` (takes no argument)."""
        if arg:
            raise InputError(f"--flow farneback takes no argument; got farneback:{arg}")
        return cls()

    def __init__(self):
        self.params = {**self._ARGS, "opencv": cv2.__version__}

    def _pair(self, a, b):
        k = self._ARGS
        return cv2.calcOpticalFlowFarneback(
            a,
            b,
            None,
            k["pyr_scale"],
            k["levels"],
            k["winsize"],
            k["iterations"],
            k["poly_n"],
            k["poly_sigma"],
            0,
        )
