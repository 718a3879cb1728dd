"""Sphere mode: the optical flow of a frame as one angular-speed field on the sphere.

The paper computes flow separately for 198-264 heavily overlapping windows per frame and
needs a new preprocessing run for every headset FOV. Here the flow of a frame pair is
computed once, on a few overlapping perspective *tiles* covering the sphere (a cube with
faces a little wider than 90 deg), converted to angular speed per pixel and splatted into
lon/lat *cells*. Any viewport (FOV, roll, asymmetric frustum) or any window grid is then a
weighted sum over cells.

Conventions (SPEC.md, :mod:`simulator.geometry`)
------------------------------------------------
World: +x right, +y up, +z forward (lon = 0, lat = 0); lon = atan2(x, z) increases to the
right, lat + up. Degrees at every public boundary (``*_deg``), radians inside. Speeds are
**deg/s of visual angle**: the angle between the ray of a pixel of frame t-1 and the ray of
its flow target in frame t, times fps.

The field
---------
``field_dps`` : float32, shape (T, n_lat, n_lon), deg/s. Laid out like an equirect frame:
row ``i`` covers latitudes ``[90 - (i+1) c, 90 - i c]`` deg (row 0 at the north pole),
column ``j`` longitudes ``[-180 + j c, -180 + (j+1) c]`` deg, ``c`` = ``cell_deg``. A cell
holds the solid-angle-weighted mean angular speed of the content inside it at frame t-1
(the flow from t-1 to t); frame 0 repeats frame 1 (the grid file's rule).

Two EPOF definitions (do not mix them)
--------------------------------------
* Paper mode (:mod:`simulator.epof`): EPOF = sum_n POF_n OL_n / sum_n OL_n, an
  overlap-weighted average of *window means*; a window far larger than the viewport still
  contributes its whole mean.
* Sphere mode (:func:`viewport_epof`, "exact EPOF"): the solid-angle-weighted mean angular
  speed over the actual viewport, sum_c f_c w_c / sum_c w_c with w_c the solid angle of
  cell c inside the viewport.

They agree for uniform motion and differ in general. To compare sphere mode with paper mode
compare like with like: :func:`window_pof` derives the paper's window matrix (window means)
from the field for any grid preset and FOV.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass, replace

import cv2
import numpy as np
from numpy.typing import NDArray
from scipy import sparse
from scipy.special import ellipe

from simulator.errors import InputError
from simulator.flow import RayAngles
from simulator.geometry import (
    WindowGrid,
    check_fov,
    dir_to_lonlat,
    equirect_remap_coords,
    head_rotation,
    pad_equirect,
    perspective_rays,
)

__all__ = [
    "CellGrid",
    "FieldEstimator",
    "Frustum",
    "SphereConfig",
    "ViewportQuery",
    "cells_from_meta",
    "field_from_frames",
    "field_from_video",
    "field_meta",
    "preprocess_sphere",
    "require_field",
    "viewport_epof",
    "viewport_weights",
    "window_pof",
]

#: How a user makes a grid with a field; quoted by every "no field" error.
MAKE_FIELD_HINT = "vimsim preprocess VIDEO -o GRID.npz --method sphere"

#: Cube faces as (yaw_deg, pitch_deg): front, right, back, left, up, down.
_CUBE = ((0.0, 0.0), (90.0, 0.0), (180.0, 0.0), (-90.0, 0.0), (0.0, 90.0), (0.0, -90.0))

#: A flow function or backend (:class:`simulator.flow.FlowBackend`): ``flow(prev, cur)`` with
#: ``(N, h, w)`` uint8 tiles returns ``(N, h, w, 2)`` float32 pixel flow ``(dx, dy)`` from prev
#: to cur (x right, y down).
FlowFn = Callable[[NDArray[np.uint8], NDArray[np.uint8]], NDArray[np.float32]]


# ---------------------------------------------------------------------------- configs
@dataclass(frozen=True)
class SphereConfig:
    """How the field is computed.

    tile_fov_deg : float, degrees in (90, 150)
        FOV of each of the 6 cube-face tiles (a little wider than 90 deg so faces overlap
        and every direction lies well inside some tile).
    tile_size : int, pixels
        Side of each square tile. The default 100 deg / 256 px (0.53 deg per pixel at the
        tile centre) was picked in bench/sphere_accuracy.py-style runs on the synthetic
        scenes: window error 0.6-1.5% median against 1.1-4.2% for 110 deg / 192 px (a
        positive bias that grows with the pixel's angular size) at ~1.3x the flow time.
    cell_deg : float, degrees
        Cell size of the lon/lat field; must divide 180.
    stride : int or None
        Evaluate the flow on every ``stride``-th pixel of each tile. ``None``: 2 for DIS
        ``ultrafast``/``fast`` (they compute flow at 1/4 resolution and upsample it, so
        nothing is lost), else 1.
    """

    tile_fov_deg: float = 100.0
    tile_size: int = 256
    cell_deg: float = 4.0
    stride: int | None = None

    def __post_init__(self) -> None:
        if not (90.0 < float(self.tile_fov_deg) < 150.0):
            raise InputError(
                f"sphere tile FOV must be degrees in (90, 150); got {self.tile_fov_deg}"
            )
        if not (16 <= int(self.tile_size) <= 1024):
            raise InputError(f"sphere tile size must be 16..1024 pixels; got {self.tile_size}")
        object.__setattr__(self, "tile_size", int(self.tile_size))
        CellGrid(self.cell_deg)  # validates
        if self.stride is not None and not (1 <= int(self.stride) <= 8):
            raise InputError(f"sphere flow stride must be 1..8 pixels; got {self.stride}")

    def to_dict(self) -> dict:
        return {
            "tile_fov_deg": float(self.tile_fov_deg),
            "tile_size": self.tile_size,
            "tiles": "cube",
            "cell_deg": float(self.cell_deg),
            "stride": self.stride,
        }


@dataclass(frozen=True)
class CellGrid:
    """The lon/lat cells of the field (layout in the module docstring).

    cell_deg : float, degrees; must divide 180 (e.g. 2, 2.5, 3, 4, 5).
    """

    cell_deg: float = 4.0

    def __post_init__(self) -> None:
        c = float(self.cell_deg)
        if not (0.5 <= c <= 30.0) or abs(180.0 / c - round(180.0 / c)) > 1e-6:
            raise InputError(
                f"field cell size must divide 180 degrees and lie in [0.5, 30]; got {self.cell_deg}"
            )
        object.__setattr__(self, "cell_deg", c)

    @property
    def shape(self) -> tuple[int, int]:
        """``(n_lat, n_lon)``."""
        n = round(180.0 / self.cell_deg)
        return n, 2 * n

    @property
    def n_cells(self) -> int:
        a, b = self.shape
        return a * b

    def centres_lonlat(self) -> tuple[NDArray, NDArray]:
        """Cell-centre ``lon (n_lon,)`` and ``lat (n_lat,)`` in **radians** (row 0 north)."""
        n_lat, n_lon = self.shape
        c = math.radians(self.cell_deg)
        lon = -math.pi + (np.arange(n_lon) + 0.5) * c
        lat = math.pi / 2 - (np.arange(n_lat) + 0.5) * c
        return lon, lat

    def solid_angles(self) -> NDArray[np.float64]:
        """Solid angle of each cell, shape ``(n_lat, n_lon)``, steradians (sums to 4 pi)."""
        return _cell_geometry(self.cell_deg)[3].reshape(self.shape)

    def index(self, lon, lat) -> NDArray[np.intp]:
        """Flat cell index (row-major ``i_lat * n_lon + j_lon``) of lon/lat in **radians**."""
        n_lat, n_lon = self.shape
        c = math.radians(self.cell_deg)
        j = np.floor((np.asarray(lon) + math.pi) / c).astype(np.intp) % n_lon
        i = np.clip(np.floor((math.pi / 2 - np.asarray(lat)) / c).astype(np.intp), 0, n_lat - 1)
        return i * n_lon + j


@functools.lru_cache(maxsize=8)
def _cell_geometry(cell_deg: float):
    """Per-cell centre direction ``(C, 3)``, east and north unit vectors scaled by the
    cell's half extent in radians (``(C, 3)`` each), and solid angle ``(C,)``; read-only."""
    cg = CellGrid(cell_deg)
    lon, lat = cg.centres_lonlat()
    LON, LAT = np.meshgrid(lon, lat)  # (n_lat, n_lon)
    c = math.radians(cell_deg)
    cl, sl = np.cos(LAT), np.sin(LAT)
    co, so = np.cos(LON), np.sin(LON)
    centre = np.stack([cl * so, sl, cl * co], -1).reshape(-1, 3)
    east = np.stack([co, np.zeros_like(co), -so], -1).reshape(-1, 3)
    north = np.stack([-sl * so, cl, -sl * co], -1).reshape(-1, 3)
    top, bot = LAT + c / 2, LAT - c / 2
    sa = (c * (np.sin(top) - np.sin(bot))).reshape(-1)
    # Half extents (radians) along east (at the centre latitude; polar cells are wedges,
    # their east extent is taken at the wider edge so they never vanish) and north.
    half_e = 0.5 * c * np.maximum(cl, np.abs(np.cos(LAT - np.sign(LAT) * c / 2))).reshape(-1)
    half_n = np.full(sa.shape, 0.5 * c)
    out = (centre, east * half_e[:, None], north * half_n[:, None], sa)
    stacked = np.ascontiguousarray(np.concatenate(out[:3], axis=0).T)  # (3, 3C)
    for a in (*out, stacked):
        a.setflags(write=False)
    return (*out, stacked)


@dataclass(frozen=True)
class Frustum:
    """A perspective viewport in the head frame, by its four half-angles in degrees.

    ``left_deg``/``right_deg``: angles of the left and right edges from the view axis
    (both > 0, measured outward); ``down_deg``/``up_deg`` likewise. Symmetric views use
    :meth:`symmetric`. Each angle lies in (0, 89.5].
    """

    left_deg: float
    right_deg: float
    down_deg: float
    up_deg: float

    def __post_init__(self) -> None:
        for name in ("left_deg", "right_deg", "down_deg", "up_deg"):
            v = float(getattr(self, name))
            if not (0.0 < v <= 89.5) or not math.isfinite(v):
                raise InputError(
                    f"viewport half-angle {name} must be degrees in (0, 89.5]; got {v}"
                )
            object.__setattr__(self, name, v)

    @classmethod
    def symmetric(cls, hfov_deg: float, vfov_deg: float | None = None) -> Frustum:
        """A centred ``hfov_deg x vfov_deg`` view: exact FOVs in degrees, checked by
        :func:`simulator.geometry.check_fov` (the one FOV rule), and at most 179 deg (the
        half-angle limit of a frustum)."""
        h, v = check_fov(hfov_deg, vfov_deg, source="viewport")
        for name, f in (("hfov", h), ("vfov", v)):
            if f > 179.0:
                raise InputError(f"viewport: {name} must be at most 179 degrees; got {f:g}")
        return cls(h / 2.0, h / 2.0, v / 2.0, v / 2.0)

    @classmethod
    def from_headset(cls, name: str, eye: str = "left") -> Frustum:
        """The exact (asymmetric) per-eye frustum of a headset profile
        (:mod:`simulator.headsets`)."""
        from simulator.headsets import get_headset

        return cls(*get_headset(name).half_angles_deg(eye))

    @property
    def hfov_deg(self) -> float:
        return self.left_deg + self.right_deg

    @property
    def vfov_deg(self) -> float:
        return self.down_deg + self.up_deg

    def normals(self) -> NDArray[np.float64]:
        """Inward unit normals ``(4, 3)`` of the four planes bounding the view (head frame)."""
        lf, rt, dn, up = (
            math.radians(a) for a in (self.left_deg, self.right_deg, self.down_deg, self.up_deg)
        )
        return np.array(
            [
                [math.cos(lf), 0.0, math.sin(lf)],  # left edge: x >= -tan(lf) z
                [-math.cos(rt), 0.0, math.sin(rt)],  # right edge
                [0.0, math.cos(dn), math.sin(dn)],  # bottom edge
                [0.0, -math.cos(up), math.sin(up)],  # top edge
            ]
        )


# --------------------------------------------------------------------- field estimation
class _TileGeometry:
    """Everything about the tiles that depends only on config and frame size."""

    def __init__(self, cfg: SphereConfig, equirect_size: tuple[int, int], stride: int):
        W, H = equirect_size
        s, fov = cfg.tile_size, cfg.tile_fov_deg
        t = math.tan(math.radians(fov) / 2.0)
        # Pyramid level: halve the equirect while its pixels stay finer than a tile's
        # centre pixel (anti-aliasing for the linear remap, and a cheaper remap).
        centre_px_deg = math.degrees(2.0 * math.atan(t / s))
        # Stored pixels may be non-square (e.g. SAR 9:8): lon and lat steps are checked apart.
        level, w, h = 0, W, H
        while (
            w % 4 == 0
            and max(360.0 / (w // 2), 180.0 / ((h + 1) // 2)) <= centre_px_deg
            and min(w // 2, (h + 1) // 2) >= 32
        ):
            w, h = w // 2, (h + 1) // 2  # cv2.pyrDown's output size
            level += 1
        self.level = level
        self.small_size = (w, h)
        dirs, sa = perspective_rays((s, s), fov, fov)
        R = head_rotation(
            [a[0] for a in _CUBE], [a[1] for a in _CUBE], 0.0
        ).as_matrix()  # (6, 3, 3)
        world = np.einsum("nij,hwj->nhwi", R, dirs.astype(np.float64))  # (6, s, s, 3)
        mx, my = equirect_remap_coords(world.reshape(len(_CUBE) * s, s, 3), *self.small_size)
        self.m1, self.m2 = cv2.convertMaps(mx, my, cv2.CV_16SC2)
        # Flow is evaluated on every ``stride``-th pixel (DIS presets with finest scale 2
        # compute flow at 1/4 resolution and upsample it: stride 2 loses nothing).
        st = self.stride = stride
        sel = np.arange(st // 2, s, st)
        # Per-pixel ray angles of the tile's flow (the formula paper mode uses), on the
        # evaluated pixels; their tile-plane coordinates u0, v0 (tan units, x right, y up).
        self.rays = RayAngles((s, s), fov, fov, stride=st)
        # Blend weight: 1 inside the cube face each tile owns (max(|u|,|v|) <= 1), falling
        # smoothly to 0 at the tile border where flow is least reliable.
        m = np.maximum(np.abs(self.rays.u0), np.abs(self.rays.v0)).astype(np.float64)
        x = np.clip((t - m) / (t - 1.0), 0.0, 1.0)
        blend = x * x * (3.0 - 2.0 * x)
        sub_world = world[:, sel][:, :, sel].reshape(-1, 3)
        w = np.broadcast_to(sa[np.ix_(sel, sel)] * blend, (len(_CUBE), len(sel), len(sel))).reshape(
            -1
        )
        lon, lat = dir_to_lonlat(sub_world)
        cells = CellGrid(cfg.cell_deg)
        idx = cells.index(lon, lat)
        self.splat = _splat_matrix(idx, w, cells, sub_world)
        self.n_tiles = len(_CUBE)
        self.size = s

    def tiles(self, frame: NDArray[np.uint8]) -> NDArray[np.uint8]:
        f = np.ascontiguousarray(frame)
        for _ in range(self.level):
            f = cv2.pyrDown(f)
        out = cv2.remap(
            pad_equirect(f), self.m1, self.m2, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE
        )
        return out.reshape(self.n_tiles, self.size, self.size)

    def angles(self, flow: NDArray[np.float32]) -> NDArray[np.float32]:
        """Angle (radians) between each evaluated pixel's ray and its flow target's ray;
        flow is ``(N, s, s, 2)`` pixels (x right, y down) -> ``(N, s', s')``."""
        return self.rays(flow)


def _splat_matrix(idx: NDArray, w: NDArray, cells: CellGrid, dirs: NDArray) -> sparse.csr_matrix:
    """Sparse ``(C, n_px)`` matrix: cell value = weighted mean of its pixels' values; cells
    no pixel centre falls in (tiny polar cells) copy their nearest covered cell."""
    C = cells.n_cells
    keep = w > 0
    idx, w, cols = idx[keep], w[keep], np.nonzero(keep)[0]
    tot = np.bincount(idx, weights=w, minlength=C)
    covered = tot > 0
    rows, vals = idx, w / tot[idx]
    if not covered.all():
        centre = _cell_geometry(cells.cell_deg)[0]
        empty = np.nonzero(~covered)[0]
        full = np.nonzero(covered)[0]
        near = full[np.argmax(centre[empty] @ centre[full].T, axis=1)]
        # Rows of the nearest covered cells, re-labelled.
        m = sparse.csr_matrix((vals, (rows, cols)), shape=(C, len(keep)))
        extra = m[near].tocoo()
        rows = np.concatenate([rows, empty[extra.row]])
        cols = np.concatenate([cols, extra.col])
        vals = np.concatenate([vals, extra.data])
    return sparse.csr_matrix((vals.astype(np.float32), (rows, cols)), shape=(C, len(keep)))


def _backend(flow, tile_size: int) -> tuple[FlowFn, int, dict]:
    """``(flow function, default stride, description for meta)`` of a flow spec, for
    square tiles of ``tile_size`` pixels."""
    from simulator.flow import DISFlow, FlowBackend, make_backend

    be = make_backend(flow, size=(tile_size, tile_size)) if isinstance(flow, str) else flow
    if isinstance(be, DISFlow):
        stride = 2 if be.preset in ("ultrafast", "fast") else 1
    else:
        stride = 1
    desc = (
        be.describe()
        if isinstance(be, FlowBackend)
        else {"method": getattr(be, "__name__", "custom")}
    )
    return be, stride, desc


class FieldEstimator:
    """Per-frame angular-speed fields of an equirect video, one frame pair at a time.

    Parameters
    ----------
    equirect_size : (W, H), pixels of one eye's equirect frame (stored pixels)
    fps : float, frames per second (converts per-frame angles to deg/s)
    config : SphereConfig
    flow : str or FlowBackend or FlowFn
        Pixel flow between two stacks of tiles: a ``--flow`` text (``"dis"`` = OpenCV DIS
        ultrafast, ``"dis:fast"``, ``"farneback"``, ``"torch:MODEL.pt"``), a
        :class:`simulator.flow.FlowBackend`, or any function of that signature.

    Use :meth:`tiles` on each decoded gray frame, then :meth:`field` on consecutive tile
    stacks; :func:`field_from_frames` and :func:`field_from_video` do the loop.
    """

    def __init__(
        self,
        equirect_size: tuple[int, int],
        fps: float,
        config: SphereConfig = SphereConfig(),
        *,
        flow: str | FlowFn = "dis",
    ):
        if not (fps > 0) or not math.isfinite(fps):
            raise InputError(f"frame rate must be > 0 frames/s; got {fps}")
        W, H = int(equirect_size[0]), int(equirect_size[1])
        # The 2:1 display aspect (with the sample aspect ratio) is the caller's check
        # (MediaInfo.eye_size); stored pixels may be non-square.
        if W % 2 or W < 64 or H < 32 or not (0.8 <= W / H <= 4.5):
            raise InputError(
                f"sphere mode needs an equirect frame with an even width >= 64 and about 2:1 "
                f"(stored pixels may be non-square); got {W}x{H}"
            )
        self.config = config
        self.cells = CellGrid(config.cell_deg)
        self.fps = float(fps)
        self.equirect_size = (W, H)
        self._flow, stride, self.flow_desc = _backend(flow, config.tile_size)
        self.stride = int(config.stride or stride)
        self._geo = _tile_geometry(config, (W, H), self.stride)

    def tiles(self, frame: NDArray[np.uint8]) -> NDArray[np.uint8]:
        """The 6 cube-face tiles ``(6, s, s)`` uint8 of a gray ``(H, W)`` frame."""
        if frame.shape[:2] != self.equirect_size[::-1] or frame.ndim != 2:
            raise InputError(
                f"expected a gray {self.equirect_size[0]}x{self.equirect_size[1]} frame; got shape {frame.shape}"
            )
        return self._geo.tiles(frame)

    def field(self, prev_tiles: NDArray[np.uint8], tiles: NDArray[np.uint8]) -> NDArray[np.float32]:
        """Angular-speed field ``(n_lat, n_lon)`` float32 in deg/s of the flow prev -> cur."""
        fl = self._flow(prev_tiles, tiles)
        ang, _ = self._geo.rays.into_scratch(np.asarray(fl, np.float32))
        f = self._geo.splat @ ang.reshape(-1)
        return (
            (f * np.float32(math.degrees(1.0) * self.fps))
            .astype(np.float32)
            .reshape(self.cells.shape)
        )


@functools.lru_cache(maxsize=4)
def _tile_geometry(cfg: SphereConfig, equirect_size: tuple[int, int], stride: int) -> _TileGeometry:
    return _TileGeometry(cfg, equirect_size, stride)


class _FieldRows:
    """Per-frame fields appended into one preallocated ``(T, n_lat, n_lon)`` float32 array
    (grown by doubling if ``expected`` was short), row 0 reserved for the copy of row 1:
    peak memory is the result itself, with no list of rows and no final stack."""

    def __init__(self, shape: tuple[int, int], expected: int):
        self._a = np.empty((max(2, int(expected)), *shape), np.float32)
        self.n = 1  # rows filled, counting the reserved row 0

    def append(self, f: NDArray[np.float32]) -> None:
        if self.n == len(self._a):
            grown = np.empty((2 * len(self._a), *self._a.shape[1:]), np.float32)
            grown[: self.n] = self._a
            self._a = grown
        self._a[self.n] = f
        self.n += 1

    def result(self) -> NDArray[np.float32]:
        """``(n, n_lat, n_lon)``; row 0 = row 1 (frame 0 has no predecessor)."""
        a = self._a[: self.n]
        a[0] = a[1]
        return a if self.n > 0.9 * len(self._a) else a.copy()


def field_from_frames(
    frames: Iterable[NDArray[np.uint8]],
    equirect_size: tuple[int, int],
    fps: float,
    config: SphereConfig = SphereConfig(),
    *,
    flow: str | FlowFn = "dis",
    progress: Callable[[int], None] | None = None,
) -> NDArray[np.float32]:
    """Fields ``(T, n_lat, n_lon)`` float32 deg/s of a sequence of gray equirect frames.

    Frame t holds the flow from frame t-1 to t; frame 0 repeats frame 1. Needs >= 2 frames.
    ``progress(n)`` is called after each frame with the number of frames done.
    """
    est = FieldEstimator(equirect_size, fps, config, flow=flow)
    return _fields(est, (est.tiles(f) for f in frames), 256, progress, "")


def _fields(est: FieldEstimator, tiles, expected: int, progress, source: str):
    """The field of each consecutive pair of ``tiles`` (one frame's tiles per item), frame 0
    repeating frame 1, into one :class:`_FieldRows` sized for ``expected`` frames.
    ``source`` prefixes the error for fewer than 2 frames."""
    out = _FieldRows(est.cells.shape, expected)
    prev = None
    n = 0
    for t in tiles:
        if prev is not None:
            out.append(est.field(prev, t))
        prev = t
        n += 1
        if progress is not None:
            progress(n)
    if out.n < 2:
        raise InputError(f"{source}sphere mode needs at least 2 frames; got {n}")
    return out.result()


def field_from_video(
    path,
    config: SphereConfig = SphereConfig(),
    *,
    layout: str = "mono",
    eye: str = "left",
    start: int = 0,
    end: int | None = None,
    flow: str | FlowFn = "dis",
    progress: Callable[[int], None] | None = None,
) -> tuple[NDArray[np.float32], object]:
    """Fields ``(T, n_lat, n_lon)`` float32 deg/s of a video file, and its ``MediaInfo``.

    Decodes the Y plane only; decoding and tile extraction run in a background thread
    while flow and splatting run in the caller's. Frames ``start <= k < end``.
    """
    from simulator.video import iter_frames, prefetch, probe

    info = probe(path)
    if not info.is_video:
        raise InputError(f"{path}: sphere mode needs a video; got a still image")
    w, h = info.eye_size(layout)
    est = FieldEstimator((w, h), info.fps, config, flow=flow)
    frames = iter_frames(path, fmt="gray", layout=layout, eye=eye, start=start, end=end)
    tiles = prefetch((est.tiles(f) for f in frames), depth=4)
    last = info.n_frames if end is None else min(int(end), info.n_frames)
    try:
        return _fields(est, tiles, last - int(start), progress, f"{path}: "), info
    finally:
        tiles.close()  # stops the decoding thread now, not when garbage-collected
        frames.close()  # closes the video file


# --------------------------------------------------------------------- integration
def viewport_weights(
    cell_deg: float,
    rot: NDArray[np.float64],
    frustum: Frustum,
) -> NDArray[np.float32]:
    """Solid angle (steradians) of each cell inside each of ``M`` viewports.

    Parameters
    ----------
    cell_deg : float, degrees; the field's cell size
    rot : ndarray, shape (M, 3, 3) or (3, 3)
        Head -> world rotation matrices (:func:`simulator.geometry.head_rotation`).
    frustum : Frustum

    Returns
    -------
    ndarray, shape (M, n_cells) or (n_cells,), float32
        ``A_c * coverage_c``; coverage is, per bounding plane, a linear ramp of the
        signed distance of the cell centre to the plane across the cell's extent along the
        plane normal (exact for a cell cut parallel to its sides), multiplied over the 4
        planes. Sums to the viewport's solid angle within ~1% for cells <= 5 deg.
    """
    _centre, _e_half, _n_half, sa, stacked = _cell_geometry(float(cell_deg))
    rot = np.asarray(rot, np.float64)
    single = rot.ndim == 2
    R = rot[None] if single else rot
    normals = np.einsum("mij,kj->mki", R, frustum.normals())  # (M, 4, 3) world
    C = len(sa)
    d = (normals.reshape(-1, 3) @ stacked).reshape(len(R), 4, 3, C)
    hw = np.abs(d[:, :, 1]) + np.abs(d[:, :, 2]) + 1e-9
    cov = np.clip(0.5 + 0.5 * d[:, :, 0] / hw, 0.0, 1.0).prod(axis=1)
    w = (cov * sa).astype(np.float32)
    return w[0] if single else w


def _weights_band(
    cell_deg: float, R: NDArray, frustum: Frustum, lo: int, hi: int
) -> NDArray[np.float64]:
    """:func:`viewport_weights` of one rotation for the flat cells ``lo <= c < hi`` only."""
    centre, e_half, n_half, sa, _ = _cell_geometry(cell_deg)
    n = frustum.normals() @ R.T  # (4, 3) world
    d0 = n @ centre[lo:hi].T
    hw = np.abs(n @ e_half[lo:hi].T) + np.abs(n @ n_half[lo:hi].T) + 1e-9
    cov = np.clip(0.5 + 0.5 * d0 / hw, 0.0, 1.0).prod(axis=0)
    return cov * sa[lo:hi]


def _rotations(yaw_deg, pitch_deg, roll_deg) -> NDArray[np.float64]:
    return head_rotation(yaw_deg, pitch_deg, roll_deg).as_matrix()


def viewport_epof(
    field_dps: NDArray,
    cell_deg: float,
    yaw_deg,
    pitch_deg,
    roll_deg=0.0,
    *,
    frustum: Frustum | None = None,
    hfov_deg: float = 107.0,
    vfov_deg: float | None = None,
    step_deg: float = 0.5,
) -> NDArray[np.float64]:
    """Exact EPOF (deg/s): mean angular speed over the actual viewport of each frame.

    Parameters
    ----------
    field_dps : ndarray, shape (T, n_lat, n_lon)
        Per-frame fields (deg/s), layout of the module docstring.
    cell_deg : float, degrees
    yaw_deg, pitch_deg, roll_deg : array_like, shape (T,) or scalars, degrees
        Head orientation at each frame (yaw + right, pitch + up, roll + right ear down).
    frustum : Frustum, optional
        The viewport; default ``Frustum.symmetric(hfov_deg, vfov_deg)``.
    step_deg : float, degrees
        Orientation resolution of the precomputed weights (:class:`ViewportQuery`).

    Returns
    -------
    ndarray, shape (T,), float64
    """
    f = np.asarray(field_dps)
    cells = CellGrid(cell_deg)
    if f.ndim != 3 or f.shape[1:] != cells.shape:
        raise InputError(
            f"field must be (T, {cells.shape[0]}, {cells.shape[1]}) for {cell_deg} deg cells; got {f.shape}"
        )
    fr = frustum or Frustum.symmetric(hfov_deg, vfov_deg)
    T = f.shape[0]
    yaw, pitch, roll = (
        np.broadcast_to(np.asarray(a, float), (T,)) for a in (yaw_deg, pitch_deg, roll_deg)
    )
    q = _query(cells.cell_deg, fr, float(step_deg))
    return q.many(f, yaw, pitch, roll)


@functools.lru_cache(maxsize=8)
def _query(cell_deg: float, frustum: Frustum, step_deg: float) -> ViewportQuery:
    return ViewportQuery(cell_deg, frustum, step_deg=step_deg)


class ViewportQuery:
    """Fast exact-EPOF queries: a few microseconds per viewport.

    The cells a viewport covers, and their weights, depend on pitch and roll only up to
    a shift in longitude: a yaw turn by ``k`` cells moves the weight map by ``k`` columns.
    Weights (:func:`viewport_weights`) are therefore computed once per (pitch, roll, yaw
    mod one cell) bin of ``step_deg`` and kept (sparse, LRU-cached); a query rounds the
    orientation to its bin, shifts the columns by ``floor(yaw / cell)`` and takes a dot
    product of ~10^3 cells. Rounding moves the viewport edges by at most ``step_deg / 2``
    (0.25 deg by default: < 0.5% of a 107 deg viewport's area).

    Parameters
    ----------
    cell_deg : float, degrees
    frustum : Frustum
    step_deg : float, degrees; must divide ``cell_deg``
    cache_size : int, number of bins kept
    """

    def __init__(
        self, cell_deg: float, frustum: Frustum, *, step_deg: float = 0.5, cache_size: int = 8192
    ):
        self.cells = CellGrid(cell_deg)
        self.frustum = frustum
        c = self.cells.cell_deg
        n_sub = c / float(step_deg)
        if not (step_deg > 0) or abs(n_sub - round(n_sub)) > 1e-6:
            raise InputError(
                f"query step must be degrees > 0 dividing the cell size {c}; got {step_deg}"
            )
        self.step_deg = float(step_deg)
        self._n_sub = round(n_sub)
        self._n_lat, self._n_lon = self.cells.shape
        self._bins: dict[tuple[int, int, int], tuple] = {}
        # Angular radius of the viewport around its axis (corner ray) plus a cell, radians.
        tl, tr, td, tu = (
            math.tan(math.radians(x))
            for x in (frustum.left_deg, frustum.right_deg, frustum.down_deg, frustum.up_deg)
        )
        self._radius = math.atan(math.hypot(max(tl, tr), max(td, tu))) + math.radians(c)
        self._cache_size = int(cache_size)

    def _bin(self, key: tuple[int, int, int]) -> tuple:
        b = self._bins.get(key)
        if b is not None:
            return b
        ip, ir, isub = key
        st = self.step_deg
        R = head_rotation(isub * st, ip * st, ir * st).as_matrix()
        # Only the latitude rows the viewport can reach (its axis latitude +- radius).
        axis_lat = math.asin(max(-1.0, min(1.0, R[1, 2])))
        c = math.radians(self.cells.cell_deg)
        i0 = max(0, math.floor((math.pi / 2 - axis_lat - self._radius) / c))
        i1 = min(self._n_lat, math.floor((math.pi / 2 - axis_lat + self._radius) / c) + 1)
        lo, hi = i0 * self._n_lon, i1 * self._n_lon
        w = _weights_band(self.cells.cell_deg, R, self.frustum, lo, hi)
        nz = np.nonzero(w > w.max() * 1e-7)[0] + lo
        w = w[nz - lo]
        rows, cols = np.divmod(nz, self._n_lon)
        # Index into a field row-doubled to (n_lat, 2 n_lon): no modulo at query time.
        base = (rows * (2 * self._n_lon) + cols).astype(np.intp)
        b = (base, w, float(w.sum()), (rows * self._n_lon).astype(np.intp), cols.astype(np.intp))
        if len(self._bins) >= self._cache_size:
            self._bins.pop(next(iter(self._bins)))
        self._bins[key] = b
        return b

    def _key(
        self, yaw_deg: float, pitch_deg: float, roll_deg: float
    ) -> tuple[tuple[int, int, int], int]:
        st = self.step_deg
        y = round(yaw_deg / st) % (self._n_lon * self._n_sub)
        shift, sub = divmod(y, self._n_sub)
        p = round(max(-90.0, min(90.0, pitch_deg)) / st)
        r = round(((roll_deg + 180.0) % 360.0 - 180.0) / st)
        return (p, r, sub), shift

    @staticmethod
    def doubled(field_dps: NDArray) -> NDArray[np.float64]:
        """A field ``(..., n_lat, n_lon)`` repeated along longitude, flattened per frame:
        ``(..., n_lat * 2 n_lon)`` float64 (what :meth:`query` indexes)."""
        f = np.asarray(field_dps, np.float64)
        d = np.concatenate([f, f], axis=-1)
        return d.reshape(*f.shape[:-2], -1)

    def query(
        self, doubled_field: NDArray, yaw_deg: float, pitch_deg: float, roll_deg: float = 0.0
    ) -> float:
        """Exact EPOF (deg/s) for one orientation of a field prepared by :meth:`doubled`."""
        key, shift = self._key(yaw_deg, pitch_deg, roll_deg)
        base, w, wsum, _, _ = self._bin(key)
        return float(doubled_field[base + shift] @ w) / wsum

    def __call__(
        self, field_dps: NDArray, yaw_deg: float, pitch_deg: float, roll_deg: float = 0.0
    ) -> float:
        """Exact EPOF (deg/s) of one ``(n_lat, n_lon)`` field for one head orientation."""
        return self.query(self.doubled(field_dps), yaw_deg, pitch_deg, roll_deg)

    def many(self, field_dps: NDArray, yaw_deg, pitch_deg, roll_deg) -> NDArray[np.float64]:
        """Exact EPOF ``(T,)`` of fields ``(T, n_lat, n_lon)``, one orientation per frame
        (or one field ``(n_lat, n_lon)`` for ``T`` orientations)."""
        f = np.asarray(field_dps)
        yaw, pitch, roll = np.broadcast_arrays(
            np.asarray(yaw_deg, float), np.asarray(pitch_deg, float), np.asarray(roll_deg, float)
        )
        yaw, pitch, roll = yaw.ravel(), pitch.ravel(), roll.ravel()
        if not (
            np.all(np.isfinite(yaw)) and np.all(np.isfinite(pitch)) and np.all(np.isfinite(roll))
        ):
            raise InputError("head orientation has non-finite values")
        n_lon = self._n_lon
        out = np.empty(len(yaw))
        if f.ndim == 2:
            d = self.doubled(f)
            for t in range(len(yaw)):
                out[t] = self.query(d, yaw[t], pitch[t], roll[t])
            return out
        if f.ndim != 3 or f.shape[0] != len(yaw):
            raise InputError(f"{f.shape[0]} field frames but {len(yaw)} orientations")
        flat = f.reshape(f.shape[0], -1)
        for t in range(len(yaw)):
            key, shift = self._key(yaw[t], pitch[t], roll[t])
            _, w, wsum, rowbase, cols = self._bin(key)
            out[t] = float(flat[t][rowbase + (cols + shift) % n_lon] @ w) / wsum
        return out


# ------------------------------------------------------------------- window matrix
@functools.lru_cache(maxsize=8)
def _window_matrices(grid: WindowGrid, cell_deg: float, rays: int = 48):
    """``(Wdps (N, C), Kpx (N, C))``: solid-angle weights of each window over the cells
    (normalised to sum 1), and the pixel-measure kernel (mean over window pixels of
    window-pixels per radian of angular displacement, per cell, divided by pixel count)."""
    fr = Frustum.symmetric(grid.hfov_deg, grid.vfov_deg)
    pitch, yaw = grid.centres_deg()
    R = _rotations(yaw.ravel(), pitch.ravel(), 0.0)
    Wd = viewport_weights(cell_deg, R, fr).astype(np.float64)
    Wd /= Wd.sum(axis=1, keepdims=True)
    # Pixel measure: sample rays uniformly in window pixels (each stands for the same
    # number of pixels); the gnomonic image stretches an angular displacement by
    # 1/cos^2(theta) radially and 1/cos(theta) tangentially; for flow of any direction
    # the mean stretch is (2/pi) E(sin^2 theta) / cos^2 theta (complete elliptic
    # integral): an isotropic-direction approximation.
    w, h = grid.size
    nx = ny = rays
    dirs, _ = perspective_rays((nx, ny), grid.hfov_deg, grid.vfov_deg)
    cos_t = dirs[..., 2].astype(np.float64).reshape(-1)
    stretch = (2.0 / math.pi) * ellipe(1.0 - cos_t**2) / cos_t**2
    ppt = math.sqrt(
        (w / (2.0 * math.tan(math.radians(grid.hfov_deg) / 2.0)))
        * (h / (2.0 * math.tan(math.radians(grid.vfov_deg) / 2.0)))
    )
    world = np.einsum("nij,pj->npi", R, dirs.reshape(-1, 3).astype(np.float64))
    lon, lat = dir_to_lonlat(world)
    cells = CellGrid(cell_deg)
    idx = cells.index(lon, lat)  # (N, p)
    N, p = idx.shape
    flat = (np.arange(N)[:, None] * cells.n_cells + idx).ravel()
    K = np.bincount(flat, weights=np.tile(stretch * ppt / p, N), minlength=N * cells.n_cells)
    K = K.reshape(N, cells.n_cells)
    # Sparse (a window covers ~1/6 of the cells): cheaper, and no BLAS threads.
    Wd[Wd < 1e-9] = 0.0
    return sparse.csr_matrix(Wd), sparse.csr_matrix(K)


def window_pof(
    field_dps: NDArray, cell_deg: float, grid: WindowGrid, fps: float
) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """The paper's window matrix derived from the field, for any grid preset and FOV.

    Parameters
    ----------
    field_dps : ndarray, shape (T, n_lat, n_lon), deg/s
    cell_deg : float, degrees
    grid : WindowGrid (any preset, FOV and window size)
    fps : float, frames/s (for the pixel measure)

    Returns
    -------
    pof_dps : ndarray, shape (T, P, Y), float32
        Solid-angle-weighted mean angular speed of each window (deg/s), as paper mode.
    pof_px : ndarray, shape (T, P, Y), float32
        The paper's pixel measure (mean flow magnitude in window pixels per frame),
        **approximate**: it assumes flow directions are isotropic within each cell.
    """
    f = np.asarray(field_dps, np.float64)
    cells = CellGrid(cell_deg)
    if f.ndim != 3 or f.shape[1:] != cells.shape:
        raise InputError(f"field must be (T, {cells.shape[0]}, {cells.shape[1]}); got {f.shape}")
    Wd, K = _window_matrices(grid, cells.cell_deg)
    T = f.shape[0]
    flat = f.reshape(T, -1)
    P, Y = grid.shape
    dps = (Wd @ flat.T).T.reshape(T, P, Y)
    px = ((K @ flat.T).T * (math.radians(1.0) / fps)).reshape(T, P, Y)
    return dps.astype(np.float32), px.astype(np.float32)


# ---------------------------------------------------------------------- grid files
def field_meta(config: SphereConfig, dtype: str = "float16") -> dict:
    """The ``meta["field"]`` entry of a grid file holding a field."""
    return {
        "method": "sphere",
        "units": "deg/s",
        "dtype": dtype,
        "cell_deg": float(config.cell_deg),
        "layout": "lonlat: row 0 = north (lat centre 90 - (i + 0.5) * cell_deg), column 0 = lon -180 (centre -180 + (j + 0.5) * cell_deg); cell = solid-angle mean speed of content at frame t-1, flow t-1 -> t",
        "tiles": config.to_dict(),
    }


def cells_from_meta(meta: dict, *, source: str = "grid") -> CellGrid:
    """The :class:`CellGrid` described by ``meta["field"]``; InputError if absent/invalid."""
    fm = meta.get("field") if isinstance(meta, dict) else None
    if not isinstance(fm, dict) or "cell_deg" not in fm:
        raise InputError(
            f"{source}: grid has no sphere-mode field; make one with `{MAKE_FIELD_HINT}`"
        )
    return CellGrid(float(fm["cell_deg"]))


def require_field(grid_file) -> tuple[NDArray[np.float32], CellGrid]:
    """``(field_dps (T, n_lat, n_lon) float32, cells)`` of a loaded grid file.

    Raises InputError (one line, with the command that makes one) if the grid has no
    field, e.g. a paper-mode grid.
    """
    src = getattr(grid_file, "path", "") or "grid"
    f = getattr(grid_file, "field_dps", None)
    if f is None:
        raise InputError(
            f"{src}: grid has no sphere-mode field (made in paper mode?); make one with `{MAKE_FIELD_HINT}`"
        )
    cells = cells_from_meta(grid_file.meta, source=src)
    f = np.asarray(f)
    if f.ndim != 3 or f.shape[1:] != cells.shape:
        raise InputError(
            f"{src}: field_dps has shape {f.shape}; expected (T, {cells.shape[0]}, {cells.shape[1]}) for {cells.cell_deg} deg cells"
        )
    if not np.all(np.isfinite(f)):
        raise InputError(f"{src}: field_dps has non-finite values")
    return f.astype(np.float32, copy=False), cells


def preprocess_sphere(
    video,
    output,
    *,
    grid: WindowGrid,
    config: SphereConfig = SphereConfig(),
    flow: str | FlowFn = "dis",
    layout: str = "mono",
    eye: str = "left",
    start_s: float = 0.0,
    end_s: float | None = None,
    field_dtype: str = "float16",
    progress: bool = True,
):
    """``vimsim preprocess --method sphere``: the field of a video and, derived from it,
    the window matrix of ``grid``, written as one grid file (atomic).

    The grid file holds everything a paper-mode grid holds (``pof_dps``, ``pof_px`` of
    ``grid``, any preset and FOV; ``pof_px`` approximate, see :func:`window_pof`) plus
    ``field_dps`` (T, n_lat, n_lon) and ``meta["field"]`` (:func:`field_meta`).
    No checkpoints: sphere mode runs at tens of frames per second.

    Every check (video, range, output directory, flow backend) runs before any work; the
    backend is built once (a ``torch:MODEL.pt`` is loaded and validated once).

    Returns the output Path. InputError on bad input (nothing written).
    """
    import sys

    from simulator.gridfile import content_hash, save_grid
    from simulator.preprocess import check_output_dir, common_meta, frame_range
    from simulator.video import probe

    src = str(video)
    info = probe(video)
    if not info.is_video:
        raise InputError(
            f"{src}: is a still image; preprocess needs a video with at least 2 frames"
        )
    info.eye_size(layout)  # the layout must fit the frame (InputError otherwise)
    if field_dtype not in ("float16", "float32"):
        raise InputError(f"field dtype must be float16 or float32; got {field_dtype!r}")
    fps = info.fps
    start_f, end_f = frame_range(info, float(start_s), end_s, src)
    out = check_output_dir(output)
    backend, default_stride, desc = _backend(flow, config.tile_size)
    from tqdm import tqdm

    bar = tqdm(
        total=end_f - start_f,
        unit="frame",
        desc="preprocess (sphere)",
        disable=not progress,
        mininterval=0.5,
        dynamic_ncols=True,
        file=sys.stderr,
    )
    last = [0]

    def tick(n: int) -> None:
        bar.update(n - last[0])
        last[0] = n

    try:
        field, _ = field_from_video(
            video,
            config,
            layout=layout,
            eye=eye,
            start=start_f,
            end=end_f,
            flow=backend,
            progress=tick,
        )
    finally:
        bar.close()
    if not np.all(np.isfinite(field)):
        raise InputError(f"{src}: flow gave non-finite values")
    cells = CellGrid(config.cell_deg)
    dps, px = window_pof(field, cells.cell_deg, grid, fps)
    T = field.shape[0]
    if T != end_f - start_f:
        print(
            f"vimsim preprocess: warning: {src}: expected {end_f - start_f} frames, decoded {T}",
            file=sys.stderr,
        )
    meta = {
        "method": "sphere",
        **common_meta(
            video,
            info,
            n_rows=T,
            start_frame=start_f,
            flow=desc,
            layout=layout,
            eye=eye,
            content_hash=content_hash(video),
            units={
                "pof_dps": "deg/s of visual angle (solid-angle-weighted mean), derived from field_dps",
                "pof_px": "window px/frame (mean magnitude), derived from field_dps assuming isotropic flow directions per cell (approximate)",
                "field_dps": "deg/s of visual angle",
            },
        ),
        "field": field_meta(replace(config, stride=config.stride or default_stride), field_dtype),
    }
    save_grid(out, dps, px, grid, meta, field_dps=field.astype(field_dtype))
    return out
