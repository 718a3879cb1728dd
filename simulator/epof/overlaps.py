"""Paper-mode EPOF: overlap weights of a viewport with the sliding windows, and their weighted mean.

The paper's section 3.5: the EPOF of a viewport is the overlap-weighted mean of the
perceived optical flow (POF) of every sliding window overlapping it::

    EPOF = sum_n POF_n * OL_n / sum_n OL_n

with ``OL_n`` = the fraction of the viewport's solid angle that lies inside window n.
The viewport may have roll (the windows have none); yaw wraps around at +-180 deg and
viewports pitched beyond the grid (up to +-90 deg) use whatever windows they overlap
(if none at all, the nearest window's POF). ``top_k`` keeps only the k largest overlaps
(the paper's figure shows 4). Units: POF and EPOF in deg/s of visual angle; angles in
degrees (yaw + right, pitch + up, roll + right ear down; simulator.sphere.geometry conventions).

How it is fast (one query ~10 us, batches > 10^6 queries/s)
-----------------------------------------------------------
The grid is yaw-regular, so the overlap of a viewport with window (p, y) depends only on
the viewport's pitch and roll, the window row p and the yaw difference. For a table of
viewport (pitch, roll) and yaw offsets within one yaw step, :class:`ViewportOverlaps`
integrates the overlaps once by dense ray sampling of the viewport (pixel-centre rays
weighted by their exact solid angles) against an exact per-row membership description
of the windows (runs of window-relative longitude per latitude band, so every yaw
difference on the table's lattice is done at once with a cumulative sum). A query
interpolates the table trilinearly (pitch, roll, yaw offset) and pairs the overlaps
with the window POFs rotated by the whole number of yaw steps.
"""

from __future__ import annotations

import functools
import math

import numpy as np
from numpy.typing import NDArray

from simulator.core.errors import InputError
from simulator.media.gridfile import GridFile
from simulator.sphere.geometry import check_fov, head_angles_deg, head_rotation, perspective_rays
from simulator.sphere.windows import WindowGrid

__all__ = [
    "ViewportOverlaps",
    "epof_from_grid",
    "viewport_fov",
    "viewport_overlaps",
    "weighted_epof",
]


def _window_runs(grid: WindowGrid, lat_step_deg: float, lon_step_deg: float):
    """Membership of each window row as runs of window-relative longitude per latitude band.

    Returns ``(start_deg, length_deg)``, each shape (P, n_lat, R): for latitude band b
    (centre ``-90 + (b + 0.5) * lat_step``) a direction at window-relative longitude
    ``dlon`` is inside a window of row p iff ``dlon`` lies (mod 360) in one of the runs
    ``[start, start + length]`` (length 0 = unused slot, 360 = whole circle).
    """
    n_lat = round(180.0 / lat_step_deg)
    n_lon = round(360.0 / lon_step_deg)
    lat = np.radians(-90.0 + (np.arange(n_lat) + 0.5) * lat_step_deg)[:, None]
    lon = np.radians(-180.0 + (np.arange(n_lon) + 0.5) * lon_step_deg)[None, :]
    cl = np.cos(lat)
    d = np.stack(
        np.broadcast_arrays(cl * np.sin(lon), np.sin(lat), cl * np.cos(lon)), axis=-1
    ).astype(np.float32)
    tx = math.tan(math.radians(grid.hfov_deg) / 2)
    ty = math.tan(math.radians(grid.vfov_deg) / 2)
    runs_all = []
    for pitch in grid.pitch_deg:
        m = head_rotation(0.0, pitch, 0.0).as_matrix().astype(np.float32)
        w = d @ m  # window-frame coordinates (R^T d as row vectors)
        z = w[..., 2]
        inside = (z > 0) & (np.abs(w[..., 0]) <= tx * z) & (np.abs(w[..., 1]) <= ty * z)
        rows = []
        for b in range(n_lat):
            row = inside[b]
            if row.all():
                rows.append([(-180.0, 360.0)])
                continue
            if not row.any():
                rows.append([])
                continue
            starts = np.flatnonzero(row & ~np.roll(row, 1))
            ends = np.flatnonzero(row & ~np.roll(row, -1))
            if ends[0] < starts[0]:  # the first run wraps past +180
                ends = np.roll(ends, -1)
            length = (ends - starts) % n_lon + 1
            rows.append(
                [
                    (-180.0 + s * lon_step_deg, L * lon_step_deg)
                    for s, L in zip(starts.tolist(), length.tolist())
                ]
            )
        runs_all.append(rows)
    R = max(1, max(len(r) for rows in runs_all for r in rows))
    P = len(grid.pitch_deg)
    start = np.zeros((P, n_lat, R))
    length = np.zeros((P, n_lat, R))
    for p, rows in enumerate(runs_all):
        for b, r in enumerate(rows):
            for k, (s, L) in enumerate(r):
                start[p, b, k], length[p, b, k] = s, L
    return start, length


#: Plain numbers a single query may be given (Python's and numpy's scalars).
_SCALARS = (int, float, np.integer, np.floating)


class ViewportOverlaps:
    """Overlap fractions of a viewport with every window of a grid, from a precomputed table.

    Parameters
    ----------
    grid : WindowGrid
        The sliding windows (no roll; yaw-regular).
    hfov_deg, vfov_deg : float, degrees
        The viewport's exact FOVs.
    pitch_step_deg, roll_step_deg : float, degrees
        Table spacing in viewport pitch (-90..90) and roll (-180..180).
    yaw_step_deg : float, degrees
        Table spacing in yaw (rounded so that it divides the grid's yaw step).
    rays : int
        The viewport is sampled by ``rays x rays`` pixel-centre rays with their solid
        angles when the table is built.

    The table has shape (n_pitch, n_roll, n_u, P, Y), float32: entry
    ``[i, j, u, p, m]`` is the overlap of a viewport at pitch ``pitch_grid[i]``, roll
    ``roll_grid[j]`` and yaw ``yaw_start + u * du`` with the window of row p whose yaw is
    m steps to its left (window column ``-m mod Y``).
    """

    def __init__(
        self,
        grid: WindowGrid,
        hfov_deg: float,
        vfov_deg: float,
        *,
        pitch_step_deg: float = 5.0,
        roll_step_deg: float = 10.0,
        yaw_step_deg: float = 3.0,
        rays: int = 48,
        lat_step_deg: float = 0.25,
        lon_step_deg: float = 0.1,
    ):
        self.grid = grid
        self.hfov_deg, self.vfov_deg = float(hfov_deg), float(vfov_deg)
        P, Y = grid.shape
        self.shape = (P, Y)
        self.step = float(grid.yaw_step_deg)
        self.yaw_start = float(grid.yaw_start_deg)
        self.n_u = max(1, math.ceil(self.step / yaw_step_deg - 1e-9))
        du = self.step / self.n_u
        n = Y * self.n_u  # yaw-difference lattice over 360 deg, spacing du
        self.pitch_grid = np.linspace(-90.0, 90.0, round(180.0 / pitch_step_deg) + 1)
        self.roll_grid = np.linspace(-180.0, 180.0, round(360.0 / roll_step_deg) + 1)
        start, length = _window_runs(grid, lat_step_deg, lon_step_deg)
        n_lat = start.shape[1]
        dirs, sa = perspective_rays((rays, rays), self.hfov_deg, self.vfov_deg)
        dirs = dirs.reshape(-1, 3).astype(np.float64)
        sa = sa.reshape(-1).astype(np.float64)
        omega = sa.sum()
        tab = np.empty((len(self.pitch_grid), len(self.roll_grid), self.n_u + 1, P, Y), np.float32)
        m_idx = (np.arange(Y)[None, :] * self.n_u + np.arange(self.n_u + 1)[:, None]) % n
        poff = (np.arange(P) * (2 * n + 1))[:, None, None]
        for i, pv in enumerate(self.pitch_grid):
            for j, rv in enumerate(self.roll_grid):
                w = dirs @ head_rotation(0.0, pv, rv).as_matrix().T
                lon = np.degrees(np.arctan2(w[:, 0], w[:, 2]))
                lat = np.degrees(np.arcsin(np.clip(w[:, 1], -1, 1)))
                b = np.clip(((lat + 90.0) / lat_step_deg).astype(np.int64), 0, n_lat - 1)
                s = start[:, b, :].transpose(0, 2, 1)  # (P, R, N)
                L = length[:, b, :].transpose(0, 2, 1)
                # 1e-9 step of slack: a ray exactly on a run edge (diagonal rays at pitch
                # +-90 land on whole degrees) counts as inside whatever the rounding noise.
                lo = np.ceil((s - lon) / du - 1e-9)
                hi = np.floor((s + L - lon) / du + 1e-9)
                cnt = np.clip(hi - lo + 1, 0, n).astype(np.int64)
                cnt[L <= 0] = 0
                j0 = lo.astype(np.int64) % n
                wts = np.broadcast_to(sa, cnt.shape)
                idx = np.concatenate([(poff + j0).ravel(), (poff + j0 + cnt).ravel()])
                val = np.concatenate([wts.ravel(), -wts.ravel()])
                diff = np.bincount(idx, val, minlength=P * (2 * n + 1)).reshape(P, 2 * n + 1)
                cs = np.cumsum(diff[:, : 2 * n], axis=1)
                B = (cs[:, :n] + cs[:, n:]) / omega  # (P, n): overlap at yaw difference j*du
                tab[i, j] = B[:, m_idx].transpose(1, 0, 2)
        tab.setflags(write=False)
        self.table = tab
        self._flat = tab.reshape(-1, P * Y)
        # each table row's total overlap (the denominator of the fast single query), float64
        self._row_sums = tab.sum(axis=(3, 4), dtype=np.float64)
        self._rows4 = tab.reshape(*tab.shape[:3], P * Y)
        nr, nu = len(self.roll_grid), self.n_u + 1
        self._corner = np.array(
            [a * nr * nu + b * nu + c for a in (0, 1) for b in (0, 1) for c in (0, 1)], np.int64
        )
        self._m = np.arange(Y)
        self._p_off = (np.arange(P) * Y)[:, None]
        self._dp = float(self.pitch_grid[1] - self.pitch_grid[0])
        self._dr = float(self.roll_grid[1] - self.roll_grid[0])
        self._np, self._nr = len(self.pitch_grid), len(self.roll_grid)
        # Flat POF index of table column m for yaw shift k: p * Y + (k - m) mod Y.
        self._perm = [(self._p_off + (k - self._m[None, :]) % Y).ravel() for k in range(Y)]
        cp, cy = grid.centres_deg()
        self._centres = head_rotation(cy.ravel(), cp.ravel(), 0.0).apply([0.0, 0.0, 1.0])

    # -- queries
    def _canonical(self, yaw, pitch, roll):
        yaw = np.asarray(yaw, np.float64)
        pitch = np.asarray(pitch, np.float64)
        roll = np.asarray(roll, np.float64)
        yaw, pitch, roll = np.broadcast_arrays(yaw, pitch, roll)
        yaw, pitch, roll = (np.array(a, np.float64).ravel() for a in (yaw, pitch, roll))
        if not (
            np.all(np.isfinite(yaw)) and np.all(np.isfinite(pitch)) and np.all(np.isfinite(roll))
        ):
            raise InputError("viewport orientation must be finite degrees")
        big = np.abs(pitch) > 90.0
        if np.any(big):  # re-express through the rotation: pitch back in [-90, 90]
            y2, p2, r2 = head_angles_deg(head_rotation(yaw[big], pitch[big], roll[big]))
            yaw[big], pitch[big], roll[big] = y2, p2, r2
        roll = (roll + 180.0) % 360.0 - 180.0
        return yaw, pitch, roll

    def _interp(self, yaw, pitch, roll):
        """Trilinear table rows: overlaps ``(Q, P*Y)`` in table order, and yaw shift k."""
        yaw, pitch, roll = self._canonical(yaw, pitch, roll)
        dp = self.pitch_grid[1] - self.pitch_grid[0]
        dr = self.roll_grid[1] - self.roll_grid[0]
        fp = (pitch + 90.0) / dp
        i0 = np.clip(np.floor(fp).astype(np.int64), 0, len(self.pitch_grid) - 2)
        wp = fp - i0
        fr = (roll + 180.0) / dr
        j0 = np.clip(np.floor(fr).astype(np.int64), 0, len(self.roll_grid) - 2)
        wr = fr - j0
        a = (yaw - self.yaw_start) / self.step
        k = np.floor(a)
        fu = (a - k) * self.n_u
        u0 = np.clip(np.floor(fu).astype(np.int64), 0, self.n_u - 1)
        wu = fu - u0
        base = (i0 * len(self.roll_grid) + j0) * (self.n_u + 1) + u0
        w = np.empty((base.size, 8))
        c = 0
        for ap in (1 - wp, wp):
            for ar in (1 - wr, wr):
                for au in (1 - wu, wu):
                    w[:, c] = ap * ar * au
                    c += 1
        rows = self._flat[base[:, None] + self._corner[None, :]]  # (Q, 8, P*Y)
        ol = np.matmul(w[:, None, :].astype(np.float32), rows)[:, 0, :]
        return ol, k.astype(np.int64) % self.shape[1]

    def overlaps(self, yaw_deg, pitch_deg, roll_deg=0.0) -> NDArray[np.float32]:
        """Overlap fraction of the viewport with every window, shape (Q, P, Y).

        Orientation in degrees (scalars or arrays broadcasting to Q queries).
        """
        ol, k = self._interp(yaw_deg, pitch_deg, roll_deg)
        P, Y = self.shape
        cols = (k[:, None] - self._m[None, :]) % Y  # window column of table column m
        out = np.empty_like(ol).reshape(-1, P, Y)
        q = np.arange(ol.shape[0])[:, None, None]
        out[q, np.arange(P)[None, :, None], cols[:, None, :]] = ol.reshape(-1, P, Y)
        return out

    def _fast_one(self, pof2d: NDArray[np.float32], yaw: float, pitch: float, roll: float) -> float:
        """One query, plain Python index arithmetic (the per-frame real-time path): the 8
        table rows around the orientation are dotted with the POF first (one matrix-vector
        product), their trilinear weights applied to the 8 sums and to the rows' totals
        (precomputed), so no overlap vector is built."""
        if not (-90.0 <= pitch <= 90.0):
            return float(self.epof(pof2d, yaw, pitch, roll, chunk=1))
        roll = (roll + 180.0) % 360.0 - 180.0
        fp = (pitch + 90.0) / self._dp
        i0 = min(int(fp), self._np - 2)
        wp = fp - i0
        fr = (roll + 180.0) / self._dr
        j0 = min(int(fr), self._nr - 2)
        wr = fr - j0
        a = (yaw - self.yaw_start) / self.step
        k = math.floor(a)
        fu = (a - k) * self.n_u
        u0 = min(int(fu), self.n_u - 1)
        wu = fu - u0
        g = pof2d.reshape(-1)[self._perm[k % self.shape[1]]]
        n0, n1, n2, n3, n4, n5, n6, n7 = (self._rows4[i0 : i0 + 2, j0 : j0 + 2, u0 : u0 + 2] @ g).flat
        d0, d1, d2, d3, d4, d5, d6, d7 = self._row_sums[i0 : i0 + 2, j0 : j0 + 2, u0 : u0 + 2].flat
        v0 = 1.0 - wu
        r0 = 1.0 - wr
        den = (1.0 - wp) * (r0 * (v0 * d0 + wu * d1) + wr * (v0 * d2 + wu * d3)) + wp * (
            r0 * (v0 * d4 + wu * d5) + wr * (v0 * d6 + wu * d7)
        )
        if den <= 1e-6:
            return float(self.epof(pof2d, yaw, pitch, roll, chunk=1))
        num = (1.0 - wp) * (r0 * (v0 * n0 + wu * n1) + wr * (v0 * n2 + wu * n3)) + wp * (
            r0 * (v0 * n4 + wu * n5) + wr * (v0 * n6 + wu * n7)
        )
        return float(num / den)

    def epof(self, pof, yaw_deg, pitch_deg, roll_deg=0.0, frames=None, *, top_k=None, chunk=1024):
        """EPOF (same unit as ``pof``) of each query.

        Parameters
        ----------
        pof : ndarray, shape (T, P, Y) or (P, Y)
            Window flow per frame.
        yaw_deg, pitch_deg, roll_deg : array_like, degrees, broadcasting to (Q,)
        frames : array_like of int, shape (Q,) or scalar; frame of each query (0 if pof is 2-D)
        top_k : int or None; keep only the k largest overlaps of each query

        Returns
        -------
        ndarray, float64, the broadcast shape of the orientations (a float for scalars)
        """
        pof = np.asarray(pof, np.float32)
        if pof.ndim == 2:
            pof = pof[None]
        T = pof.shape[0]
        P, Y = self.shape
        if pof.shape[1:] != (P, Y):
            raise InputError(f"pof has shape {pof.shape}; expected (T, {P}, {Y})")
        if top_k is not None and not (1 <= int(top_k)):
            raise InputError(f"top_k must be >= 1; got {top_k}")
        if (
            top_k is None
            and chunk != 1
            and isinstance(yaw_deg, _SCALARS)
            and isinstance(pitch_deg, _SCALARS)
            and isinstance(roll_deg, _SCALARS)
            and (frames is None or isinstance(frames, _SCALARS))
        ):  # one query of plain numbers: the real-time path (isinstance, not np.ndim: 4 us)
            fi = 0 if frames is None else int(frames)
            if not 0 <= fi < T:
                raise InputError(f"frame {fi} out of range 0..{T - 1}")
            y, p, r = float(yaw_deg), float(pitch_deg), float(roll_deg)
            if math.isfinite(y) and math.isfinite(p) and math.isfinite(r):
                return self._fast_one(pof[fi], y, p, r)
        yaw, pitch, roll = np.broadcast_arrays(
            np.asarray(yaw_deg, float), np.asarray(pitch_deg, float), np.asarray(roll_deg, float)
        )
        shape = yaw.shape
        yaw, pitch, roll = yaw.ravel(), pitch.ravel(), roll.ravel()
        f = np.broadcast_to(np.asarray(0 if frames is None else frames, np.int64), shape).ravel()
        if f.size and (f.min() < 0 or f.max() >= T):
            raise InputError(f"frame index out of range 0..{T - 1}")
        flat = pof.reshape(T, P * Y)
        # POF of window column (k - m) mod Y for table column m, as a sliding window:
        # ext[t, p, j] = pof[t, p, (Y - j) mod Y] for j < 2Y; columns k..: ext[.., Y-k+m].
        ext = pof[:, :, (-np.arange(2 * Y)) % Y]
        win = np.lib.stride_tricks.sliding_window_view(ext, Y, axis=2)  # (T, P, Y+1, Y)
        p_ix = np.arange(P)[None, :]
        out = np.empty(yaw.size, np.float64)
        step = max(1, int(chunk))
        for s in range(0, yaw.size, step):
            sl = slice(s, s + step)
            ol, k = self._interp(yaw[sl], pitch[sl], roll[sl])
            g = win[f[sl][:, None], p_ix, (Y - k)[:, None]].reshape(len(k), P * Y)
            if top_k is not None and int(top_k) < P * Y:
                kk = int(top_k)
                part = np.argpartition(ol, P * Y - kk, axis=1)[:, : P * Y - kk]
                np.put_along_axis(ol, part, 0.0, axis=1)
            num = np.einsum("qn,qn->q", ol, g, dtype=np.float64)
            den = ol.sum(axis=1, dtype=np.float64)
            e = np.divide(num, np.where(den > 1e-6, den, 1.0))
            none = den <= 1e-6
            if np.any(none):  # viewport outside every window: nearest window's flow
                fwd = head_rotation(yaw[sl][none], pitch[sl][none], roll[sl][none]).apply(
                    [0, 0, 1.0]
                )
                near = np.argmax(np.atleast_2d(fwd) @ self._centres.T, axis=1)
                e[none] = flat[f[sl][none], near]
            out[sl] = e
        if shape == ():
            return float(out[0])
        return out.reshape(shape)


def weighted_epof(pof, overlaps, *, top_k: int | None = None) -> float:
    """The paper's eq. (section 3.5) for one viewport: sum POF_n OL_n / sum OL_n.

    ``pof`` and ``overlaps`` (fractions of the viewport, 0..1) have the same shape (any);
    ``top_k`` keeps the k largest overlaps. The paper's example: flows 16, 15.5, 16.8, 17
    with overlaps 0.90, 0.88, 0.85, 0.80 give 16.3. (:meth:`ViewportOverlaps.epof` is the
    vectorised form of this.)
    """
    f = np.asarray(pof, np.float64).ravel()
    w = np.asarray(overlaps, np.float64).ravel()
    if f.shape != w.shape:
        raise InputError(f"pof and overlaps differ in size: {f.size} vs {w.size}")
    if top_k is not None and top_k < w.size:
        keep = np.argsort(w, kind="stable")[-int(top_k) :]
        f, w = f[keep], w[keep]
    den = w.sum()
    if den <= 0:
        raise InputError("the viewport overlaps no window")
    return float((f * w).sum() / den)


@functools.lru_cache(maxsize=8)
def viewport_overlaps(grid: WindowGrid, hfov_deg: float, vfov_deg: float) -> ViewportOverlaps:
    """The (cached) :class:`ViewportOverlaps` of a grid and viewport FOV (degrees)."""
    return ViewportOverlaps(grid, hfov_deg, vfov_deg)


def viewport_fov(grid: GridFile, hfov_deg=None, vfov_deg=None) -> tuple[float, float]:
    """Viewport FOV (degrees): the grid's window FOV by default, ``vfov`` = ``hfov`` when
    only that is given; checked by the one rule, :func:`simulator.sphere.geometry.check_fov`."""
    h = grid.hfov_deg if hfov_deg is None else hfov_deg
    v = (grid.vfov_deg if hfov_deg is None else h) if vfov_deg is None else vfov_deg
    return check_fov(h, v, source="viewport")


def _frames(grid: GridFile) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """``(frame, time_s)`` of each grid row: video frame numbers and their times (s from
    the video start). A grid made with ``preprocess --start`` begins at ``meta["start_frame"]``
    (``GridFile.frame_times_s`` counts from 0 regardless)."""
    start = int(grid.meta.get("start_frame", 0) or 0)
    frames = start + np.arange(grid.n_frames, dtype=np.int64)
    times = grid.meta.get("frame_times_s")  # a variable-rate video: its timestamps
    if times is not None and len(times) == grid.n_frames:
        return frames, np.asarray(times, float)
    return frames, frames / float(grid.fps)


def epof_from_grid(
    grid: GridFile,
    yaw_deg,
    pitch_deg,
    roll_deg,
    frames,
    *,
    hfov_deg: float | None = None,
    vfov_deg: float | None = None,
    top_k: int | None = None,
    pof=None,
) -> NDArray[np.float64]:
    """EPOF in deg/s for each (frame, orientation) query, vectorised.

    Parameters
    ----------
    grid : GridFile
    yaw_deg, pitch_deg, roll_deg : float or array_like, degrees (broadcast together)
    frames : int or array_like of int, frame index of each query
    hfov_deg, vfov_deg : float, degrees; viewport FOV, default the grid's window FOV
        (``vfov_deg`` defaults to ``hfov_deg`` when only that is given)
    top_k : int, optional; use only the k largest overlaps
    pof : another (T, P, Y) or (P, Y) window matrix to average instead of ``grid.pof_dps``
        (e.g. the covered windows, giving the covered share of each view)

    Returns
    -------
    ndarray, float64, the broadcast shape of the orientation arguments
    """
    h, v = viewport_fov(grid, hfov_deg, vfov_deg)
    key = tuple(
        (k, tuple(x) if isinstance(x, list) else x) for k, x in sorted(grid.meta["grid"].items())
    )
    return _overlaps_for(key, h, v).epof(
        grid.pof_dps if pof is None else pof, yaw_deg, pitch_deg, roll_deg, frames, top_k=top_k
    )


def _overlaps_for(grid_key: tuple, hfov_deg: float, vfov_deg: float) -> ViewportOverlaps:
    return viewport_overlaps(WindowGrid.from_dict(dict(grid_key)), hfov_deg, vfov_deg)
