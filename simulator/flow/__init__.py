"""Optical-flow backends: one module per backend over a base with a registry, and ray angles for flow in deg/s.

Layout: :mod:`~simulator.flow.registry` (the light table the CLI reads: names, ``--flow``
spellings, help), :mod:`~simulator.flow.base` (:class:`FlowBackend`, :func:`register`,
:func:`make_backend`), one module per backend (:mod:`~simulator.flow.dis`,
:mod:`~simulator.flow.farneback`, :mod:`~simulator.flow.torchscript`) and
:mod:`~simulator.flow.rays` (:class:`RayAngles`). The names below are loaded lazily, so
``import simulator.flow.registry`` stays free of numpy and OpenCV.
"""

from __future__ import annotations

import importlib

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

_WHERE = {
    "DIS_PRESETS": "dis",
    "DISFlow": "dis",
    "FarnebackFlow": "farneback",
    "TorchFlow": "torchscript",
    "FlowBackend": "base",
    "make_backend": "base",
    "native_stride": "base",
    "RayAngles": "rays",
    "FLOW_CHOICES": "registry",
}


def __getattr__(name: str):
    if name not in _WHERE:
        raise AttributeError(f"module 'simulator.flow' has no attribute {name!r}")
    return getattr(importlib.import_module(f"simulator.flow.{_WHERE[name]}"), name)
