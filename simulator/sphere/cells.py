"""Lon/lat cells on the sphere, view frusta, and the solid angle of each cell inside a view.

Conventions (SPEC.md, :mod:`simulator.sphere.geometry`): world +x right, +y up, +z forward
(lon = 0, lat = 0); lon = atan2(x, z) increases to the right, lat + up. Degrees at every
public boundary (``*_deg``), radians inside.

Cells (:class:`CellGrid`) are laid out like an equirect frame: row ``i`` covers latitudes
``[90 - (i+1) c, 90 - i c]`` deg (row 0 at the north pole), column ``j`` longitudes
``[-180 + j c, -180 + (j+1) c]`` deg, ``c`` = ``cell_deg``. A :class:`Frustum` is one eye's
perspective view in the head frame by its four half-angles (symmetric from a FOV, or a
headset profile's exact asymmetric per-eye frustum); it is the one viewport value that
EPOF (both modes) and the renderer take. :func:`viewport_weights` gives the solid angle of
every cell inside a view (the overlap weights of sphere mode).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import sparse
from scipy.special import ellipe

from simulator.core.errors import InputError
from simulator.sphere.geometry import check_fov, dir_to_lonlat, head_rotation, perspective_rays
from simulator.sphere.headsets import get_headset
from simulator.sphere.windows import WindowGrid

__all__ = ["CellGrid", "Frustum", "viewport_weights", "window_pof"]


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
        :func:`simulator.sphere.geometry.check_fov` (the one FOV rule), and at most 179 deg (the
        half-angle limit of a frustum)."""
        h, v = check_fov(hfov_deg, vfov_deg, source="viewport")
        for name, f in (("hfov", h), ("vfov", v)):
            if f > 179.0:
                raise InputError(f"viewport: {name} must be at most 179 degrees; got {f:g}")
        return cls(h / 2.0, h / 2.0, v / 2.0, v / 2.0)

    @classmethod
    def from_headset(cls, name: str, eye: str = "left") -> Frustum:
        """The exact (asymmetric) per-eye frustum of a headset profile
        (:mod:`simulator.sphere.headsets`)."""
        return cls(*get_headset(name).half_angles_deg(eye))

    def for_eye(self, eye: str = "left") -> Frustum:
        """This (left-eye) frustum as ``eye`` sees it: the right eye mirrors left and right
        (as headset profiles do, :meth:`simulator.sphere.headsets.Headset.half_angles_deg`)."""
        if eye == "right":
            return Frustum(self.right_deg, self.left_deg, self.down_deg, self.up_deg)
        return self

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
        Head -> world rotation matrices (:func:`simulator.sphere.geometry.head_rotation`).
    frustum : Frustum

    Returns
    -------
    ndarray, shape (M, n_cells) or (n_cells,), float32
        ``A_c * coverage_c``; coverage is, per bounding plane, a linear ramp of the
        signed distance of the cell centre to the plane across the cell's extent along the
        plane normal (exact for a cell cut parallel to its sides), multiplied over the 4
        planes. Sums to the viewport's solid angle within ~1% for cells <= 5 deg.
    """
    cell_deg = float(cell_deg)
    _centre, _e_half, _n_half, sa, stacked = _cell_geometry(cell_deg)
    rot = np.asarray(rot, np.float64)
    single = rot.ndim == 2
    R = rot[None] if single else rot
    normals = np.einsum("mij,kj->mki", R, frustum.normals())  # (M, 4, 3) world
    C = len(sa)
    n_lon = CellGrid(cell_deg).shape[1]
    w = np.zeros((len(R), C), np.float32)
    # Only the latitude rows a view can reach are evaluated (a window covers ~1/6 of the
    # cells); every cell outside them has coverage exactly 0.
    rows = _view_rows(R, frustum, cell_deg)
    for lo, hi in np.unique(rows, axis=0):
        m = np.flatnonzero((rows[:, 0] == lo) & (rows[:, 1] == hi))
        a, b = int(lo) * n_lon, int(hi) * n_lon
        band = np.concatenate([stacked[:, a + k * C : b + k * C] for k in range(3)], axis=1)
        d = (normals[m].reshape(-1, 3) @ band).reshape(len(m), 4, 3, b - a)
        hw = np.abs(d[:, :, 1]) + np.abs(d[:, :, 2]) + 1e-9
        cov = np.clip(0.5 + 0.5 * d[:, :, 0] / hw, 0.0, 1.0).prod(axis=1)
        w[m, a:b] = cov * sa[a:b]
    return w[0] if single else w


def _view_rows(R: NDArray, frustum: Frustum, cell_deg: float) -> NDArray[np.intp]:
    """Per view ``(M, 2)``: the cell rows ``[lo, hi)`` its frustum can touch: the latitudes
    within ``r`` of its axis, ``r`` = the cone around the axis holding the frustum's corners
    plus two cells (a cell whose centre lies farther out is outside one of the four planes
    by more than its half extent, so its coverage is 0)."""
    t = [math.tan(math.radians(a)) for a in
         (frustum.left_deg, frustum.right_deg, frustum.down_deg, frustum.up_deg)]  # fmt: skip
    cone = max(math.atan(math.hypot(tx, ty)) for tx in t[:2] for ty in t[2:])
    c = math.radians(cell_deg)
    r = cone + 2.0 * c
    lat = np.arcsin(np.clip(R[:, 1, 2], -1.0, 1.0))  # the view axis (head +z) in the world
    n_lat = CellGrid(cell_deg).shape[0]
    lo = np.floor((math.pi / 2 - np.minimum(lat + r, math.pi / 2)) / c)
    hi = np.floor((math.pi / 2 - np.maximum(lat - r, -math.pi / 2)) / c) + 1
    return np.stack([np.clip(lo, 0, n_lat), np.clip(hi, 0, n_lat)], -1).astype(np.intp)


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
