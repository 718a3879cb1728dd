"""What every frame of a viewing shows: its checked inputs, poses, EPOF and opacity (no GL, no files).

:func:`plan_viewing` is the planning half of the one-viewing job, shared by ``vimsim render``
(:func:`simulator.viewing.job.render_viewing`) and ``vimsim frames``: the video probed, the head
path sampled at each frame's time ``i / fps`` (seconds; angles in degrees, yaw + right,
pitch + up, roll + right ear down), the EPOF over ``config.frustum`` and the opacity that
drives the mitigation.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from simulator.core.errors import InputError
from simulator.epof.nearest import nearest_epof
from simulator.epof.viewing import compute_epof, read_epof_csv
from simulator.media.gridfile import MAKE_FIELD_HINT, GridFile, load_grid, require_field
from simulator.media.source import Source, as_source
from simulator.media.video import MediaInfo
from simulator.mitigation.grf import grain_count
from simulator.preprocess.artefacts import stored_artefacts
from simulator.sphere.cells import Frustum
from simulator.traces.path import HeadPath
from simulator.traces.readers import load_headpath
from simulator.viewing.inputs import csv_opacity, frame_range
from simulator.viewing.spec import ViewSpec

__all__ = ["ViewingPlan", "grf_settings", "plan_viewing"]


@dataclass(frozen=True)
class ViewingPlan:
    """One viewing's inputs, checked, and its per-frame poses and GRF opacity.

    info : the video's :class:`simulator.media.video.MediaInfo`
    headpath : the head path; grid : the grid file or None
    frames : ndarray, shape (N,), the video frame numbers of the plan (``f0 .. f1 - 1``)
    times_s : ndarray, shape (N,), time of each frame ``i / fps`` (seconds)
    angles_deg : ndarray, shape (N, 3), (yaw, pitch, roll) of the view in the video frame
        at each frame, degrees: the head's turned by the source's initial orientation
        (:meth:`simulator.media.source.Source.view_angles_deg`; the head's without one)
    epof_dps : ndarray, shape (N,), EPOF (deg/s; NaN without a grid)
    opacity : ndarray, shape (N,), the GRF opacity rendered at each frame (0 without GRF)
    thresholds_dps : the opacity rule's 0 and 1 thresholds (NaN without a grid)
    epof_method : ``paper`` or ``sphere`` (None without a grid)
    opacity_label : what ``opacity`` was given as: ``auto``, a number, or the EPOF CSV's path
    source : the checked :class:`simulator.media.source.Source` (layout, right-eye file)
    epof_eye : the eye whose view the EPOF measures: the grid's eye (its meta) for a
        stereo source, else ``left``
    epof_frustum : the frustum the EPOF was computed over (that eye's; the right eye's
        mirrors the left eye's left and right half-angles)
    coverage : ndarray, shape (N,), covered share of the viewport per frame (a grid of a
        projection not covering the sphere), else None
    """

    info: MediaInfo
    headpath: HeadPath
    grid: GridFile | None
    frames: np.ndarray
    times_s: np.ndarray
    angles_deg: np.ndarray
    epof_dps: np.ndarray
    opacity: np.ndarray
    thresholds_dps: tuple[float, float]
    epof_method: str | None = None
    opacity_label: object = "auto"
    source: Source | None = None
    epof_eye: str = "left"
    epof_frustum: Frustum | None = None
    coverage: np.ndarray | None = None
    #: the artefact kind of each frame (``""``: none) when the grid stores them, else None
    artefact: tuple[str, ...] | None = None
    #: (N, 3) the head path's own (yaw, pitch, roll) at each frame (None: ``angles_deg``)
    head_angles_deg: np.ndarray | None = None
    #: ``--preset cao2021-code``: the nearest window's flow (N,), window px/frame, and the
    #: :class:`simulator.mitigation.cao2021.FixedPxRule` its opacity came from (else None)
    flow_px: np.ndarray | None = None
    px_rule: object = None

    @property
    def right(self) -> str | None:
        """The right eye's own file (two per-eye files), or None."""
        return None if self.source is None else self.source.right

    @property
    def ranged(self) -> bool:
        """True when the plan covers only part of the video."""
        return (int(self.frames[0]), int(self.frames[-1]) + 1) != (0, self.info.n_frames)


def grf_settings(grf) -> dict | None:
    """The GRF parameters as written in ``summary.json`` / ``frames.json`` (None: no GRF)."""
    if grf is None:
        return None
    return {
        "grain_deg": grf.grain_deg,
        "density": grf.density,
        "inner_deg": grf.inner_deg,
        "outer_deg": grf.outer_deg,
        "seed": grf.seed,
        "distance_m": grf.distance_m,
        "n_grains": grain_count(grf),
        "layout": grf.layout,
    }


def _check_needs_grid(view: ViewSpec, grid) -> None:
    """InputError when what is drawn needs a grid (or a sphere-mode field) not given."""
    mit, grf = view.mitigation, view.grains
    if mit.local and grf is not None and grid is None:
        raise InputError(
            f"--mitigation {mit.kind} needs --grid GRID.npz with a sphere-mode field; make one "
            f"with `{MAKE_FIELD_HINT}`"
        )
    if mit.local and grf is not None:
        require_field(grid)  # local-grf on a paper-mode grid: one line with the hint
    if view.drawn and view.opacity == "auto" and grid is None:
        raise InputError(
            "--opacity auto follows the EPOF and needs --grid GRID.npz; or give --opacity 0..1"
        )


def _epof_rows(grid, hp: HeadPath, view: ViewSpec, frustum: Frustum, frames, fps, ranged, pose):
    """``(epof_dps, opacity, thresholds_dps, method, coverage, artefact)`` of the plan's
    ``frames`` (NaN, None, NaN, None, None, None without a grid): the EPOF over ``frustum``,
    the opacity of ``view.rule``, the covered share of the view (None for a full-sphere
    source) and the artefact kinds the grid stores (None when it stores none)."""
    nf = len(frames)
    if grid is None:
        return np.full(nf, np.nan), None, (float("nan"), float("nan")), None, None, None
    rule, f0, f1 = view.rule, int(frames[0]), int(frames[-1]) + 1
    # A range: EPOF of its frames only, plus a warm-up before it so that smoothing
    # and easing have their state at the range's start (cost ~ the range).
    warm = 0
    if ranged:
        warm = int(np.ceil(fps * (rule.ease_in_s + rule.ease_out_s + 5 * rule.smoothing_s)))
    res = compute_epof(
        grid,
        hp,
        frustum=frustum,
        hold=True if ranged else view.hold,
        rule=rule,
        method=view.method,
        frames=(max(0, f0 - warm), f1) if ranged else None,
        artefacts=stored_artefacts(grid),  # those preprocess --artefacts stored: held
        orientation_deg=pose,  # the source's initial orientation (docs/sources.md)
    )
    # Grid rows by video frame number (a grid may start later or lack the last frame).
    rows = np.clip(frames - int(res.frame[0]), 0, len(res.frame) - 1)
    return (
        res.epof_dps[rows].astype(float),
        res.opacity[rows].astype(float),
        tuple(float(v) for v in res.thresholds_dps),
        res.meta["method"],
        None if res.coverage is None else res.coverage[rows].astype(float),
        None if res.artefact is None else tuple(res.artefact[int(r)] for r in rows),
    )


def _rows(grid, hp, view: ViewSpec, frustum, frames, fps, ranged, pose):
    """:func:`_epof_rows` then the flow px/frame and rule of ``--preset cao2021-code``
    (None, None otherwise): :func:`_nearest_rows` with that preset."""
    if grid is not None and view.preset == "cao2021-code":
        return _nearest_rows(grid, hp, view, frames, ranged, pose)
    return (*_epof_rows(grid, hp, view, frustum, frames, fps, ranged, pose), None, None)


def _nearest_rows(grid, hp: HeadPath, view: ViewSpec, frames, ranged, pose):
    """:func:`_epof_rows` of ``--preset cao2021-code`` (the authors' runtime,
    :func:`simulator.epof.nearest.nearest_epof`: no state, no warm-up), and after them the
    nearest window's flow (px/frame) and the fixed-scale rule of its opacity."""
    f0, f1 = int(frames[0]), int(frames[-1]) + 1
    res = nearest_epof(grid, hp, hold=True if ranged else view.hold,
                       frames=(f0, f1) if ranged else None, orientation_deg=pose)  # fmt: skip
    rows = np.clip(frames - int(res.frame[0]), 0, len(res.frame) - 1)
    px = np.asarray(res.meta["flow_px"], float)[rows]
    nan2 = (float("nan"), float("nan"))
    dps, op = res.epof_dps[rows].astype(float), res.opacity[rows].astype(float)
    return dps, op, nan2, res.meta["method"], None, None, px, res.meta["rule"]


def plan_viewing(
    source,
    headpath,
    *,
    grid=None,
    view: ViewSpec | None = None,
    start_s: float | None = None,
    end_s: float | None = None,
    **view_fields,
) -> ViewingPlan:
    """Check a viewing's inputs and work out what every frame shows (no GL, no output).

    What :func:`render_viewing` renders and ``vimsim frames`` renders at chosen moments:
    the head pose at each frame's time ``i / fps`` and, when something is drawn, the
    opacity of ``view`` (a :class:`simulator.viewing.spec.ViewSpec`, or its fields as
    keywords; ``"auto"``: from the EPOF of ``grid`` through ``view.rule``, over its
    frustum; an EPOF CSV's path: its opacity column; else the constant).
    ``start_s``/``end_s`` limit it to a time range
    (:func:`simulator.viewing.inputs.frame_range`). ``source``: a
    :class:`simulator.media.source.Source` (layout, right-eye file; checked when opened) or
    a path (mono equirect). Raises InputError for a bad video, head path, grid, range or
    opacity.
    """
    view = ViewSpec.given(view, **view_fields)
    config, opacity, hold, drawn = view.config, view.opacity, view.hold, view.drawn
    op_csv = None
    if isinstance(opacity, (str, os.PathLike)) and opacity != "auto":
        op_csv = read_epof_csv(opacity)  # InputError naming the file if malformed
        opacity = str(opacity)
    elif isinstance(opacity, str):
        pass
    elif not (0.0 <= float(opacity) <= 1.0):
        raise InputError(f"opacity must be 'auto' or a number in [0, 1], e.g. 0.5; got {opacity!r}")

    source = as_source(source)  # checked once: 2:1 per eye, the right-eye file
    info, video = source.info, source.path
    if not info.is_video:
        raise InputError(
            f"{video}: a still image; render needs a video (vimsim viewport renders images)"
        )
    hp = headpath if isinstance(headpath, HeadPath) else load_headpath(headpath)
    f0, f1 = frame_range(
        info.n_frames, info.fps, start_s, end_s, video=str(video), times=info.frame_times
    )
    ranged = (f0, f1) != (0, info.n_frames)
    nf = f1 - f0
    frames = np.arange(f0, f1)
    times = info.times_s(frames)  # the stream's timestamps (player's clock), else i / fps
    hp.check_covers(float(times[-1]), hold=hold, video=str(video), start_s=float(times[0]))

    if grid is not None and not isinstance(grid, GridFile):
        grid = load_grid(grid)
    if grid is not None:
        grid.check_video(info, source=grid.path, frames=(f0, f1) if ranged else None)
    if op_csv is not None:
        op_from_csv = csv_opacity(op_csv, opacity, frames, info.n_frames, video=video)
    _check_needs_grid(view, grid)

    # Per-frame head angles and opacity (EPOF rows when a grid is given).
    yaw, pitch, roll = hp.sample_angles_deg(times, hold=hold)
    stereo = source.stereo
    epof_eye = str(grid.meta.get("eye", "left")) if grid is not None and stereo else "left"
    # the grid holds the flow of its eye (a stereo grid's meta): that eye's view
    epof_frustum = config.frustum.for_eye(epof_eye)
    rows = _rows(grid, hp, view, epof_frustum, frames, info.fps, ranged, source.orientation_deg)
    epof_dps, op_auto, thresholds, epof_method, coverage, artefact, flow_px, px_rule = rows
    if not drawn:
        op = np.zeros(nf)
    elif op_csv is not None:
        op = op_from_csv
    elif opacity == "auto":
        op = op_auto
    else:
        op = np.full(nf, float(opacity))
    head = np.stack([yaw, pitch, roll], axis=-1)
    angles = np.stack(source.view_angles_deg(yaw, pitch, roll), axis=-1)  # in the frame
    return ViewingPlan(
        info,
        hp,
        grid,
        frames,
        times,
        angles,
        epof_dps,
        op,
        thresholds,
        epof_method,
        opacity,
        source,
        epof_eye,
        epof_frustum,
        coverage,
        artefact,
        head,
        flow_px,
        px_rule,
    )
