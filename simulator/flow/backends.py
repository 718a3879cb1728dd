"""Optical-flow backends behind one small interface.

A backend takes a batch of ``N`` window pairs and returns their dense flow::

    flow = backend(prev, nxt)   # prev, nxt: (N, h, w) uint8 gray -> (N, h, w, 2) float32

``flow[n, y, x] = (dx, dy)`` in **window pixels per frame**: the content at pixel
``(x, y)`` of ``prev[n]`` (image coordinates, +x right, +y down, origin top-left) is at
``(x + dx, y + dy)`` in ``nxt[n]``.

:class:`RayAngles` turns pixel flow inside a perspective view into the angle (radians)
between the ray of each pixel centre and the ray of its flow target: the one formula
behind paper mode's deg/s (:mod:`simulator.preprocess`) and sphere mode's field
(:mod:`simulator.preprocess.sphere`).

Backends (:func:`make_backend` parses the ``--flow`` text):

``dis`` (default)
    OpenCV's DIS (Kroeger et al. 2016), preset ``ultrafast`` by default
    (``dis:fast``, ``dis:medium`` select others): the preset was chosen from measured
    accuracy and speed, see ``docs/preprocess.md``. Deterministic; thread-safe (one DIS
    object per thread).
``farneback``
    OpenCV's Farneback (pyramid 0.5, 3 levels, window 15, 3 iterations, poly_n 5,
    sigma 1.2); slower, for comparison.
``torch:MODEL.pt``
    A TorchScript model taking two ``(N, 3, H, W)`` float tensors in ``[0, 1]`` (RGB;
    gray windows are repeated over the 3 channels) and returning ``(N, 2, H, W)`` pixel
    flow ``(dx, dy)``. Run in batches on CUDA when available, else CPU. torch is
    imported only here (optional dependency). ``docs/preprocess.md`` shows how to export
    RAFT (torchvision) or FlowNet2 to this interface.
"""

from __future__ import annotations

import math
import threading
from pathlib import Path
from typing import ClassVar

import cv2
import numpy as np
from numpy.typing import NDArray

from simulator.core.choices import FLOW_CHOICES, DISPreset
from simulator.core.errors import InputError
from simulator.sphere.geometry import check_fov

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

DIS_PRESETS: dict[str, int] = {
    "ultrafast": cv2.DISOPTICAL_FLOW_PRESET_ULTRAFAST,
    "fast": cv2.DISOPTICAL_FLOW_PRESET_FAST,
    "medium": cv2.DISOPTICAL_FLOW_PRESET_MEDIUM,
}


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
        Method name recorded in the grid file (``"dis"``, ``"farneback"``, ``"torch"``).
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

    def _dis(self):
        d = getattr(self._local, "dis", None)
        if d is None:
            d = cv2.DISOpticalFlow_create(DIS_PRESETS[self.preset])
            self._local.dis = d
        return d

    def _pair(self, a, b):
        return self._dis().calc(a, b, None)


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


class TorchFlow(FlowBackend):
    """A TorchScript flow model: ``model(img1, img2)`` with ``(N, 3, H, W)`` float
    tensors in ``[0, 1]`` returns ``(N, 2, H, W)`` pixel flow ``(dx, dy)``.

    Parameters
    ----------
    path : the TorchScript file (``torch.jit.save``)
    device : ``"cuda"`` / ``"cpu"``; default CUDA when available
    batch : windows per forward pass (memory bound; all of a frame's windows are
        processed, ``batch`` at a time)
    probe_size : (width, height) of the pair the model is checked with on load: the size
        it will be given (the window size; ``preprocess`` and sphere mode pass theirs);
        ``None``: 64 x 64.
        Models have minimum sizes (RAFT: 128 px) or fixed ones (a traced FlowNet2).

    The model is checked on load with a ``(1, 3, h, w)`` pair of ``probe_size``:
    anything but a ``(1, 2, h, w)`` floating tensor raises InputError "not a flow model",
    with the model's own last error line when it raises (e.g. RAFT's "should be at least
    8 * 16 = 128").
    """

    name = "torch"
    thread_safe = False

    def __init__(
        self,
        path: str | Path,
        *,
        device: str | None = None,
        batch: int = 32,
        probe_size: tuple[int, int] | None = None,
    ):
        try:
            import torch
        except ImportError:
            raise InputError(
                f"{path}: the torch flow backend needs PyTorch; install it (pip install torch) "
                "or use --flow dis"
            ) from None
        p = Path(path)
        if not p.is_file():
            raise InputError(f"{p}: TorchScript flow model file not found")
        self._torch = torch
        self.device = device or ("cuda" if torch.cuda.is_available() else "cpu")
        try:
            self.model = torch.jit.load(str(p), map_location=self.device).eval()
        except Exception as e:  # noqa: BLE001 - torch raises many types for a bad file
            first = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
            raise InputError(f"{p}: not a TorchScript model ({first})") from None
        if batch < 1:
            raise InputError(f"torch flow batch must be >= 1; got {batch}")
        self.batch = int(batch)
        self.params = {"model": str(p), "model_bytes": p.stat().st_size, "device": self.device}
        self._path = p
        w, h = probe_size or (64, 64)
        self._validate(int(w), int(h))

    def _validate(self, w: int, h: int) -> None:
        torch = self._torch
        # Random noise and the same moved by one pixel: some models misbehave on constants.
        g = torch.Generator().manual_seed(0)
        a = torch.rand(1, 3, h + 1, w + 1, generator=g)
        x, y0 = a[..., :h, :w].to(self.device), a[..., 1:, 1:].to(self.device)
        try:
            with torch.inference_mode():
                y = self.model(x, y0)
        except Exception as e:  # noqa: BLE001 - any failure of the user's model
            # TorchScript puts the interpreter's frame first and the model's reason last.
            lines = [ln.strip() for ln in str(e).strip().splitlines() if ln.strip()]
            why = lines[-1] if lines else type(e).__name__
            raise InputError(
                f"{self._path}: not a flow model for {w}x{h} px windows: calling it with two "
                f"(1, 3, {h}, {w}) tensors failed ({why[:300]})"
            ) from None
        shape = tuple(y.shape) if isinstance(y, torch.Tensor) else type(y).__name__
        if not isinstance(y, torch.Tensor) or shape != (1, 2, h, w) or not y.is_floating_point():
            raise InputError(
                f"{self._path}: not a flow model: two (1, 3, {h}, {w}) inputs gave {shape}; "
                f"expected a (1, 2, {h}, {w}) float tensor (see docs/preprocess.md for the interface)"
            )

    def __call__(self, prev, nxt):
        torch = self._torch
        prev, nxt = _check_pair(prev, nxt)
        N, h, w = prev.shape
        out = np.empty((N, h, w, 2), np.float32)
        with torch.inference_mode():
            for s in range(0, N, self.batch):
                a = torch.from_numpy(np.ascontiguousarray(prev[s : s + self.batch])).to(self.device)
                b = torch.from_numpy(np.ascontiguousarray(nxt[s : s + self.batch])).to(self.device)
                a = (a.float() / 255.0)[:, None].expand(-1, 3, -1, -1).contiguous()
                b = (b.float() / 255.0)[:, None].expand(-1, 3, -1, -1).contiguous()
                f = self.model(a, b)
                if tuple(f.shape) != (a.shape[0], 2, h, w):
                    raise InputError(
                        f"{self._path}: not a flow model: gave {tuple(f.shape)} for {tuple(a.shape)} inputs"
                    )
                out[s : s + self.batch] = f.float().permute(0, 2, 3, 1).cpu().numpy()
        return out


def make_backend(spec: str, size: tuple[int, int] | None = None) -> FlowBackend:
    """A backend from its ``--flow`` text: ``dis``, ``dis:PRESET``, ``farneback`` or
    ``torch:MODEL.pt``. Raises InputError for anything else. ``size``: (width, height) of
    the images it will be given (a torch model is checked at that size)."""
    text = str(spec).strip()
    kind, _, arg = text.partition(":")
    kind = kind.lower()
    if kind == "dis":
        return DISFlow(arg or "ultrafast")  # type: ignore[arg-type]
    if kind == "farneback" and not arg:
        return FarnebackFlow()
    if kind == "torch":
        if not arg:
            raise InputError("--flow torch needs a model file: torch:MODEL.pt")
        return TorchFlow(arg, probe_size=size)
    raise InputError(f"unknown flow backend {text!r}; expected one of {FLOW_CHOICES}")


class RayAngles:
    """Angle between each pixel's ray and its flow target's ray, in a perspective view.

    Rays follow :func:`simulator.sphere.geometry.perspective_rays`: the pixel centre ``(i, j)``
    (column, row) has its ray ``r0 = (u0, v0, 1)`` through the plane ``z = 1`` at
    ``u0 = ((i + 0.5) / w * 2 - 1) tan(hfov / 2)`` (+ right) and
    ``v0 = (1 - (j + 0.5) / h * 2) tan(vfov / 2)`` (+ up). A flow ``(dx, dy)`` in pixels
    (+x right, +y down) moves it to ``r1 = r0 + (dx * 2 tan(hfov/2) / w,
    -dy * 2 tan(vfov/2) / h, 0)``; targets outside the view still have a ray. The angle is
    ``atan2(|r0 x r1|, r0 . r1)`` (exact at any angle), the ``atan2`` evaluated by OpenCV's
    vectorised ``phase`` (relative error < 3e-4, 30x faster than numpy's), float32.

    Parameters
    ----------
    size : (w, h), pixels of the view
    hfov_deg, vfov_deg : float, degrees in (0, 180); exact FOVs (``vfov_deg`` defaults to
        ``hfov_deg``)
    stride : int >= 1, keyword-only
        Evaluate every ``stride``-th pixel only: columns and rows ``stride // 2,
        stride // 2 + stride, ...`` (``sel``); the flow passed in is still full size.

    Attributes
    ----------
    u0, v0 : ndarray, shape (h', w'), float32, read-only; plane coordinates (tan units)
    sel : slice selecting the evaluated rows (and columns) of a full-size array
    """

    def __init__(
        self,
        size: tuple[int, int],
        hfov_deg: float,
        vfov_deg: float | None = None,
        *,
        stride: int = 1,
    ):
        w, h = int(size[0]), int(size[1])
        if w < 1 or h < 1:
            raise InputError(f"view size must be positive (w, h) pixels; got {size!r}")
        hf, vf = check_fov(hfov_deg, vfov_deg)
        st = int(stride)
        if st < 1:
            raise InputError(f"flow stride must be >= 1 pixel; got {stride}")
        tx = math.tan(math.radians(hf) / 2.0)
        ty = math.tan(math.radians(vf) / 2.0)
        u = ((np.arange(w) + 0.5) / w * 2.0 - 1.0) * tx
        v = (1.0 - (np.arange(h) + 0.5) / h * 2.0) * ty
        self.sel = slice(st // 2, None, st)
        uu, vv = np.meshgrid(u[self.sel], v[self.sel])
        self.size = (w, h)
        self.stride = st
        self.u0 = uu.astype(np.float32)
        self.v0 = vv.astype(np.float32)
        self._a = (1.0 + uu * uu + vv * vv).astype(np.float32)  # r0 . r0
        for arr in (self.u0, self.v0, self._a):
            arr.setflags(write=False)
        # Pixel steps of u and v: +x right = +u, +y down = -v.
        self._cx = np.float32(2.0 * tx / w)
        self._cy = np.float32(-2.0 * ty / h)
        self._local = threading.local()

    def _scratch(self, shape: tuple[int, ...]) -> list[NDArray[np.float32]]:
        """Seven float32 scratch arrays of ``shape`` for the calling thread (reused: fresh
        temporaries cost a page-faulting mmap each, more than the arithmetic)."""
        bufs = getattr(self._local, "bufs", None)
        if bufs is None or bufs[0].shape != shape:
            bufs = [np.empty(shape, np.float32) for _ in range(7)]
            self._local.bufs = bufs
        return bufs

    def into_scratch(
        self, flow: NDArray[np.float32], *, magnitude: bool = False
    ) -> tuple[NDArray[np.float32], NDArray[np.float32] | None]:
        """:meth:`__call__` without the copy: ``(angles, |flow| or None)`` as views into
        this thread's scratch arrays, overwritten by the thread's next call.

        ``flow`` is ``(..., h, w, 2)`` pixels (full size, also when ``stride > 1``);
        ``magnitude=True`` also gives ``sqrt(dx^2 + dy^2)`` (pixels) of the evaluated pixels.
        """
        w, h = self.size
        if flow.shape[-3:] != (h, w, 2):
            raise ValueError(f"flow must be (..., {h}, {w}, 2); got {flow.shape}")
        if self.stride > 1:
            flow = flow[..., self.sel, self.sel, :]
        fx, fy, du, dv, t, u, mag = self._scratch(flow.shape[:-1])
        np.copyto(fx, flow[..., 0])
        np.copyto(fy, flow[..., 1])
        np.multiply(fx, fx, out=t)
        np.multiply(fy, fy, out=u)
        if magnitude:
            np.add(t, u, out=mag)
            np.sqrt(mag, out=mag)
        np.multiply(fx, self._cx, out=du)
        np.multiply(fy, self._cy, out=dv)
        # |r0 x r1|^2 = du^2 + dv^2 + (u0 dv - v0 du)^2 with r = (u, v, 1)
        np.multiply(t, self._cx * self._cx, out=t)
        np.multiply(u, self._cy * self._cy, out=u)
        np.add(t, u, out=t)
        np.multiply(self.u0, dv, out=u)
        np.multiply(self.v0, du, out=fx)
        np.subtract(u, fx, out=u)
        np.multiply(u, u, out=u)
        np.add(t, u, out=t)
        np.sqrt(t, out=t)
        # r0 . r1 = 1 + u0^2 + v0^2 + u0 du + v0 dv
        np.multiply(self.u0, du, out=u)
        np.multiply(self.v0, dv, out=fy)
        np.add(u, fy, out=u)
        np.add(u, self._a, out=u)
        # atan2(|cross|, dot) in [0, pi]; OpenCV wants 2-D arrays (views, no copy).
        cols = fx.shape[-1]
        ang = cv2.phase(u.reshape(-1, cols), t.reshape(-1, cols), fx.reshape(-1, cols))
        return ang.reshape(fx.shape), (mag if magnitude else None)

    def __call__(self, flow: NDArray[np.float32]) -> NDArray[np.float32]:
        """Angles in **radians**, ``(..., h', w')`` float32, of pixel flow ``(..., h, w, 2)``
        (+x right, +y down); ``(h', w') = (h, w)`` unless ``stride > 1``."""
        ang, _ = self.into_scratch(np.asarray(flow, np.float32))
        return ang.copy()
