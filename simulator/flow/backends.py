"""The former single module of the flow backends, kept importable: its names now live one module per backend.

New code imports from :mod:`simulator.flow.base`, :mod:`simulator.flow.dis`,
:mod:`simulator.flow.farneback`, :mod:`simulator.flow.torchscript` and
:mod:`simulator.flow.rays`.
"""

from __future__ import annotations

from simulator.flow.base import FlowBackend, make_backend, native_stride
from simulator.flow.dis import DIS_PRESETS, DISFlow
from simulator.flow.farneback import FarnebackFlow
from simulator.flow.rays import RayAngles
from simulator.flow.registry import FLOW_CHOICES
from simulator.flow.torchscript import TorchFlow

__all__ = [
    "DIS_PRESETS",
    "FLOW_CHOICES",
    "DISFlow",
    "FarnebackFlow",
    "FlowBackend",
    "RayAngles",
    "TorchFlow",
    "make_backend",
    "native_stride",
]
