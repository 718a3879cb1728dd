"""The one-viewing job: head path -> EPOF -> render -> files in OUTDIR (``vimsim render``, the demo, studies)."""

from __future__ import annotations

import time
import warnings
from pathlib import Path
from typing import Literal

import numpy as np

from simulator.epof.viewing import EpofResult, compute_epof, write_epof_csv
from simulator.errors import InputError
from simulator.fileio import atomic_output, check_output_dir, json_text
from simulator.grf import grain_count
from simulator.gridfile import MAKE_FIELD_HINT, GridFile, load_grid, require_field
from simulator.headpath import HeadPath
from simulator.mitigation import cell_opacity, visible_flow
from simulator.progress import Progress
from simulator.readers import load_headpath
from simulator.render.eye import RenderConfig
from simulator.render.gl import create_context
from simulator.render.video import render_video
from simulator.video import probe

__all__ = ["OUTDIR_FILES", "render_viewing"]

#: What :func:`render_viewing` writes into OUTDIR, in this order; ``summary.json`` last.
OUTDIR_FILES = ("left.mp4", "right.mp4", "epof.csv", "summary.json")

#: Columns ``epof.csv`` of a render has after the EPOF columns: what reaches the eye
#: (:func:`simulator.mitigation.visible_flow`).
VISIBLE_COLUMNS = ("visible_flow_dps", "visible_ratio", "blocked_share")


def _clear_outputs(out) -> None:
    """Remove a previous run's :data:`OUTDIR_FILES` from ``out`` (only those names)."""
    for name in OUTDIR_FILES:
        p = out / name
        try:
            p.unlink(missing_ok=True)
        except OSError as e:
            raise InputError(
                f"{p}: cannot remove the previous run's output ({e.strerror})"
            ) from None


def _mean(a) -> float | None:
    a = np.asarray(a, float)
    a = a[np.isfinite(a)]
    return float(a.mean()) if a.size else None


def _ratio(num, den) -> float | None:
    """sum(visible) / sum(EPOF) over frames: the share of the viewing's flow let through."""
    n, d = np.asarray(num, float), np.asarray(den, float)
    ok = np.isfinite(n) & np.isfinite(d)
    return float(n[ok].sum() / d[ok].sum()) if ok.any() and d[ok].sum() > 0 else None


def render_viewing(
    video,
    headpath,
    outdir,
    *,
    grid=None,
    config: RenderConfig = RenderConfig(),
    opacity: float | Literal["auto"] = "auto",
    layout: str = "mono",
    hold: bool = False,
    preset: str = "veryfast",
    crf: int = 18,
    progress: Progress | None = None,
    note: str | None = None,
    ctx=None,
) -> dict:
    """Render one viewing into ``outdir``: what ``vimsim render`` (and the demo) runs.

    Head path -> (with a grid) EPOF and GRF opacity -> both eyes rendered and encoded ->
    ``epof.csv`` -> ``summary.json``, i.e. :data:`OUTDIR_FILES`.

    Parameters
    ----------
    video : path of the equirect video (mono or stereo, see ``layout``)
    headpath : :class:`simulator.headpath.HeadPath`, or the path of a head path file
        (read with :func:`simulator.readers.load_headpath`, format detected)
    outdir : output folder (created)
    grid : :class:`simulator.gridfile.GridFile`, a grid file's path, or None. With a grid
        the EPOF is computed and ``opacity="auto"`` follows it.
    config : eye size, exact FOVs (degrees), GRF (``config.grf=None``: no grains) and the
        mitigation (``config.mitigation``: grf, vignette, grf+vignette, local-grf, none;
        local-grf needs a grid with a sphere-mode field)
    opacity : ``"auto"`` (from the EPOF, needs ``grid``) or a constant in [0, 1]; ignored
        when nothing is drawn and by local-grf (each cell's own flow drives it)
    layout : ``mono``, ``top-bottom`` (left eye top) or ``side-by-side`` (left eye left)
    hold : hold the head path's first/last pose where it does not cover the video
    preset, crf : x264 speed preset and quality
    note : one line for the user, printed on stderr once the inputs are checked and kept
        in ``summary.json``
    ctx : moderngl.Context, or None to create one (:func:`create_context`)

    The inputs (video, head path, grid, options) and the GL context are checked before
    OUTDIR is touched (GL size limits only once rendering starts). Then the previous run's
    :data:`OUTDIR_FILES` (only those names) are removed, each output appears only when
    complete (temporary name, then rename), and ``summary.json`` is written last: a run
    is complete when it exists.

    Returns
    -------
    dict, the summary (also ``OUTDIR/summary.json``): settings, grain count, opacity
    thresholds, EPOF and opacity percentiles, timings (seconds), frames/s, GL renderer.
    """
    t0 = time.perf_counter()
    w, h = config.eye_size
    hfov, vfov = config.hfov_deg, config.vfov_deg
    grf = config.grains
    mit = config.mitigation
    drawn = grf is not None or mit.vignette
    if isinstance(opacity, str):
        if opacity != "auto":
            raise InputError(
                f"opacity must be 'auto' or a number in [0, 1], e.g. 0.5; got {opacity!r}"
            )
    elif not (0.0 <= float(opacity) <= 1.0):
        raise InputError(f"opacity must be 'auto' or a number in [0, 1], e.g. 0.5; got {opacity!r}")
    if w % 2 or h % 2:
        raise InputError(
            f"--eye-size must be even for H.264 (yuv420p); got {w}x{h}, e.g. {w + w % 2}x{h + h % 2}"
        )

    info = probe(video)
    info.eye_size(layout)  # 2:1 per eye (or squeezed stereo), else InputError
    if not info.is_video:
        raise InputError(
            f"{video}: a still image; render needs a video (vimsim viewport renders images)"
        )
    hp = headpath if isinstance(headpath, HeadPath) else load_headpath(headpath)
    duration = (info.n_frames - 1) / info.fps  # time of the last frame
    hp.check_covers(duration, hold=hold, video=str(video))
    nf = info.n_frames
    times = np.arange(nf) / info.fps

    if grid is not None and not isinstance(grid, GridFile):
        grid = load_grid(grid)
    if grid is not None:
        grid.check_video(info, source=grid.path)
    if mit.local and grf is not None and grid is None:
        raise InputError(
            f"--mitigation local-grf needs --grid GRID.npz with a sphere-mode field; make one "
            f"with `{MAKE_FIELD_HINT}`"
        )
    if drawn and opacity == "auto" and grid is None:
        raise InputError(
            "--opacity auto follows the EPOF and needs --grid GRID.npz; or give --opacity 0..1"
        )
    field_dps = cells = None
    if grid is not None and (getattr(grid, "field_dps", None) is not None or mit.local):
        field_dps, cells = require_field(grid)  # local-grf on a paper-mode grid: the hint

    # Per-frame head angles and opacity (EPOF rows when a grid is given).
    yaw, pitch, roll = hp.sample_angles_deg(times, hold=hold)
    epof_dps = np.full(nf, np.nan)
    thresholds = (float("nan"), float("nan"))
    op_auto = None
    if grid is not None:
        res = compute_epof(grid, hp, frustum=config.frustum, hold=hold)
        n = min(len(res.epof_dps), nf)
        epof_dps[:n] = res.epof_dps[:n]
        epof_dps[n:] = res.epof_dps[-1]
        op_auto = np.empty(nf)
        op_auto[:n] = res.opacity[:n]
        op_auto[n:] = res.opacity[-1]
        thresholds = tuple(float(v) for v in res.thresholds_dps)
    if not drawn:
        op = np.zeros(nf)
    elif opacity == "auto":
        op = op_auto
    else:
        op = np.full(nf, float(opacity))

    cell_op = None
    if mit.local and grf is not None:
        cell_op = cell_opacity(field_dps, thresholds)
    angles = np.stack([yaw, pitch, roll], axis=-1)
    vis = visible_flow(
        mit,
        config.frustum,
        angles,
        op,
        epof_dps,
        grf=grf,
        field_dps=field_dps,
        cell_deg=None if cells is None else cells.cell_deg,
        cell_op=cell_op,
    )
    per_direction = field_dps is not None
    del field_dps  # the render needs only cell_op (local-grf); long videos hold less

    if ctx is None:
        ctx = create_context()
    out = check_output_dir(outdir)
    _clear_outputs(out)  # a failed run must not leave the previous run's files beside new ones
    if note:
        warnings.warn(note, stacklevel=2)
    t_setup = time.perf_counter() - t0
    result = render_video(
        ctx,
        str(video),
        (str(out / "left.mp4"), str(out / "right.mp4")),
        angles,
        opacity=op,
        cell_opacity=cell_op,
        config=config,
        layout=layout,
        fps=info.fps,
        n_frames=nf,
        preset=preset,
        crf=crf,
        progress=progress,
    )

    # epof.csv: one row per video frame.
    write_epof_csv(
        out / "epof.csv",
        EpofResult(np.arange(nf), times, yaw, pitch, roll, epof_dps, op, thresholds),
        extra=dict(zip(VISIBLE_COLUMNS, (vis.visible_dps, vis.ratio, vis.blocked))),
    )

    def pct(a):
        a = np.asarray(a, float)
        a = a[np.isfinite(a)]
        return {f"p{q}": float(np.percentile(a, q)) for q in (10, 50, 90)} if a.size else None

    timings = dict(result.timings_s, setup=t_setup, total_with_setup=time.perf_counter() - t0)
    summary = {
        "video": str(video),
        "headpath": hp.source or str(headpath),
        "grid": None if grid is None else (grid.path or None),
        "layout": layout,
        "fps": info.fps,
        "frames_video": nf,
        "frames_written": result.n_frames,
        "eye_size": [w, h],
        "hfov_deg": hfov,
        "vfov_deg": vfov,
        "frustum_deg": {
            "eye": "left (the right eye mirrors left and right)",
            "left": config.frustum.left_deg,
            "right": config.frustum.right_deg,
            "down": config.frustum.down_deg,
            "up": config.frustum.up_deg,
        },
        "grf": None
        if grf is None
        else {
            "grain_deg": grf.grain_deg,
            "density": grf.density,
            "inner_deg": grf.inner_deg,
            "outer_deg": grf.outer_deg,
            "seed": grf.seed,
            "distance_m": grf.distance_m,
            "n_grains": grain_count(grf),
        },
        "mitigation": {
            "kind": mit.kind,
            "vignette": {
                "aperture_min_deg": mit.aperture_min_deg,
                "feather_deg": mit.feather_deg,
                "color_rgb": [round(c * 255) for c in mit.color],
            }
            if mit.vignette
            else None,
            "grain_opacity": "per-cell flow (sphere-mode field)" if cell_op is not None else None,
        },
        "opacity": "off" if not drawn else opacity,
        "opacity_thresholds_dps": list(thresholds),
        "epof_dps_percentiles": pct(epof_dps),
        "opacity_percentiles": pct(op),
        "visible_flow": {
            "what": "viewport flow weighted by 1 - alpha of what is drawn over each direction",
            "flow_per_direction": "sphere-mode field" if per_direction else "uniform (EPOF)",
            "visible_flow_dps_mean": _mean(vis.visible_dps),
            "visible_ratio_mean": _mean(vis.ratio),
            "visible_ratio_flow_weighted": _ratio(vis.visible_dps, epof_dps),
            "blocked_share_mean": _mean(vis.blocked),
            "visible_flow_dps_percentiles": pct(vis.visible_dps),
        },
        "x264": {"preset": preset, "crf": crf},
        "timings_s": timings,
        "frames_per_s": result.frames_per_s,
        "renderer": ctx.info.get("GL_RENDERER"),
        "outdir": str(out),
    }
    if note:
        summary["note"] = note
    # Last: the completion marker.
    with atomic_output(out / "summary.json") as tmp:
        Path(tmp).write_text(json_text(summary) + "\n")
    return summary
