"""The flow-backend interface, the registry of backend classes and :func:`make_backend`.

A backend takes a batch of ``N`` window pairs and returns their dense flow::

    flow = backend(prev, nxt)   # prev, nxt: (N, h, w) uint8 gray -> (N, h, w, 2) float32

``flow[n, y, x] = (dx, dy)`` in **window pixels per frame**: the content at pixel
``(x, y)`` of ``prev[n]`` (image coordinates, +x right, +y down, origin top-left) is at
``(x + dx, y + dy)`` in ``nxt[n]``.

Each backend is one module of :mod:`simulator.flow` (``dis``, ``farneback``,
``torchscript``): a subclass of :class:`FlowBackend` that declares its
:attr:`~FlowBackend.native_stride` (the pixel step at which its flow carries independent
information; paper and sphere mode read the flow at that step) and a
:meth:`~FlowBackend.from_spec` constructor, decorated with :func:`register`. The CLI's
spellings and help come from :mod:`simulator.flow.registry`, which names the module;
:func:`make_backend` imports it on first use.
"""

from __future__ import annotations

import importlib

import numpy as np
from numpy.typing import NDArray

from simulator.core.errors import InputError
from simulator.flow.registry import FLOW_CHOICES, entry

__all__ = ["FlowBackend", "backend_class", "make_backend", "native_stride", "register"]

_CLASSES: dict[str, type[FlowBackend]] = {}


def _check_pair(prev: NDArray, nxt: NDArray) -> tuple[NDArray, NDArray]:
    prev = np.asarray(prev)
    nxt = np.asarray(nxt)
    if prev.ndim == 2:
        prev, nxt = prev[None], nxt[None]
    if prev.shape != nxt.shape or prev.ndim != 3 or prev.dtype != np.uint8 or nxt.dtype != np.uint8:
        raise ValueError(
            f"flow input must be two (N, h, w) uint8 arrays of one shape; got {prev.shape} "
            f"{prev.dtype} and {nxt.shape} {nxt.dtype}"
        )
    return prev, nxt


class FlowBackend:
    """Base class: dense flow for a batch of gray window pairs.

    Attributes
    ----------
    name : str
        Method name recorded in the grid file and spelled by ``--flow`` (``"dis"``,
        ``"farneback"``, ``"torch"``); the key of its :mod:`simulator.flow.registry` entry.
    params : dict
        Everything that determines the result, JSON-serialisable (recorded in ``meta``).
    thread_safe : bool
        True when several threads may call the backend at once (the caller then splits a
        frame's windows over a thread pool); False for backends that parallelise inside
        (torch) and want the whole batch.
    """

    name: str = ""
    params: dict
    thread_safe: bool = True

    @property
    def native_stride(self) -> int:
        """Pixel step at which this backend's flow carries independent values: paper and
        sphere mode read every ``native_stride``-th pixel (1: every pixel)."""
        return 1

    @classmethod
    def from_spec(cls, arg: str, size: tuple[int, int] | None) -> FlowBackend:
        """The backend from the text after ``:`` in ``--flow`` (``""`` when none) and the
        (width, height) of the images it will be given (None: unknown)."""
        raise NotImplementedError

    def __call__(self, prev: NDArray[np.uint8], nxt: NDArray[np.uint8]) -> NDArray[np.float32]:
        """Flow of each pair.

        Parameters
        ----------
        prev, nxt : ndarray, shape (N, h, w), uint8
            Gray windows of frames t-1 and t.

        Returns
        -------
        flow : ndarray, shape (N, h, w, 2), float32
            ``(dx, dy)`` in window pixels per frame (+x right, +y down).
        """
        prev, nxt = _check_pair(prev, nxt)
        out = np.empty((*prev.shape, 2), np.float32)
        for i in range(prev.shape[0]):
            out[i] = self._pair(prev[i], nxt[i])
        return out

    def pair(self, a: NDArray[np.uint8], b: NDArray[np.uint8]) -> NDArray[np.float32]:
        """Flow of one pair, ``(h, w)`` C-contiguous uint8 each (not checked: the fast path
        for callers that already hold such windows), ``(h, w, 2)`` float32 (a fresh array,
        no copy into a batch). Thread-safe backends only; same values as ``__call__``."""
        return self._pair(a, b)

    def _pair(self, a: NDArray[np.uint8], b: NDArray[np.uint8]) -> NDArray[np.float32]:
        raise NotImplementedError

    def describe(self) -> dict:
        """``{"method": name, **params}``: the ``flow`` entry of a grid file's meta."""
        return {"method": self.name, **self.params}


def register(cls: type[FlowBackend]) -> type[FlowBackend]:
    """Class decorator: make ``cls`` the backend of its ``name``'s registry entry."""
    if entry(cls.name) is None:
        raise ValueError(f"flow backend {cls.name!r} has no entry in simulator.flow.registry")
    _CLASSES[cls.name] = cls
    return cls


def backend_class(name: str) -> type[FlowBackend] | None:
    """The registered class of a backend name (importing its module), or None."""
    e = entry(name)
    if e is None:
        return None
    if e.name not in _CLASSES:
        importlib.import_module(f"simulator.flow.{e.module}")
    return _CLASSES.get(e.name)


def make_backend(spec: str, size: tuple[int, int] | None = None) -> FlowBackend:
    """A backend from its ``--flow`` text (:data:`simulator.flow.registry.FLOW_CHOICES`:
    ``dis``, ``dis:PRESET``, ``farneback``, ``torch:MODEL.pt``). Raises InputError for
    anything else. ``size``: (width, height) of the images it will be given (a torch model
    is checked at that size)."""
    text = str(spec).strip()
    kind, _, arg = text.partition(":")
    cls = backend_class(kind)
    if cls is None:
        raise InputError(f"unknown flow backend {text!r}; expected one of {FLOW_CHOICES}")
    return cls.from_spec(arg, size)


def native_stride(backend) -> int:
    """The declared native stride of a backend (:attr:`FlowBackend.native_stride`); 1 for
    a plain flow function."""
    return max(1, int(getattr(backend, "native_stride", 1)))
