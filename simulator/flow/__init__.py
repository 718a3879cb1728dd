"""Optical-flow backends: a base class, the DIS, Farneback and TorchScript backends, and ray angles for flow in deg/s.
"""

from simulator.flow.backends import (
    DIS_PRESETS,
    FLOW_CHOICES,
    DISFlow,
    FarnebackFlow,
    FlowBackend,
    RayAngles,
    TorchFlow,
    make_backend,
)

__all__ = [
    "DIS_PRESETS",
    "FLOW_CHOICES",
    "DISFlow",
    "FarnebackFlow",
    "FlowBackend",
    "RayAngles",
    "TorchFlow",
    "make_backend",
]
