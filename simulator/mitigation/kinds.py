"""Mitigations beyond the paper (tunneling vignette, flow-local grains) and the flow that still reaches the eye.

A :class:`Mitigation` says what is drawn over the video (one of
:data:`simulator.core.choices.MITIGATIONS`):

* ``grf`` (default): the paper's world-fixed grains, alpha ``cutout(ecc) * opacity``
  (:mod:`simulator.mitigation.grf`);
* ``vignette``: a head-fixed dynamic FOV restriction ("tunneling", Fernandes & Feiner
  2016). Its **aperture diameter**, in degrees of visual field around the view axis
  (as Meta's tunneling specifies it, so the look is the same on every headset), shrinks
  linearly with the opacity from the full view at opacity 0 (nothing blocked: the view's
  corner eccentricity plus half the feather) to ``aperture_min_deg`` at opacity 1. The
  edge is soft, linear in angle, ``feather_deg`` wide and centred on the aperture radius
  ``r``: ``alpha(ecc) = clamp((ecc - r) / feather + 1/2, 0, 1)`` (a step at ``r`` for
  feather 0), in ``color`` (black by default);
* ``grf+vignette``: both from the same opacity (grains first, the vignette over them);
* ``local-grf``: the grains drawn only where the image moves: each direction's grain
  alpha is ``cutout(ecc) * opacity_rule(f_c)`` with ``f_c`` the sphere-mode field's flow
  (deg/s) of the cell the direction falls in, through the same percentile thresholds as
  the EPOF opacity (:func:`cell_opacity`); the frame's EPOF opacity is not used;
* ``none``: nothing.

:func:`visible_flow` measures what each one lets through: per frame, the viewport's flow
weighted by the solid angle and the visibility ``1 - alpha`` of what is drawn over each
direction, as a ratio to the unmitigated EPOF, and the share of the view blocked.
Angles are degrees at the boundary (``*_deg``), radians inside; world +x right, +y up,
+z forward; eccentricity is the angle from the head's forward axis.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from simulator.core.errors import InputError
from simulator.media.lazyfield import LazyField, field_chunks
from simulator.mitigation.grf import GrainField, GrfConfig, cutout_alpha
from simulator.sphere.cells import CellGrid, Frustum
from simulator.sphere.geometry import head_rotation

__all__ = [
    "KINDS",
    "Kind",
    "Mitigation",
    "VisibleFlow",
    "cell_opacity",
    "parse_color",
    "visible_flow",
]

#: Default smallest aperture, degrees of visual field (see docs/mitigation.md).
APERTURE_MIN_DEG = 60.0
#: Default soft-edge width, degrees.
FEATHER_DEG = 10.0


@dataclass(frozen=True)
class Kind:
    """One mitigation kind, its whole definition (an entry of :data:`KINDS`).

    name : as ``--mitigation`` spells it (:data:`simulator.core.choices.MITIGATION_HELP`
        gives its help line)
    grains, vignette : flags: it draws the world-fixed grains / the head-fixed vignette
    local : flag: the grain opacity is each cell's own, from a sphere-mode field
        (:func:`cell_opacity`), not the frame's
    defines : the eye shader's defines it switches on (``shaders/eye.frag``), e.g.
        ``VIGNETTE``; ``grain_defines`` likewise, only while grains are drawn
    alpha : its alpha rule, as docs/mitigation.md states it
    visible : its visible-flow rule: ``visible(rays) -> visibility`` of every sampled ray
        of one frame (:class:`_Rays`: ``rays.grains(alpha)``, ``rays.vignette()``, the
        frame's and the cells' grain alpha), ``1 - alpha`` of what is drawn, multiplied
    """

    name: str
    alpha: str
    visible: Callable[[_Rays], object]
    grains: bool = False
    vignette: bool = False
    local: bool = False
    defines: tuple[str, ...] = ()
    grain_defines: tuple[str, ...] = ()


#: Every mitigation kind, by name, in :data:`simulator.core.choices.MITIGATIONS`' order:
#: a new kind is one entry here (and its name and help line in ``core/choices.py``).
KINDS: dict[str, Kind] = {
    k.name: k
    for k in (
        Kind(
            "grf",
            "cutout(ecc) * opacity on grain pixels",
            lambda r: r.grains(r.frame_grain_alpha()),
            grains=True,
        ),
        Kind(
            "vignette",
            "clamp((ecc - r(opacity)) / feather + 1/2, 0, 1)",
            lambda r: r.vignette(),
            vignette=True,
            defines=("VIGNETTE",),
        ),
        Kind(
            "grf+vignette",
            "visibility multiplies: (1 - a_grain)(1 - a_vignette)",
            lambda r: r.grains(r.frame_grain_alpha()) * r.vignette(),
            grains=True,
            vignette=True,
            defines=("VIGNETTE",),
        ),
        Kind(
            "local-grf",
            "cutout(ecc) * rule(f_cell) on grain pixels",
            lambda r: r.grains(r.cell_grain_alpha()),
            grains=True,
            local=True,
            grain_defines=("LOCAL_GRF",),
        ),
        Kind("none", "0", lambda r: 1.0),
    )
}
#: Every define a kind may switch on (each is 0 in the shader unless its kind's).
SHADER_DEFINES: tuple[str, ...] = tuple(
    sorted({d for k in KINDS.values() for d in (*k.defines, *k.grain_defines)})
)


def parse_color(text: str) -> tuple[float, float, float]:
    """``"#RRGGBB"`` or ``"R,G,B"`` (0..255 each) -> RGB in [0, 1]; InputError otherwise."""
    t = str(text).strip()
    msg = f"vignette colour must be #RRGGBB or R,G,B with 0..255 each, e.g. 0,0,0; got {text!r}"
    try:
        if t.startswith("#") and len(t) == 7:
            vals = [int(t[i : i + 2], 16) for i in (1, 3, 5)]
        else:
            vals = [int(v) for v in t.split(",")]
    except ValueError:
        raise InputError(msg) from None
    if len(vals) != 3 or not all(0 <= v <= 255 for v in vals):
        raise InputError(msg)
    return tuple(v / 255.0 for v in vals)


@dataclass(frozen=True)
class Mitigation:
    """What is drawn over the video, and the vignette's parameters (degrees).

    kind : one of :data:`simulator.core.choices.MITIGATIONS` (default ``"grf"``)
    aperture_min_deg : vignette aperture diameter at opacity 1, degrees of visual field,
        in (0, FOV) (checked against the view by :meth:`check_view`); default 60
    feather_deg : width of the vignette's soft edge, degrees >= 0 (default 10)
    color : vignette colour, RGB in [0, 1] (default black)
    """

    kind: str = "grf"
    aperture_min_deg: float = APERTURE_MIN_DEG
    feather_deg: float = FEATHER_DEG
    color: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise InputError(
                f"unknown mitigation {self.kind!r}; expected one of {', '.join(KINDS)}"
            )
        a, f = float(self.aperture_min_deg), float(self.feather_deg)
        if not (math.isfinite(a) and 0.0 < a < 180.0):
            raise InputError(
                f"--aperture-min must be degrees in (0, FOV), e.g. 60; got {self.aperture_min_deg}"
            )
        if not (math.isfinite(f) and 0.0 <= f <= 180.0):
            raise InputError(f"--feather must be degrees >= 0, e.g. 10; got {self.feather_deg}")
        c = tuple(float(v) for v in self.color)
        if len(c) != 3 or not all(0.0 <= v <= 1.0 for v in c):
            raise InputError(f"vignette colour must be RGB in [0, 1]; got {self.color!r}")
        object.__setattr__(self, "aperture_min_deg", a)
        object.__setattr__(self, "feather_deg", f)
        object.__setattr__(self, "color", c)

    @property
    def entry(self) -> Kind:
        """The kind's entry of :data:`KINDS`."""
        return KINDS[self.kind]

    @property
    def grains(self) -> bool:
        """Grains are drawn (``grf``, ``grf+vignette``, ``local-grf``)."""
        return self.entry.grains

    @property
    def vignette(self) -> bool:
        return self.entry.vignette

    @property
    def local(self) -> bool:
        return self.entry.local

    def shader_defines(self, grains: bool) -> dict[str, int]:
        """The eye shader's mitigation defines (:data:`SHADER_DEFINES`), 0 or 1;
        ``grains``: grains are drawn (a GRF is configured)."""
        on = {*self.entry.defines, *(self.entry.grain_defines if grains else ())}
        return {d: int(d in on) for d in SHADER_DEFINES}

    def check_view(self, frustum: Frustum) -> None:
        """InputError unless the aperture lies inside the view: ``aperture_min < hfov``."""
        if self.vignette and not self.aperture_min_deg < frustum.hfov_deg:
            raise InputError(
                f"--aperture-min must be degrees in (0, FOV) = (0, {frustum.hfov_deg:g}); "
                f"got {self.aperture_min_deg:g}"
            )

    def aperture_radius_rad(self, opacity: float, frustum: Frustum) -> float:
        """Aperture radius (radians, where the vignette alpha is 1/2) at ``opacity`` 0..1:
        linear in the opacity from the full view (:func:`full_radius_rad`) to
        ``aperture_min_deg / 2``."""
        o = min(max(float(opacity), 0.0), 1.0)
        r0 = full_radius_rad(frustum) + math.radians(self.feather_deg) / 2.0
        r1 = math.radians(self.aperture_min_deg) / 2.0
        return r0 + (r1 - r0) * o

    def vignette_alpha(self, ecc_rad, opacity: float, frustum: Frustum) -> NDArray[np.float64]:
        """Vignette alpha (0..1) at eccentricities ``ecc_rad`` (radians, any shape)."""
        e = np.asarray(ecc_rad, float)
        if not self.vignette:
            return np.zeros_like(e)
        r = self.aperture_radius_rad(opacity, frustum)
        fw = math.radians(self.feather_deg)
        if fw <= 0.0:
            return (e >= r).astype(np.float64)
        return np.clip((e - r) / fw + 0.5, 0.0, 1.0)


def full_radius_rad(frustum: Frustum) -> float:
    """Largest eccentricity in the view (its farthest corner), radians."""
    tl, tr, td, tu = (
        math.tan(math.radians(a))
        for a in (frustum.left_deg, frustum.right_deg, frustum.down_deg, frustum.up_deg)
    )
    return math.atan(math.hypot(max(tl, tr), max(td, tu)))


def cell_opacity(field_dps: NDArray, thresholds_dps: tuple[float, float]) -> NDArray[np.float32]:
    """Per-cell grain opacity of local-grf: the EPOF opacity rule (clamped linear ramp
    between the ``(lo, hi)`` thresholds, deg/s) applied to each cell's flow.

    field_dps : ndarray or LazyField, shape (T, n_lat, n_lon), deg/s (a lazy field is
    read chunk by chunk). Returns float32, same shape.
    """
    lo, hi = (float(v) for v in thresholds_dps)
    if not (math.isfinite(lo) and math.isfinite(hi)):
        raise InputError("local-grf needs the opacity thresholds of a grid (--grid GRID.npz)")
    if not isinstance(field_dps, LazyField):
        field_dps = np.asarray(field_dps)
    out = np.empty(tuple(field_dps.shape), np.float32)
    for i0, c in field_chunks(field_dps):
        f = np.asarray(c, np.float64)
        if hi > lo:
            op = np.clip((f - lo) / (hi - lo), 0.0, 1.0)
        else:
            op = (f > lo).astype(np.float64)
        out[i0 : i0 + len(f)] = op
    return out


@dataclass(frozen=True)
class VisibleFlow:
    """What reaches the eye, per frame (arrays shape (N,)).

    visible_dps : visible flow, deg/s: EPOF times ``ratio``
    ratio : visible flow / unmitigated flow of the viewport (1 = nothing blocked)
    blocked : share of the view (by solid angle) blocked, 0..1
    """

    visible_dps: NDArray[np.float64]
    ratio: NDArray[np.float64]
    blocked: NDArray[np.float64]


def view_samples(frustum: Frustum, n: int = 128):
    """``(dirs (n*n, 3), solid angle (n*n,))``: pixel-centre rays of an ``n x n`` image of
    the (left-eye) frustum in the head frame, and each pixel's solid angle (steradians)."""
    return _view_samples(frustum, int(n))


@functools.lru_cache(maxsize=8)
def _view_samples(frustum: Frustum, n: int):
    tl, tr, td, tu = (
        math.tan(math.radians(a))
        for a in (frustum.left_deg, frustum.right_deg, frustum.down_deg, frustum.up_deg)
    )
    u = -tl + (np.arange(n) + 0.5) / n * (tl + tr)
    v = tu - (np.arange(n) + 0.5) / n * (tu + td)
    U, V = np.meshgrid(u, v)
    d = np.stack([U, V, np.ones_like(U)], -1).reshape(-1, 3)
    r2 = (d**2).sum(-1)
    sa = (tl + tr) * (tu + td) / (n * n) / r2**1.5
    d = d / np.sqrt(r2)[:, None]
    for a in (d, sa):
        a.setflags(write=False)
    return d, sa


@functools.lru_cache(maxsize=4)
def _grain_tree(grf: GrfConfig):
    from scipy.spatial import cKDTree

    gf = GrainField.from_config(grf)
    return cKDTree(gf.centers), 2.0 * math.sin(gf.radius_rad / 2.0)


class _Rays:
    """The sampled rays of the view in one frame: what a kind's visible-flow rule reads
    (:attr:`Kind.visible`). Grains are at infinity (stereo parallax is ignored)."""

    def __init__(self, mitigation: Mitigation, frustum: Frustum, dirs, grf: GrfConfig | None):
        self.m, self.frustum = mitigation, frustum
        self.ecc = np.arccos(np.clip(dirs[:, 2], -1.0, 1.0))  # radians from the view axis
        self.cut = None  # grain cutout alpha per ray; None: no grains drawn
        if mitigation.grains and grf is not None:
            self.cut = cutout_alpha(np.degrees(self.ecc), grf)
            self.tree, self.chord = _grain_tree(grf)
            self.near = self.cut > 0
        self.frame(0.0, None, None, None)

    def frame(self, opacity: float, world, idx, cell_row) -> None:
        """This frame's opacity, world ray directions, cell index of each ray and the
        cells' grain opacity (local-grf)."""
        self.opacity, self.world, self.idx, self.cell_row = opacity, world, idx, cell_row

    def vignette(self):
        """Visibility ``1 - alpha`` through the vignette at this frame's opacity."""
        return 1.0 - self.m.vignette_alpha(self.ecc, self.opacity, self.frustum)

    def frame_grain_alpha(self):
        """Grain alpha of the frame's opacity: ``cutout(ecc) * opacity`` (None: no grains)."""
        return None if self.cut is None else self.cut * self.opacity

    def cell_grain_alpha(self):
        """Grain alpha of each ray's cell: ``cutout(ecc) * cell opacity`` (None: no grains)."""
        return None if self.cut is None else self.cut * self.cell_row[self.idx]

    def grains(self, alpha):
        """Visibility ``1 - alpha * covered`` (``covered``: the ray hits a grain disc)."""
        if alpha is None:
            return 1.0
        cov = np.zeros(len(self.ecc))
        near = self.near
        if np.any(near) and np.any(alpha[near] > 0):
            dist, _ = self.tree.query(self.world[near], k=1, distance_upper_bound=self.chord)
            cov[near] = dist <= self.chord
        return 1.0 - alpha * cov


def visible_flow(
    mitigation: Mitigation,
    frustum: Frustum,
    angles_deg: NDArray,
    opacity: NDArray,
    epof_dps: NDArray,
    *,
    grf: GrfConfig | None = None,
    field_dps: NDArray | None = None,
    cell_deg: float | None = None,
    cell_op: NDArray | None = None,
    samples: int = 128,
) -> VisibleFlow:
    """Visible flow, its ratio to the unmitigated EPOF, and the blocked share, per frame.

    Parameters
    ----------
    mitigation : Mitigation
    frustum : the (left-eye) viewport
    angles_deg : ndarray, shape (N, 3): yaw, pitch, roll per frame, degrees
    opacity : ndarray, shape (N,): the EPOF-driven opacity 0..1 of each frame
    epof_dps : ndarray, shape (N,): the unmitigated EPOF, deg/s (NaN: no grid)
    grf : grain parameters; None = no grains drawn
    field_dps, cell_deg : sphere-mode field ``(T, n_lat, n_lon)`` (deg/s) and its cell
        size: each direction's own flow. Without it (paper-mode grid) the flow is taken
        as uniform over the view (the EPOF), so the ratio is the visible share.
    cell_op : ``(T, n_lat, n_lon)`` per-cell grain opacity (:func:`cell_opacity`), for
        local-grf
    samples : the view is sampled at ``samples x samples`` pixel-centre rays

    Each ray's visibility is the kind's rule (:attr:`Kind.visible`), e.g.
    ``(1 - grain_alpha * covered) * (1 - vignette_alpha)`` for grf+vignette;
    ``covered``: the ray hits a grain disc (grains at infinity; stereo parallax is
    ignored). ``ratio = sum(f v w) / sum(f w)`` over rays (``f`` flow, ``v`` visibility,
    ``w`` solid angle); where the viewport's flow is 0 it is ``sum(v w) / sum(w)``.
    """
    ang = np.asarray(angles_deg, float).reshape(-1, 3)
    N = ang.shape[0]
    op = np.broadcast_to(np.asarray(opacity, float), (N,))
    epof = np.broadcast_to(np.asarray(epof_dps, float), (N,))
    dirs, sa = view_samples(frustum, samples)
    rays = _Rays(mitigation, frustum, dirs, grf)
    if rays.cut is not None and mitigation.local and cell_op is None:
        raise InputError("local-grf needs a sphere-mode field (--grid made with --method sphere)")
    cells = CellGrid(cell_deg) if cell_deg is not None else None
    rots = head_rotation(ang[:, 0], ang[:, 1], ang[:, 2]).as_matrix()
    ratio = np.empty(N)
    blocked = np.empty(N)
    for t in range(N):
        world = dirs @ rots[t].T
        idx = None
        if cells is not None:
            lon = np.arctan2(world[:, 0], world[:, 2])
            lat = np.arcsin(np.clip(world[:, 1], -1.0, 1.0))
            idx = cells.index(lon, lat)
        row = None if cell_op is None else cell_op[min(t, len(cell_op) - 1)].reshape(-1)
        rays.frame(op[t], world, idx, row)
        vis = mitigation.entry.visible(rays)
        wsum = sa.sum()
        blocked[t] = 1.0 - float((vis * sa).sum() / wsum)
        if field_dps is not None and idx is not None:
            f = np.asarray(field_dps[min(t, len(field_dps) - 1)], np.float64).reshape(-1)[idx]
            fw = float((f * sa).sum())
            ratio[t] = float((f * vis * sa).sum()) / fw if fw > 0 else 1.0 - blocked[t]
        else:
            ratio[t] = 1.0 - blocked[t]
    return VisibleFlow(epof * ratio, ratio, blocked)
