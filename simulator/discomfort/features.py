"""Discomfort features of a video or of one viewing, from vimsim's own sphere-mode outputs only: named, versioned, with units.

Every feature is computed from a sphere-mode grid file (``vimsim preprocess --method
sphere``: the field ``field_dps``, its translational part ``field_trans_dps`` and the
camera's angular velocity ``ego_omega_dps`` with its ``ego_confidence``) and, for a
viewing, the viewer's head path. Nothing else: no poses, no depth.

- **Per video** (no head path), the EPOF is that of a viewer looking everywhere equally:
  the solid-angle weighted mean of the field over the whole sphere, per frame. Its
  rotational and translational parts split each cell's speed by
  :func:`simulator.epof.parts.rotation_share` (the rule of ``vimsim epof``'s parts).
- **Per viewing** (a head path), the EPOF, its parts and the GRF opacity are those of
  :func:`simulator.epof.viewing.compute_epof` for that head path.
- The camera's rates (``yaw_rate``, ``pitch_rate``, ``roll_rate``: ``vimsim ego``'s
  columns, deg/s, about the camera's axes) are the camera's whatever the viewer does.
  Their means are weighted by the ego fit's confidence per frame (0..1): a frame whose
  fit is poor (much of the picture moving on its own, no texture) counts less. So are
  the camera's angular acceleration and the view's rotation against the content: the
  camera's angular velocity plus the head's (:func:`head_omega_dps`, both in the world =
  equirect frame), 0 for a head that turns with the content, the camera's own for a
  video (no head).
- Blocks are 1 s long (``round(fps)`` frames, at least 1; the last partial block
  counted); a block feature is the largest block mean.
- The opacity is the absolute rule of the named bands: 0 at 5, 1 at 30 deg/s
  (:mod:`simulator.mitigation.bands`), so it means the same in every video.

:data:`FEATURES_VERSION` changes whenever a definition changes; a model fitted on one
version refuses features of another (:mod:`simulator.discomfort.model`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from simulator.core.errors import InputError
from simulator.epof.parts import MAKE_PARTS_HINT, has_parts, rotation_share
from simulator.epof.viewing import compute_epof
from simulator.media.gridfile import GridFile, require_field
from simulator.media.lazyfield import LazyField
from simulator.mitigation.bands import ABSOLUTE_HIGH_DPS, ABSOLUTE_LOW_DPS
from simulator.mitigation.grf import OpacityRule
from simulator.sphere.geometry import head_rotation

__all__ = [
    "FEATURES",
    "FEATURES_VERSION",
    "Feature",
    "feature_names",
    "features_from_grid",
    "head_omega_dps",
    "sphere_series",
]

#: Version of the feature definitions below (a model records it and refuses others).
FEATURES_VERSION = "1"


@dataclass(frozen=True)
class Feature:
    """One feature: its ``name`` (a column of the features table), ``unit`` and what it is."""

    name: str
    unit: str
    description: str


#: Every feature, in the order a model's columns take them.
FEATURES: tuple[Feature, ...] = (
    Feature("duration_s", "s", "length of the video (or of the viewing's frames)"),
    Feature("epof_mean_dps", "deg/s", "mean EPOF over the frames"),
    Feature("epof_p90_dps", "deg/s", "90th percentile of the EPOF over the frames"),
    Feature("epof_block_max_dps", "deg/s", "largest 1 s block mean of the EPOF"),
    Feature("epof_rot_mean_dps", "deg/s", "mean rotational part of the EPOF"),
    Feature("epof_trans_mean_dps", "deg/s", "mean translational part of the EPOF"),
    Feature("time_above_high_share", "1", "share of frames whose EPOF is above 30 deg/s"),
    Feature("opacity_mean", "1", "mean GRF opacity, absolute rule 0 at 5 and 1 at 30 deg/s"),
    Feature("yaw_rate_mean_dps", "deg/s", "camera's mean |yaw rate|, confidence-weighted"),
    Feature("pitch_rate_mean_dps", "deg/s", "camera's mean |pitch rate|, confidence-weighted"),
    Feature("roll_rate_mean_dps", "deg/s", "camera's mean |roll rate|, confidence-weighted"),
    Feature("yaw_rate_block_max_dps", "deg/s", "largest 1 s block mean of |yaw rate|"),
    Feature("pitch_rate_block_max_dps", "deg/s", "largest 1 s block mean of |pitch rate|"),
    Feature("roll_rate_block_max_dps", "deg/s", "largest 1 s block mean of |roll rate|"),
    Feature("rotation_mean_dps", "deg/s", "camera's mean angular speed, confidence-weighted"),
    Feature(
        "rotation_change_mean_dps2",
        "deg/s^2",
        "camera's mean angular acceleration |d omega / dt|, confidence-weighted",
    ),
    Feature(
        "view_rate_mean_dps",
        "deg/s",
        "the view's rotation against the content |omega_camera + omega_head| (the "
        "camera's angular speed for a video), confidence-weighted",
    ),
    Feature("ego_confidence_mean", "1", "mean confidence of the camera-rotation fit (0..1)"),
)


def feature_names() -> list[str]:
    """The names of :data:`FEATURES`, in order."""
    return [f.name for f in FEATURES]


def _rows(field, i0: int, i1: int) -> NDArray[np.float32]:
    if isinstance(field, LazyField):
        return field.block(i0, i1).astype(np.float32, copy=False)
    return np.asarray(field[i0:i1], np.float32)


def sphere_series(grid: GridFile) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``(epof, rot)`` (T,) deg/s: the sphere-mean speed of each frame (a viewer looking
    everywhere equally) and its rotational part, read chunk by chunk (memory flat in
    the video's length)."""
    field, cells = require_field(grid)
    trans = grid.field_trans_dps
    omega = np.asarray(grid.extras["ego_omega_dps"], np.float64)
    sa = cells.solid_angles().astype(np.float64)
    sa = sa / sa.sum()
    T = len(omega)
    n = min([x.chunk_rows for x in (field, trans) if isinstance(x, LazyField)] or [256])
    epof, rot = np.empty(T), np.empty(T)
    for i0 in range(0, T, n):
        i1 = min(T, i0 + n)
        f = _rows(field, i0, i1)
        part = f * rotation_share(f, _rows(trans, i0, i1), omega[i0:i1], cells)
        epof[i0:i1] = np.einsum("tij,ij->t", f.astype(np.float64), sa)
        rot[i0:i1] = np.einsum("tij,ij->t", part.astype(np.float64), sa)
    return epof, rot


def _block_max(x: NDArray, n: int, w: NDArray | None = None) -> float:
    """Largest (``w``-weighted) mean of consecutive blocks of ``n`` rows (the last one
    partial; a block whose weights are all 0 counts unweighted)."""
    w = np.ones_like(x) if w is None else w
    return float(
        max(
            np.average(x[i : i + n], weights=w[i : i + n])
            if w[i : i + n].sum() > 0
            else x[i : i + n].mean()
            for i in range(0, len(x), n)
        )
    )


def head_omega_dps(time_s, yaw_deg, pitch_deg, roll_deg) -> NDArray[np.float64]:
    """``(T, 3)`` the head's angular velocity (deg/s, world = equirect frame, as
    ``ego_omega_dps``) from its pose at each frame; row 0 repeats row 1."""
    R = head_rotation(np.asarray(yaw_deg), np.asarray(pitch_deg), np.asarray(roll_deg))
    dt = np.diff(np.asarray(time_s, np.float64))
    w = np.degrees((R[1:] * R[:-1].inv()).as_rotvec()) / np.maximum(dt, 1e-9)[:, None]
    return np.vstack([w[:1], w]) if len(w) else np.zeros((len(R), 3))


def _rate_features(grid: GridFile, rows: NDArray[np.int64], block: int, head=None) -> dict:
    om = np.asarray(grid.extras["ego_omega_dps"], np.float64)[rows]
    conf = np.clip(np.asarray(grid.extras["ego_confidence"], np.float64)[rows], 0.0, 1.0)
    rates = np.abs(np.column_stack([om[:, 1], -om[:, 0], -om[:, 2]]))  # yaw, pitch, roll
    w = conf if conf.sum() > 0 else np.ones_like(conf)
    out: dict[str, float] = {}
    for k, axis in enumerate(("yaw", "pitch", "roll")):
        out[f"{axis}_rate_mean_dps"] = float(np.average(rates[:, k], weights=w))
        out[f"{axis}_rate_block_max_dps"] = _block_max(rates[:, k], block, w)
    out["rotation_mean_dps"] = float(np.average(np.linalg.norm(om, axis=1), weights=w))
    acc = np.linalg.norm(np.diff(om, axis=0), axis=1) * float(grid.fps)
    out["rotation_change_mean_dps2"] = (
        float(np.average(acc, weights=np.minimum(w[1:], w[:-1]) + 1e-12)) if len(acc) else 0.0
    )
    view = om if head is None else om + np.asarray(head, np.float64)[rows]
    out["view_rate_mean_dps"] = float(np.average(np.linalg.norm(view, axis=1), weights=w))
    out["ego_confidence_mean"] = float(conf.mean())
    return out


def features_from_grid(grid: GridFile, headpath=None) -> dict[str, float]:
    """The features (:data:`FEATURES`, units there) of a sphere-mode grid with the
    camera's rotation: of the video, or of the viewing of ``headpath`` (a
    :class:`simulator.traces.path.HeadPath` covering the grid's frames).

    Frame 0 of a grid repeats frame 1 and is left out. InputError (naming the grid and
    the fix) for a grid without a field or without the per-frame camera rotation."""
    src = grid.path or "grid"
    if grid.field_dps is None or not has_parts(grid):
        raise InputError(
            f"{src}: grid has no sphere-mode field with the camera's rotation; {MAKE_PARTS_HINT}"
        )
    if grid.n_frames < 2:
        raise InputError(f"{src}: grid has {grid.n_frames} frame(s); features need at least 2")
    rule = OpacityRule(low_dps=ABSOLUTE_LOW_DPS, high_dps=ABSOLUTE_HIGH_DPS)
    head = None
    if headpath is None:
        epof, rot = sphere_series(grid)
        lo, hi = ABSOLUTE_LOW_DPS, ABSOLUTE_HIGH_DPS
        opacity = np.clip((epof - lo) / (hi - lo), 0.0, 1.0)
    else:
        res = compute_epof(grid, headpath, method="sphere", rule=rule)
        epof, rot, opacity = res.epof_dps, res.epof_rot_dps, res.opacity
        head = head_omega_dps(res.time_s, res.yaw_deg, res.pitch_deg, res.roll_deg)
    rows = np.arange(1, grid.n_frames)
    epof, rot, opacity = epof[rows], rot[rows], opacity[rows]
    block = max(1, round(grid.fps))
    feats = {
        "duration_s": float(grid.n_frames / grid.fps),
        "epof_mean_dps": float(epof.mean()),
        "epof_p90_dps": float(np.percentile(epof, 90)),
        "epof_block_max_dps": _block_max(epof, block),
        "epof_rot_mean_dps": float(rot.mean()),
        "epof_trans_mean_dps": float((epof - rot).mean()),
        "time_above_high_share": float((epof > ABSOLUTE_HIGH_DPS).mean()),
        "opacity_mean": float(opacity.mean()),
        **_rate_features(grid, rows, block, head),
    }
    bad = [k for k, v in feats.items() if not np.isfinite(v)]
    if bad:
        raise InputError(f"{src}: feature(s) {', '.join(bad)} are not finite numbers")
    return {name: feats[name] for name in feature_names()}
