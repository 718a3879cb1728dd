"""The camera's own rotation from a frame pair's flow on the sphere: a robust fit over every direction, and the flow with it removed.

For a frame pair, sphere mode knows, at every evaluated tile pixel, the unit ray ``r0``
of the content at frame t-1 and the ray ``r1`` it moved to at frame t (world frame = the
equirect frame: +x right, +y up, +z forward). Its *rotation vector*
``c = angle(r0, r1) * (r0 x r1) / |r0 x r1|`` (radians) is what a rotation of the content
by ``w`` (a rotation vector, radians per frame) gives as ``P(r0) w``, ``P(r) = I - r r^T``
(to first order; the fit is iterated with the exact residual below). A camera that also
translates by ``t`` adds, at depth ``d``, ``(r0 x t) / d``: perpendicular to ``t``'s own
great circles, so the component of ``c - P w`` along ``t_perp = P(r0) t`` is free of
it whatever the depth: ``(c - w) . t_perp = 0`` (the continuous epipolar constraint).

:func:`fit_rotation` solves for ``w`` and the translation direction ``t`` together by
alternating least squares on those constraints, per lon/lat cell (the cell means of
``c``), with Tukey's biweight against cells that move on their own (people, vehicles:
independently moving content must not drag the estimate). The camera's angular
velocity is the opposite of the content's: ``omega_cam = -w * fps``.

The residual of a pixel (the flow with the rotation removed: parallax of the
translation plus anything moving on its own) is the rotation taking ``R(w) r0`` to
``r1``; per cell, the length of the mean residual vector (less the flow's noise where no
translation is fitted: :func:`residual_speed`) is the *translational part* of the flow
(:mod:`simulator.epof.parts`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import cv2
import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from simulator.sphere.cells import CellGrid
from simulator.sphere.geometry import dir_to_lonlat, lonlat_to_dir

__all__ = [
    "EGO_META",
    "EgoFit",
    "EgoRows",
    "FrameParts",
    "MidpointSplat",
    "adjust_parts",
    "fit_rotation",
    "residual_speed",
]

#: ``meta["ego"]`` of a grid with the per-frame camera rotation (sphere mode).
EGO_META = {
    "ego_omega_dps": "camera angular velocity, deg/s, (T, 3) vector in the world (equirect) "
    "frame at t-1: right-handed about +x right, +y up, +z forward; yaw rate = y, pitch rate "
    "= -x, roll rate = -z",
    "ego_confidence": "0..1: share of the sphere the fitted camera motion explains, times "
    "how evenly it constrains the rotation",
    "field_trans_dps": "deg/s: the speed with the fitted camera rotation removed (parallax "
    "of the translation and independently moving content): the length of each cell's mean "
    "residual vector, less the flow's noise where no translation is fitted "
    "(simulator.preprocess.ego.residual_speed)",
    "method": "robust fit over every cell (Tukey), rotation plus translation direction "
    "(continuous epipolar constraint); simulator.preprocess.ego",
}


@dataclass(frozen=True)
class FrameParts:
    """One frame pair's results: ``field`` and ``trans`` (n_lat, n_lon) float32 deg/s (the
    speed, and the speed with the camera rotation removed), ``omega_dps`` (3,) float32 the
    camera's angular velocity (deg/s, world frame = the equirect frame at t-1, right-handed
    about +x right, +y up, +z forward), ``confidence`` in [0, 1]
    (:class:`simulator.preprocess.ego.EgoFit`)."""

    field: NDArray[np.float32]
    trans: NDArray[np.float32]
    omega_dps: NDArray[np.float32]
    confidence: float


def adjust_parts(p: FrameParts, mask, scale) -> FrameParts:
    """``p`` without flow outside the covered cells (``mask``), speeds scaled by a variable
    frame rate's true interval (``scale``: :func:`simulator.preprocess.common.flow_rate_scale`)."""
    if mask is None and scale is None:
        return p
    k = np.float32(1.0 if scale is None else scale)
    m = np.float32(1.0) if mask is None else mask
    return replace(p, field=p.field * m * k, trans=p.trans * m * k, omega_dps=p.omega_dps * k)


class EgoRows:
    """The per-frame camera rotation and translational field of a run: ``trans`` (a
    :class:`FieldSpool` or anything with ``append``), ``omega_dps`` (T, 3) and
    ``confidence`` (T,) float32 (:meth:`arrays`; row 0 repeats row 1)."""

    def __init__(self, trans):
        self.trans = trans
        self._omega: list = []
        self._conf: list = []

    def append(self, p: FrameParts) -> None:
        self.trans.append(p.trans)
        self._omega.append(p.omega_dps)
        self._conf.append(p.confidence)

    def arrays(self) -> dict[str, NDArray[np.float32]]:
        """``{"ego_omega_dps": (T, 3), "ego_confidence": (T,)}`` float32, row 0 = row 1."""
        om = np.asarray(self._omega[:1] + self._omega, np.float32).reshape(-1, 3)
        cf = np.asarray(self._conf[:1] + self._conf, np.float32)
        return {"ego_omega_dps": om, "ego_confidence": cf}


#: Tukey biweight scale, in units of the robust (MAD) spread of the cell residuals.
_TUKEY_C = 4.685
#: Residual spread floor, radians per frame (0.05 deg: sub-pixel flow noise).
_SIGMA_MIN = np.radians(0.05)
_ITERATIONS = 5


@dataclass(frozen=True)
class EgoFit:
    """One frame pair's fit.

    w : (3,) content rotation vector, radians per frame, world frame
    t : (3,) unit translation direction (sign arbitrary; zeros when not determined)
    confidence : float in [0, 1]: the share of the sphere (cells, by solid angle) the
        fitted camera motion explains (Tukey weight > 0), times how well those cells
        constrain ``w`` (1 when they cover the sphere evenly enough: smallest over largest
        eigenvalue of their normal matrix >= 1/2)
    """

    w: NDArray[np.float64]
    t: NDArray[np.float64]
    confidence: float


def _solve_w(c, d, wt, t):
    """``w`` minimising sum wt |P_t (c - P(d) w)|^2, with P_t the projection on t_perp
    (all of the tangent plane when t is None)."""
    if t is None:
        # sum wt P(d)^T P(d) w = sum wt P(d) c; P(d) c = c (c is tangent)
        A = np.eye(3) * wt.sum() - (d * wt[:, None]).T @ d
        b = wt @ c
    else:
        tp = t[None, :] - (d @ t)[:, None] * d  # t_perp per cell
        # (c - w) . tp = 0  ->  tp^T w = tp^T c
        wtp = tp * wt[:, None]
        A = wtp.T @ tp
        b = wtp.T @ (tp * c).sum(axis=1)
    return np.linalg.solve(A + np.eye(3) * (1e-9 * max(np.trace(A), 1e-30)), b), A


def _solve_t(c, d, wt, w):
    """Unit ``t`` minimising sum wt ((c - w) . P(d) t)^2: the smallest eigenvector."""
    e = c - w[None, :]
    a = e - (e * d).sum(axis=1, keepdims=True) * d  # P(d) e
    M = (a * wt[:, None]).T @ a
    vals, vecs = np.linalg.eigh(M)
    return vecs[:, 0], vals


def _residuals(c, d, w, t):
    """Per-cell residual (radians per frame) of the model: the component of ``c - P w``
    across the translation's great circles, or its whole length when ``t`` is None."""
    e = c - (w[None, :] - (d @ w)[:, None] * d)
    if t is None:
        return np.linalg.norm(e, axis=1)
    tp = t[None, :] - (d @ t)[:, None] * d
    n = np.linalg.norm(tp, axis=1)
    return np.abs((e * tp).sum(axis=1)) / np.maximum(n, 1e-9)


def _tukey(r, base):
    sig = max(1.4826 * float(np.median(r[base > 0])) if np.any(base > 0) else 0.0, _SIGMA_MIN)
    x = r / (_TUKEY_C * sig)
    return base * np.where(x < 1.0, (1.0 - x * x) ** 2, 0.0)


def fit_rotation(
    cell_vec: NDArray, cell_dir: NDArray, weight: NDArray, *, translation: bool = True
) -> EgoFit:
    """Robust rotation (and translation direction) of the content from per-cell rotation
    vectors.

    Parameters
    ----------
    cell_vec : (C, 3) mean rotation vector ``c`` of each cell's pixels, radians per frame
    cell_dir : (C, 3) unit direction of each cell's centre
    weight : (C,) base weight of each cell (its solid angle covered by pixels; 0 = none)
    translation : also fit the translation direction (the epipolar constraint); False
        fits a pure rotation (every cell's whole residual)
    """
    c = np.asarray(cell_vec, np.float64)
    d = np.asarray(cell_dir, np.float64)
    base = np.where(np.isfinite(c).all(axis=1), np.asarray(weight, np.float64), 0.0)
    c = np.where(base[:, None] > 0, c, 0.0)
    wt = base.copy()
    w, _ = _solve_w(c, d, wt, None)
    t = None
    for it in range(_ITERATIONS):
        if translation and it > 0:
            t, vals = _solve_t(c, d, wt, w)
            # a translation is only fitted when it explains clearly more than noise
            if vals[0] > 0.5 * vals[1]:
                t = None
        wt = _tukey(_residuals(c, d, w, t), base)
        w, _ = _solve_w(c, d, wt, t)
    wt = _tukey(_residuals(c, d, w, t), base)
    _, A = _solve_w(c, d, wt, None)
    ev = np.linalg.eigvalsh(A)
    span = float(ev[0] / ev[-1]) if ev[-1] > 0 else 0.0
    share = float(base[wt > 0].sum() / base.sum()) if base.sum() > 0 else 0.0
    conf = share * min(1.0, 2.0 * span)
    return EgoFit(w=w, t=np.zeros(3) if t is None else t, confidence=float(np.clip(conf, 0, 1)))


#: Median of a chi-square variable of 2 degrees of freedom (2 ln 2): the power of
#: isotropic 2-D Gaussian noise over its variance per component.
_CHI2_2_MEDIAN = 1.3863


def residual_speed(vec, cell_dir, t, speed, ok) -> NDArray[np.float64]:
    """Per cell: the speed of the flow with the camera rotation removed (radians per
    frame).

    ``vec`` (C, 3): each cell's mean residual rotation vector (world frame; averaging the
    vectors, not their lengths, lets noise that varies within a cell cancel);
    ``cell_dir`` (C, 3) unit directions (unused but for the shape check); ``t`` (3,) the
    fitted translation direction (zeros: none fitted); ``speed`` (C,) the cells'
    measured speed; ``ok`` (C,) cells with pixels.

    - **no translation fitted** (the fit found none above the noise): the residual is
      flow noise, or content moving on its own. The length of a noisy vector is biased
      upward (a pure rotation's residual reads 3-5 % of the speed, which would count as
      translation), so its noise power is removed: ``sqrt(max(|vec|^2 - 2 sigma^2, 0))``,
      ``sigma^2 = speed^2 * median(|vec|^2 / speed^2) / 1.386`` over the cells (the
      noise grows with the motion; the median of a 2-degree-of-freedom chi-square is
      1.386): content moving on its own, far above the noise, keeps its speed;
    - **a translation fitted**: ``|vec|``. Its parallax dominates the residual, and any
      discount tried removed real parallax where the translation is weak (the fitted
      heading is then uncertain: in a 20 m room, projecting on ``d x t`` kept 0.90 of
      the truth's translational part, removing a noise floor 0.84-0.95).
    """
    if np.shape(cell_dir) != np.shape(vec):
        raise ValueError("residual_speed: vec and cell_dir must both be (C, 3)")
    m2 = (vec * vec).sum(axis=1)
    good = ok & (speed > 1e-9)
    if np.any(t) or not good.any():
        return np.sqrt(m2)
    s2 = speed * speed
    eps2 = np.median(m2[good] / s2[good]) / _CHI2_2_MEDIAN
    return np.sqrt(np.maximum(m2 - 2.0 * eps2 * s2, 0.0))


class MidpointSplat:
    """Per-frame cell means of a frame pair's tile flow, each pixel counted in the cell of
    its path's *midpoint*, plus the camera rotation and the residual (translational) field.

    A pixel's angle is the motion of its content over the frame interval; the truth (and
    any instantaneous speed) belongs to where the content is at the interval's middle.
    Counting it in the cell of ``r0`` instead biases fields that vary along the motion
    (5 % high down a corridor at 5 m/s): here it goes to the cell of the pixel position
    plus half its flow (looked up in a per-tile table of cell indices, extended beyond
    the tile by ``pad`` pixels). Cells no midpoint falls in (rare, polar) take the value
    of the static splat (the cell of ``r0``). A pixel's weight is its solid angle times
    the tile blend at the less reliable end of its path (:meth:`_frame_weight`).

    Parameters
    ----------
    tile_rot : (n, 3, 3) tile -> world rotation matrices
    size : tile side, pixels; ``tan_half`` : tan(tile FOV / 2)
    sel : slice of the evaluated pixels (stride); ``u0, v0`` : their plane coordinates
    weight : (n, s', s') base weight of each evaluated pixel (solid angle x blend)
    cells : CellGrid; ``splat`` : the static (C, n px) splat matrix (fallback)
    cx, cy : plane units per pixel of x and y (``RayAngles._cx``, ``_cy``)
    """

    def __init__(
        self, tile_rot, size, tan_half, sel, u0, v0, weight, cells: CellGrid, splat, cx, cy, pad=48
    ):
        n, s = len(tile_rot), int(size)
        self.pad, self.ext = int(pad), s + 2 * int(pad)
        xs = (np.arange(-pad, s + pad) + 0.5) / s * 2.0 - 1.0
        uu, vv = np.meshgrid(xs * tan_half, -xs * tan_half)
        rays = np.stack([uu, vv, np.ones_like(uu)], -1)
        rays /= np.linalg.norm(rays, axis=-1, keepdims=True)
        world = np.einsum("nij,hwj->nhwi", tile_rot, rays, optimize=True).reshape(-1, 3)
        lon, lat = dir_to_lonlat(world)
        self.lut = cells.index(lon, lat).astype(np.int32).reshape(n, self.ext, self.ext)
        g = np.arange(s)[sel].astype(np.float32) + np.float32(pad + 0.5)
        self.gx, self.gy = np.meshgrid(g, g)
        self.sel = sel
        self.tile_rot = np.asarray(tile_rot, np.float64)
        self.u0, self.v0 = u0, v0
        self.weight = np.ascontiguousarray(weight, np.float64).reshape(-1)
        self.tan_half = np.float32(tan_half)
        # the static blend of each evaluated pixel (the one in ``weight``) and its solid
        # angle alone, for the per-frame blend at the flow's target (:meth:`_frame_weight`)
        b0 = _smoothstep(
            (self.tan_half - np.maximum(np.abs(u0), np.abs(v0))) / (self.tan_half - np.float32(1.0))
        )
        self._blend0 = b0.astype(np.float32)
        wt = self.weight.reshape(-1, *b0.shape)
        self._area = np.where(b0 > 0, wt / np.where(b0 > 0, b0, 1.0), 0.0)
        self.splat = splat
        self.cells = cells
        self.cx, self.cy = np.float32(cx), np.float32(cy)
        lo, la = cells.centres_lonlat()
        self.cell_dir = lonlat_to_dir(*np.meshgrid(lo, la)).reshape(-1, 3)
        self._tile = np.arange(n)[:, None, None]
        self._tile_off = (self._tile * self.ext * self.ext).astype(np.int32)
        self._row = np.arange(cells.n_cells) // cells.shape[1]
        # bins of k x k cells (~12 deg) for the fit; direction = mean of their cell centres
        k = max(1, round(12.0 / cells.cell_deg))
        n_lon = cells.shape[1]
        r, c = np.divmod(np.arange(cells.n_cells), n_lon)
        self._bin = (r // k) * (-(-n_lon // k)) + c // k
        sa = cells.solid_angles().reshape(-1)
        bd = np.stack(
            [np.bincount(self._bin, weights=sa * self.cell_dir[:, i]) for i in range(3)], -1
        )
        self._bin_dir = bd / np.linalg.norm(bd, axis=1, keepdims=True)

    def _cell_mean(self, idx, values, den, weight):
        """Weighted cell means of per-pixel ``values``; cells without pixels this frame
        take the static splat's value (their rows only)."""
        v = values.reshape(-1)
        num = np.bincount(idx, weights=weight * v, minlength=den.size)
        out = num / np.where(den > 0, den, 1.0)
        empty = den <= 0
        if empty.any():  # tiny polar cells: the mean of their latitude row
            rn = np.bincount(self._row, weights=num, minlength=self.cells.shape[0])
            rd = np.bincount(self._row, weights=den, minlength=self.cells.shape[0])
            if np.all(rd[self._row[empty]] > 0):
                out[empty] = (rn / np.where(rd > 0, rd, 1.0))[self._row[empty]]
            else:
                e = np.flatnonzero(empty)
                out[e] = self.splat[e] @ v
        return out

    def __call__(self, flow: NDArray, ang: NDArray, components=None):
        """``(field, trans_field, EgoFit)``: cell means (radians per frame) of the angles
        ``ang`` (n, s', s') and of the residual angles, and the rotation fit, for pixel
        flow ``flow`` (n, s, s, 2) (x right, y down); ``components``: its evaluated
        ``(dx, dy)`` (n, s', s') contiguous, when the caller has them (not modified)."""
        if components is None:
            sub = flow[:, self.sel, self.sel, :]
            fx, fy = np.ascontiguousarray(sub[..., 0]), np.ascontiguousarray(sub[..., 1])
        else:
            fx, fy = components
        hi = self.ext - 1
        # midpoint pixel (rounded; gx, gy hold the pixel centres + pad + 0.5)
        xi = np.clip((self.gx + np.float32(0.5) * fx).astype(np.int32), 0, hi)
        yi = np.clip((self.gy + np.float32(0.5) * fy).astype(np.int32), 0, hi)
        yi *= self.ext
        yi += xi
        yi += self._tile_off
        idx = self.lut.take(yi).reshape(-1)
        C = self.cells.n_cells
        wt = self._frame_weight(fx, fy)
        den = np.bincount(idx, weights=wt, minlength=C)
        field = self._cell_mean(idx, ang, den, wt)
        # the fit and the residual run on every other evaluated pixel: their (tile, cell)
        # keys and weights, made once for both
        n, h = len(self.tile_rot), slice(None, None, 2)
        sub = (self._tile_key(idx, n, C, h), wt.reshape(n, *self.u0.shape)[:, h, h])
        # the fit, in coarser bins of cells (~12 deg)
        vsum, dsum = self._cell_vectors(sub, fx, fy, ang)
        nb = self._bin_dir.shape[0]
        bw = np.bincount(self._bin, weights=dsum, minlength=nb)
        bv = np.stack(
            [np.bincount(self._bin, weights=vsum[:, k], minlength=nb) for k in range(3)], -1
        )
        fit = fit_rotation(bv / np.where(bw > 0, bw, 1.0)[:, None], self._bin_dir, bw)
        return field, self._trans_field(sub, dsum, fit, fx, fy, field), fit

    def _tile_key(self, idx, n: int, C: int, h: slice):
        """``tile * C + cell`` of the evaluated pixels of the slice ``h`` (flat)."""
        return (idx.reshape(n, *self.u0.shape)[:, h, h] + self._tile * C).reshape(-1)

    def _trans_field(self, sub, den, fit, fx, fy, field):
        """Per cell (radians per frame): the speed of the flow with the rotation removed,
        from the cell's mean residual rotation vector (:func:`residual_speed`), on every
        other evaluated pixel (stride 4 at DIS ultrafast's: its flow's own resolution);
        ``sub`` = their (tile, cell) keys and weights, ``den`` (C,) the cells' weights."""
        n, C = len(self.tile_rot), self.cells.n_cells
        h = slice(None, None, 2)
        fx, fy = fx[:, h, h], fy[:, h, h]
        ang, crx, cry, crz, m = self._residual(fit.w, fx, fy, h)
        key, wsub = sub[0], sub[1].reshape(-1)
        # each pixel's residual as a rotation vector (angle x unit axis), tile coordinates
        k = (ang / np.maximum(m, np.float32(1e-12))).reshape(-1) * wsub
        parts = [np.bincount(key, weights=k * c.reshape(-1), minlength=n * C) for c in (crx, cry, crz)]
        vec = (np.stack(parts, -1).reshape(n, C, 3) @ self.tile_rot.transpose(0, 2, 1)).sum(axis=0)
        vec /= np.where(den > 0, den, 1.0)[:, None]
        st = residual_speed(vec, self.cell_dir, fit.t, field, den > 0)
        empty = den <= 0
        if empty.any():  # tiny polar cells: the mean of their latitude row
            rn = np.bincount(self._row, weights=st * den, minlength=self.cells.shape[0])
            rd = np.bincount(self._row, weights=den, minlength=self.cells.shape[0])
            st[empty] = (rn / np.where(rd > 0, rd, 1.0))[self._row[empty]]
        return st

    def _frame_weight(self, fx, fy):
        """Per evaluated pixel: its solid angle times the tile blend at the less reliable
        of its two ends (its position, or its flow *target*): a pixel whose content leaves
        the tile (fast motion near a border) cannot be matched and reads low; the
        overlapping tile, where both ends lie inside, measures it. No flow: the static
        weights."""
        q0 = np.abs(self.u0 + fx * self.cx)
        q1 = np.abs(self.v0 + fy * self.cy)
        np.maximum(q0, q1, out=q0)
        b = _smoothstep((self.tan_half - q0) / (self.tan_half - np.float32(1.0)))
        np.minimum(b, self._blend0, out=b)
        return (self._area * b).reshape(-1)

    def _cell_vectors(self, sub, fx, fy, ang):
        """``(C, 3)`` weighted sums of the rotation vectors of every other evaluated pixel
        (each direction) per cell, world frame (summed per (tile, cell) in tile
        coordinates, then rotated per tile), and ``(C,)`` their weights; ``sub`` = those
        pixels' (tile, cell) keys and weights."""
        n, C = len(self.tile_rot), self.cells.n_cells
        h = slice(None, None, 2)
        fx, fy, ang = fx[:, h, h], fy[:, h, h], ang[:, h, h]
        du, dv = fx * self.cx, fy * self.cy
        cz = self.u0[h, h] * dv - self.v0[h, h] * du
        scale = ang / np.maximum(np.sqrt(du * du + dv * dv + cz * cz), np.float32(1e-12))
        key, wsub = sub
        ws = (wsub * scale).reshape(-1)
        parts = [
            np.bincount(key, weights=ws * comp.reshape(-1), minlength=n * C)
            for comp in (-dv, du, cz)
        ]
        vt = np.stack(parts, -1).reshape(n, C, 3)  # tile coordinates
        dsum = np.bincount(key, weights=wsub.reshape(-1), minlength=n * C)
        vec = (vt @ self.tile_rot.transpose(0, 2, 1)).sum(axis=0)
        return vec, dsum.reshape(n, C).sum(axis=0)

    def _residual(self, w, fx, fy, h):
        """Per evaluated pixel (those of the slice ``h``; ``fx``, ``fy`` already sliced):
        the angle (radians) between ``R(w) r0`` and ``r1``, the flow with the rotation
        removed, and the cross product ``R(w) r0 x r1`` (3 arrays) with its length, in
        tile coordinates (``r = (u, v, 1)``)."""
        Rw = _rotvec_matrix(w)
        Rt = (self.tile_rot.transpose(0, 2, 1) @ Rw @ self.tile_rot).astype(np.float32)
        R = Rt[:, :, :, None, None]
        u0, v0 = self.u0[h, h], self.v0[h, h]
        p0, p1, p2 = (R[:, i, 0] * u0 + R[:, i, 1] * v0 + R[:, i, 2] for i in range(3))
        q0 = u0 + fx * self.cx
        q1 = v0 + fy * self.cy
        crx = p1 - p2 * q1
        cry = p2 * q0 - p0
        crz = p0 * q1 - p1 * q0
        dot = p0 * q0 + p1 * q1 + p2
        cols = dot.shape[-1]
        m = cv2.magnitude(crx.reshape(-1, cols), cry.reshape(-1, cols))
        m = cv2.magnitude(m, crz.reshape(-1, cols))
        return cv2.phase(dot.reshape(-1, cols), m), crx, cry, crz, m


def _smoothstep(x):
    """``3x^2 - 2x^3`` of ``x`` clipped to [0, 1] (float32 in, float32 out)."""
    x = np.clip(x, np.float32(0.0), np.float32(1.0))
    return x * x * (np.float32(3.0) - np.float32(2.0) * x)


def _rotvec_matrix(w: NDArray) -> NDArray[np.float64]:
    """Rotation matrix of a rotation vector (Rodrigues)."""
    return Rotation.from_rotvec(np.asarray(w, np.float64)).as_matrix()
