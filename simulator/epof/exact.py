"""Sphere-mode ("exact") EPOF: the solid-angle-weighted mean of a field over the actual viewport.

Two EPOF definitions (do not mix them)
--------------------------------------
* Paper mode (:mod:`simulator.epof.overlaps`): EPOF = sum_n POF_n OL_n / sum_n OL_n, an
  overlap-weighted average of *window means*; a window far larger than the viewport still
  contributes its whole mean.
* Sphere mode (:func:`viewport_epof`): sum_c f_c w_c / sum_c w_c with w_c the solid angle of
  cell c inside the viewport (:func:`simulator.sphere.cells.viewport_weights`).

They agree for uniform motion and differ in general. To compare sphere mode with paper mode
compare like with like: :func:`simulator.preprocess.sphere.window_pof` derives the paper's
window matrix (window means) from the field for any grid preset and FOV. Angles in degrees (yaw + right, pitch + up,
roll + right ear down); speeds in deg/s.
"""

from __future__ import annotations

import functools
import math

import numpy as np
from numpy.typing import NDArray

from simulator.core.errors import InputError
from simulator.media.lazyfield import LazyField
from simulator.sphere.cells import CellGrid, Frustum, _weights_band
from simulator.sphere.geometry import head_rotation

__all__ = ["ViewportQuery", "viewport_epof"]


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
    field_dps : ndarray or LazyField, shape (T, n_lat, n_lon)
        Per-frame fields (deg/s), layout of the module docstring; a grid file's
        :class:`~simulator.media.lazyfield.LazyField` is integrated chunk by chunk.
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
    f = field_dps if isinstance(field_dps, LazyField) else np.asarray(field_dps)
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
    if not isinstance(f, LazyField):
        return q.many(f, yaw, pitch, roll)
    out = np.empty(T)  # a grid file's field: chunk by chunk (memory flat in T)
    for i0, c in f.chunks():
        i1 = i0 + len(c)
        out[i0:i1] = q.many(c, yaw[i0:i1], pitch[i0:i1], roll[i0:i1])
    return out


@functools.lru_cache(maxsize=8)
def _query(cell_deg: float, frustum: Frustum, step_deg: float) -> ViewportQuery:
    return ViewportQuery(cell_deg, frustum, step_deg=step_deg)


def shared_query(cell_deg: float, frustum: Frustum, step_deg: float = 0.5) -> ViewportQuery:
    """The :class:`ViewportQuery` :func:`viewport_epof` uses for these cells and frustum
    (one per process, LRU of 8), e.g. to give it a larger weight cache
    (:meth:`ViewportQuery.set_cache_bytes`) in a process that serves many viewings."""
    return _query(float(CellGrid(cell_deg).cell_deg), frustum, float(step_deg))


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
    cache_bytes : int, bytes of weights kept at most (the oldest bins go first): a head
        path visits a new bin almost every frame, so a count alone would let the cache
        grow with the video's length (about 28 KB a bin for 4 deg cells; 8 MiB keeps ~300)
    """

    def __init__(
        self,
        cell_deg: float,
        frustum: Frustum,
        *,
        step_deg: float = 0.5,
        cache_size: int = 8192,
        cache_bytes: int = 8 << 20,
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
        self._cache_bytes = int(cache_bytes)
        self._bytes = 0

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
        size = sum(a.nbytes for a in (base, w, b[3], b[4]))
        while self._bins and (
            len(self._bins) >= self._cache_size or self._bytes + size > self._cache_bytes
        ):
            old = self._bins.pop(next(iter(self._bins)))
            self._bytes -= sum(a.nbytes for a in (old[0], old[1], old[3], old[4]))
        self._bins[key] = b
        self._bytes += size
        return b

    def set_cache_bytes(self, cache_bytes: int) -> None:
        """Keep at most ``cache_bytes`` of bin weights from now on (the oldest go first)."""
        self._cache_bytes = int(cache_bytes)
        while self._bins and self._bytes > self._cache_bytes:
            old = self._bins.pop(next(iter(self._bins)))
            self._bytes -= sum(a.nbytes for a in (old[0], old[1], old[3], old[4]))

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
        out = np.empty(len(yaw))
        if f.ndim == 2:
            d = self.doubled(f)
            for t in range(len(yaw)):
                out[t] = self.query(d, yaw[t], pitch[t], roll[t])
            return out
        if f.ndim != 3 or f.shape[0] != len(yaw):
            raise InputError(f"{f.shape[0]} field frames but {len(yaw)} orientations")
        return self.many_stacked((f,), yaw, pitch, roll)[0]

    def many_stacked(self, fields, yaw_deg, pitch_deg, roll_deg) -> NDArray[np.float64]:
        """Exact EPOF ``(K, T)`` of ``K`` fields ``(T, n_lat, n_lon)`` seen through the same
        viewports (one orientation per frame): one weight lookup and one index per frame
        for all ``K`` (e.g. an EPOF and its parts)."""
        yaw, pitch, roll = (np.asarray(a, float).ravel() for a in (yaw_deg, pitch_deg, roll_deg))
        T, n_lon = len(yaw), self._n_lon
        if not all(np.shape(f) == (T, *self.cells.shape) for f in fields):
            shapes = [np.shape(f) for f in fields]
            raise InputError(f"fields {shapes} for {T} orientations of {self.cells.shape} cells")
        if not (np.isfinite(yaw).all() and np.isfinite(pitch).all() and np.isfinite(roll).all()):
            raise InputError("head orientation has non-finite values")
        flats = [np.asarray(f).reshape(T, -1) for f in fields]
        out = np.empty((len(fields), T))
        for t in range(T):
            key, shift = self._key(yaw[t], pitch[t], roll[t])
            _, w, wsum, rowbase, cols = self._bin(key)
            idx = rowbase + (cols + shift) % n_lon
            for k, fl in enumerate(flats):  # a 1-D gather and dot each: faster than (m, K)
                out[k, t] = float(fl[t][idx] @ w) / wsum
        return out
