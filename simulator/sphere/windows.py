"""The paper's sliding-window grid (section 3.3) and the extraction of every window of a frame.

Window centres in degrees (yaw + right, pitch + up; windows have no roll); each window is a
perspective view with exact FOVs (:func:`simulator.sphere.geometry.perspective_map`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

import cv2
import numpy as np
from numpy.typing import NDArray

from simulator.core.errors import InputError
from simulator.core.mapcache import cached_arrays
from simulator.sphere.geometry import (
    _PAD,
    _check_size,
    check_fov,
    dir_to_lonlat,
    head_rotation,
    lonlat_to_equirect_xy,
    pad_equirect,
    perspective_rays,
)

__all__ = ["GRID_PRESETS", "WindowExtractor", "WindowGrid", "grid_preset"]


@dataclass(frozen=True)
class WindowGrid:
    """The sliding-window grid of the paper (section 3.2), in degrees.

    Window centres: yaw ``yaw_start_deg + k * yaw_step_deg`` for k < 360 / yaw_step_deg
    (wrapping), pitch from ``pitch_min_deg`` to ``pitch_max_deg`` in ``pitch_step_deg``
    steps. Each window is a perspective view with no roll, ``hfov_deg x vfov_deg``
    (exact FOVs), sampled at ``size`` pixels.

    Presets (:data:`GRID_PRESETS`): ``default`` = 15 deg yaw x 7.5 deg pitch steps, pitch
    -37.5..37.5 (24 x 11 = 264 windows); ``paper-198`` = 20 deg yaw steps (18 x 11);
    ``cao2021`` = the authors' code: 15 x 15 deg steps, pitch -90..90 with the poles
    (24 x 13 = 312), 107 deg wide at 1600 x 1440 px with the *linear* vertical FOV
    1440 / 1600 x 107 = 96.3 deg (square pixels would give 101.1).
    """

    yaw_step_deg: float = 15.0
    pitch_step_deg: float = 7.5
    pitch_min_deg: float = -37.5
    pitch_max_deg: float = 37.5
    yaw_start_deg: float = -180.0
    hfov_deg: float = 107.0
    vfov_deg: float = 107.0
    size: tuple[int, int] = (256, 256)
    yaw_deg: NDArray = field(init=False, repr=False, compare=False)
    pitch_deg: NDArray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        check_fov(self.hfov_deg, self.vfov_deg)
        _check_size(self.size)
        object.__setattr__(self, "size", (int(self.size[0]), int(self.size[1])))
        if not (0 < self.yaw_step_deg <= 360):
            raise InputError(f"grid yaw step must be in (0, 360] degrees; got {self.yaw_step_deg}")
        n_yaw = 360.0 / self.yaw_step_deg
        if abs(n_yaw - round(n_yaw)) > 1e-6:
            raise InputError(f"grid yaw step must divide 360 degrees; got {self.yaw_step_deg}")
        if not (self.pitch_step_deg > 0):
            raise InputError(f"grid pitch step must be > 0 degrees; got {self.pitch_step_deg}")
        if not (-90 <= self.pitch_min_deg <= self.pitch_max_deg <= 90):
            raise InputError(
                f"grid pitch range must satisfy -90 <= min <= max <= 90; got {self.pitch_min_deg}..{self.pitch_max_deg}"
            )
        yaw = self.yaw_start_deg + self.yaw_step_deg * np.arange(round(n_yaw))
        yaw = (yaw + 180.0) % 360.0 - 180.0
        n_p = math.floor((self.pitch_max_deg - self.pitch_min_deg) / self.pitch_step_deg + 1e-9) + 1
        pitch = self.pitch_min_deg + self.pitch_step_deg * np.arange(n_p)
        yaw.setflags(write=False)
        pitch.setflags(write=False)
        object.__setattr__(self, "yaw_deg", yaw)
        object.__setattr__(self, "pitch_deg", pitch)

    @property
    def shape(self) -> tuple[int, int]:
        """``(P, Y)``: number of pitch rows and yaw columns (the grid file's axis order)."""
        return len(self.pitch_deg), len(self.yaw_deg)

    @property
    def n_windows(self) -> int:
        return len(self.pitch_deg) * len(self.yaw_deg)

    def centres_deg(self) -> tuple[NDArray, NDArray]:
        """``(pitch, yaw)`` of every window, each shape ``(P, Y)``, degrees."""
        return np.meshgrid(self.pitch_deg, self.yaw_deg, indexing="ij")

    def to_dict(self) -> dict:
        return {
            "yaw_step_deg": self.yaw_step_deg,
            "pitch_step_deg": self.pitch_step_deg,
            "pitch_min_deg": self.pitch_min_deg,
            "pitch_max_deg": self.pitch_max_deg,
            "yaw_start_deg": self.yaw_start_deg,
            "hfov_deg": self.hfov_deg,
            "vfov_deg": self.vfov_deg,
            "size": list(self.size),
        }

    @classmethod
    def from_dict(cls, d: dict) -> WindowGrid:
        d = dict(d)
        if "size" in d:
            d["size"] = tuple(d["size"])
        return cls(**d)


GRID_PRESETS: dict[str, dict] = {
    "default": {
        "yaw_step_deg": 15.0,
        "pitch_step_deg": 7.5,
        "pitch_min_deg": -37.5,
        "pitch_max_deg": 37.5,
    },
    "paper-198": {
        "yaw_step_deg": 20.0,
        "pitch_step_deg": 7.5,
        "pitch_min_deg": -37.5,
        "pitch_max_deg": 37.5,
    },
    # The authors' Unity preprocessing (docs/parity.md): its FOV and window size are the
    # preset's own defaults (a caller's hfov/vfov/size still win).
    "cao2021": {
        "yaw_step_deg": 15.0,
        "pitch_step_deg": 15.0,
        "pitch_min_deg": -90.0,
        "pitch_max_deg": 90.0,
        "hfov_deg": 107.0,
        "vfov_deg": 1440.0 / 1600.0 * 107.0,
        "size": (1600, 1440),
    },
}


def grid_preset(
    name: str = "default",
    *,
    hfov_deg: float | None = None,
    vfov_deg: float | None = None,
    size: tuple[int, int] | None = None,
) -> WindowGrid:
    """A :class:`WindowGrid` from a preset name (``default``, ``paper-198``, ``cao2021``).

    ``hfov_deg`` (default the preset's, else 107), ``vfov_deg`` (default ``hfov_deg`` when
    that is given, else the preset's, else 107) and ``size`` (default the preset's, else
    256 x 256) override the preset's window."""
    if name not in GRID_PRESETS:
        raise InputError(f"unknown grid preset {name!r}; expected one of {', '.join(GRID_PRESETS)}")
    steps = dict(GRID_PRESETS[name])
    h_pre, v_pre = steps.pop("hfov_deg", 107.0), steps.pop("vfov_deg", 107.0)
    size_pre = steps.pop("size", (256, 256))
    if vfov_deg is None:
        vfov_deg = v_pre if hfov_deg is None else hfov_deg
    return WindowGrid(
        **steps,
        hfov_deg=h_pre if hfov_deg is None else hfov_deg,
        vfov_deg=vfov_deg,
        size=size_pre if size is None else size,
    )


class WindowExtractor:
    """Extract every window of a :class:`WindowGrid` from equirect frames of one size, fast.

    The sampling maps of all windows are built once (per grid and frame size; cached in
    the user cache folder, :mod:`simulator.core.mapcache`), stacked window after window into
    tall maps in OpenCV's fixed-point form, so that every frame is a few ``cv2.remap``
    calls (seam wrap, pole crossing) writing each window contiguously: the
    ``(P, Y, h, w)`` result needs no rearranging copy and can be written into a reused
    buffer (``out=``).

    Parameters
    ----------
    grid : WindowGrid
    equirect_size : (W, H), pixels of one eye's equirect frame (stored pixels)
    cache : bool, keyword-only; False: build the maps without reading or writing the
        cache (``--no-cache``)

    Attributes
    ----------
    maps_source : ``"memory"`` (built or loaded earlier in this process), ``"hit"``
        (loaded from the cache), ``"built"`` (built and stored) or ``"uncached"``

    Call with an ``(H, W)`` or ``(H, W, C)`` frame; returns ``(P, Y, h, w[, C])``, C-contiguous.
    """

    def __init__(self, grid: WindowGrid, equirect_size: tuple[int, int], *, cache: bool = True):
        self.grid = grid
        self.equirect_size = _check_size(equirect_size)
        self._m1, self._m2, self.maps_source = _window_maps(grid, self.equirect_size, cache)
        h = grid.size[1]
        per = max(1, (_MAX_SIDE - 1) // h)  # windows per remap call (OpenCV side limit)
        n = grid.n_windows
        self._calls = [(a, min(n, a + per)) for a in range(0, n, per)]

    def __call__(
        self,
        frame: NDArray,
        *,
        interp: Literal["cubic", "linear"] = "cubic",
        out: NDArray | None = None,
    ) -> NDArray:
        """All windows of ``frame``; ``out``: a C-contiguous ``(P, Y, h, w[, C])`` array
        of the frame's dtype to write into (returned), e.g. a buffer reused per frame."""
        H, W = frame.shape[:2]
        if (W, H) != self.equirect_size:
            raise InputError(
                f"frame is {W}x{H}; this extractor was built for {self.equirect_size[0]}x{self.equirect_size[1]}"
            )
        flags = cv2.INTER_CUBIC if interp == "cubic" else cv2.INTER_LINEAR
        padded = pad_equirect(np.ascontiguousarray(frame))
        P, Y = self.grid.shape
        w, h = self.grid.size
        shape = (P, Y, h, w, *padded.shape[2:])
        if out is None:
            out = np.empty(shape, padded.dtype)
        elif out.shape != shape or out.dtype != padded.dtype or not out.flags.c_contiguous:
            raise ValueError(
                f"out must be C-contiguous {shape} {padded.dtype}; got {out.shape} {out.dtype}"
            )
        flat = out.reshape(P * Y * h, w, *padded.shape[2:])
        for a, b in self._calls:
            rows = slice(a * h, b * h)
            cv2.remap(
                padded,
                self._m1[rows],
                self._m2[rows],
                flags,
                dst=flat[rows],
                borderMode=cv2.BORDER_REPLICATE,
            )
        return out


#: OpenCV's remap limits each side of its maps to < 32767 pixels.
_MAX_SIDE = 32767
#: Layout of the cached maps; bump when the map construction changes.
_MAP_LAYOUT = "window-major-fixed-point-1"


def _window_maps(grid: WindowGrid, equirect_size: tuple[int, int], cache: bool = True):
    """``(m1, m2, source)``: fixed-point remap maps of all windows, stacked window after
    window ``(P*Y*h, w)`` (window ``k = p * Y + y``), from memory, the cache or built."""
    key = (grid, equirect_size)
    hit = _MEMO.get(key)
    if hit is not None:
        return (*hit, "memory")
    ckey = {
        "kind": "window-maps",
        "layout": _MAP_LAYOUT,
        "grid": grid.to_dict(),
        "equirect_size": list(equirect_size),
        "opencv": cv2.__version__,
        "numpy": np.__version__,
    }
    arrays, how = cached_arrays(
        ckey, lambda: _build_window_maps(grid, equirect_size), use_cache=cache
    )
    m1, m2 = arrays["m1"], arrays["m2"]
    (P, Y), (w, h) = grid.shape, grid.size
    if (
        m1.shape != (P * Y * h, w, 2)
        or m1.dtype != np.int16
        or m2.shape != (P * Y * h, w)
        or m2.dtype != np.uint16
    ):
        arrays, how = _build_window_maps(grid, equirect_size), "uncached"  # foreign entry
        m1, m2 = arrays["m1"], arrays["m2"]
    m1.setflags(write=False)
    m2.setflags(write=False)
    if len(_MEMO) >= 4:
        _MEMO.pop(next(iter(_MEMO)))
    _MEMO[key] = (m1, m2)
    return m1, m2, how


_MEMO: dict = {}


def _build_window_maps(grid: WindowGrid, equirect_size: tuple[int, int]) -> dict:
    """Fixed-point remap maps of all windows, ``{"m1": (P*Y*h, w, 2) int16, "m2": (P*Y*h, w) uint16}``.

    Windows have no roll, so a window at yaw ``psi`` samples the equirect exactly where the
    window at yaw 0 and the same pitch does, shifted by ``psi`` in longitude: the
    trigonometry runs once per pitch row (P windows, float64), every yaw column is then a
    shift of the column coordinate, wrapped (float64 for the wrap, float32 maps), instead
    of one rotation and ``atan2``/``asin`` per pixel of every window.
    """
    W, H = equirect_size
    dirs, _ = perspective_rays(grid.size, grid.hfov_deg, grid.vfov_deg)
    (P, Y), (w, h) = grid.shape, grid.size
    if h >= _MAX_SIDE or w >= _MAX_SIDE:
        raise InputError(f"windows of {w}x{h} px are too large for one remap; use smaller windows")
    R = head_rotation(np.zeros(P), grid.pitch_deg, 0.0).as_matrix()  # (P, 3, 3)
    world = np.einsum("nij,hwj->nhwi", R, dirs.astype(np.float64))  # (P, h, w, 3)
    lon, lat = dir_to_lonlat(world)
    x0, y0 = lonlat_to_equirect_xy(lon, lat, W, H)
    x0 -= 0.5  # array-index convention (unpadded), as equirect_remap_coords
    my0 = (y0 - 0.5 + _PAD).astype(np.float32)
    shift = np.asarray(grid.yaw_deg, np.float64) / 360.0 * W  # px per yaw column
    mx = np.empty((P, Y, h, w), np.float32)
    for k, s in enumerate(shift):
        # Same wrap as lon in (-pi, pi]: continuous x in (0, W], index x - 0.5 in (-0.5, W - 0.5].
        x = x0 + s
        x -= W * np.floor((x + 0.5) / W)
        x[x <= -0.5] += W
        mx[:, k] = x + _PAD
    my = np.broadcast_to(my0[:, None], (P, Y, h, w))
    mx = mx.reshape(P * Y * h, w)
    my = np.ascontiguousarray(my).reshape(P * Y * h, w)
    m1 = np.empty((P * Y * h, w, 2), np.int16)
    m2 = np.empty((P * Y * h, w), np.uint16)
    step = max(1, (_MAX_SIDE - 1) // h) * h
    for a in range(0, P * Y * h, step):
        m1[a : a + step], m2[a : a + step] = cv2.convertMaps(
            mx[a : a + step], my[a : a + step], cv2.CV_16SC2
        )
    return {"m1": m1, "m2": m2}
