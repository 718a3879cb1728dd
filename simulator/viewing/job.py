"""The one-viewing job: head path -> EPOF -> render -> files in OUTDIR (``vimsim render``, the demo, studies)."""

from __future__ import annotations

import os
import time
import warnings
from pathlib import Path
from typing import Literal

import numpy as np

from simulator.core.errors import InputError
from simulator.core.fileio import OutputFolder, atomic_output, json_text
from simulator.core.progress import Progress
from simulator.epof.viewing import EpofResult, write_epof_csv
from simulator.media.audio import audio_source
from simulator.media.gridfile import require_field
from simulator.media.lazyfield import take_rows
from simulator.media.source import as_source
from simulator.mitigation.grf import OpacityRule
from simulator.mitigation.kinds import cell_opacity, visible_flow
from simulator.render.eye import RenderConfig
from simulator.render.gl import create_context
from simulator.render.video import render_video
from simulator.traces.path import HeadPath
from simulator.viewing.plan import grf_settings, plan_viewing
from simulator.viewing.review import ReviewWriter

__all__ = ["OUTDIR_FILES", "REVIEW_FILES", "VISIBLE_COLUMNS", "render_viewing"]

#: What :func:`render_viewing` writes into OUTDIR, in this order; ``summary.json`` last.
OUTDIR_FILES = ("left.mp4", "right.mp4", "epof.csv", "summary.json")
#: Written besides with ``review=True`` (before ``summary.json``).
REVIEW_FILES = ("review.mp4", "sheet.png")

#: Columns ``epof.csv`` of a render has after the EPOF columns: what reaches the eye
#: (:func:`simulator.mitigation.kinds.visible_flow`).
VISIBLE_COLUMNS = ("visible_flow_dps", "visible_ratio", "blocked_share")


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
    source,
    headpath,
    outdir,
    *,
    grid=None,
    config: RenderConfig = RenderConfig(),
    opacity: float | str | os.PathLike | Literal["auto"] = "auto",
    hold: bool = False,
    preset: str = "veryfast",
    crf: int = 18,
    progress: Progress | None = None,
    note: str | None = None,
    ctx=None,
    start_s: float | None = None,
    end_s: float | None = None,
    rule: OpacityRule = OpacityRule(),
    method: str = "auto",
    review: bool = False,
    eyes: str | None = None,
    audio: bool = True,
    threads: int | None = None,
) -> dict:
    """Render one viewing into ``outdir``: what ``vimsim render`` (and the demo) runs.

    Head path -> (with a grid) EPOF and GRF opacity -> both eyes rendered and encoded ->
    ``epof.csv`` -> ``summary.json``, i.e. :data:`OUTDIR_FILES`.

    Parameters
    ----------
    source : the video: a :class:`simulator.media.source.Source` (stereo layout, right-eye
        file, projection; checked when opened) or a path (mono equirect)
    headpath : :class:`simulator.traces.path.HeadPath`, or the path of a head path file
        (read with :func:`simulator.traces.readers.load_headpath`, format detected)
    outdir : output folder (created)
    grid : :class:`simulator.media.gridfile.GridFile`, a grid file's path, or None. With a grid
        the EPOF is computed and ``opacity="auto"`` follows it.
    config : eye size, the frustum, GRF (``config.grf=None``: no grains) and the
        mitigation (``config.mitigation``: grf, vignette, grf+vignette, local-grf, none;
        local-grf needs a grid with a sphere-mode field)
    opacity : ``"auto"`` (from the EPOF, needs ``grid``), a constant in [0, 1], or the path
        of an EPOF CSV (its ``opacity`` column; it must have a row for every rendered
        frame, numbered as the video's frames); ignored when nothing is drawn and by
        local-grf (each cell's own flow drives it)
    rule : the opacity rule of ``"auto"`` (:class:`simulator.mitigation.grf.OpacityRule`; default
        the paper's unsmoothed rule, ``vimsim render`` uses :func:`simulator.mitigation.grf.comfort_rule`)
    method : EPOF method (``auto``, ``paper``, ``sphere``; :func:`compute_epof`)
    eyes : ``left``, ``right`` or ``both``: which eye files to write; None (default) =
        ``left`` for a mono video (both eyes would be the same, so ``right.mp4`` would be a
        byte copy) and ``both`` for a stereo one
    audio : copy the source's audio (of ``video``; the range's part) into every output
        video (:mod:`simulator.media.audio`); False: silent outputs. A source without audio
        gives silent outputs either way (``summary.json`` says which)
    review : also write :data:`REVIEW_FILES` (:class:`simulator.viewing.review.ReviewWriter`):
        ``review.mp4`` (equirect with the viewport outline, the left eye view, EPOF and
        opacity strip) and ``sheet.png`` (contact sheet)
    hold : hold the head path's first/last pose where it does not cover the video
    preset, crf : x264 speed preset and quality
    threads : the render's CPU budget (:func:`simulator.render.render_video`; None: no
        bound; a study passes its task's declared CPUs, 1: one core, no pipeline threads)
    note : one line for the user, printed on stderr once the inputs are checked and kept
        in ``summary.json``
    ctx : moderngl.Context, or None to create one (:func:`create_context`)
    start_s, end_s : render only video frames with ``start_s <= i / fps < end_s``
        (seconds of video time; None = the video's start / end). Head path and grid stay
        in video time; a grid made of part of the video is accepted if it covers the range.

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
    if w % 2 or h % 2:
        raise InputError(
            f"--eye-size must be even for H.264 (yuv420p); got {w}x{h}, e.g. {w + w % 2}x{h + h % 2}"
        )
    source = as_source(source)
    video = source.path
    if eyes is None:
        eyes = "both" if source.stereo else "left"
    if eyes not in ("left", "right", "both"):
        raise InputError(f"eyes must be left, right or both; got {eyes!r}")
    plan = plan_viewing(
        source,
        headpath,
        grid=grid,
        config=config,
        opacity=opacity,
        hold=hold,
        start_s=start_s,
        end_s=end_s,
        rule=rule,
        method=method,
    )
    info, hp, grid, opacity = plan.info, plan.headpath, plan.grid, plan.opacity_label
    frames, times = plan.frames, plan.times_s
    f0, f1 = int(frames[0]), int(frames[-1]) + 1
    nf = f1 - f0
    yaw, pitch, roll = plan.angles_deg.T
    epof_dps, op, thresholds = plan.epof_dps, plan.opacity, plan.thresholds_dps
    epof_method = plan.epof_method
    ranged = plan.ranged
    # Only our own earlier outputs are removed (a failed run must not leave them beside new
    # ones); a file of one of our names that we did not write, or an input, is refused.
    folder = OutputFolder(outdir, OUTDIR_FILES + (REVIEW_FILES if review else ()), "render")
    inputs = [*source.files, *([] if isinstance(headpath, HeadPath) else [headpath])]
    inputs += [grid.path] if grid is not None and getattr(grid, "path", None) else []
    if isinstance(opacity, str) and opacity != "auto":
        inputs.append(opacity)  # an EPOF CSV
    folder.check(inputs)  # before the GL context and any work

    # What reaches the eye: the flow of each direction (the sphere-mode field, rows of the
    # plan's frames) weighted by what is drawn over it.
    field_dps = cells = None
    if grid is not None and (getattr(grid, "field_dps", None) is not None or mit.local):
        field_dps, cells = require_field(grid)  # local-grf on a paper-mode grid: the hint
        start = int(grid.meta.get("start_frame", 0) or 0)
        field_dps = take_rows(field_dps, np.clip(frames - start, 0, len(field_dps) - 1))
    cell_op = None
    if mit.local and grf is not None:
        cell_op = cell_opacity(field_dps, thresholds)
    angles = plan.angles_deg
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

    aud = None
    if audio:
        aud = audio_source(video, times[0] if ranged else None, f1 / info.fps if ranged else None)

    if ctx is None:
        ctx = create_context()
    out = folder.prepare(inputs)
    if note:
        warnings.warn(note, stacklevel=2)
    t_setup = time.perf_counter() - t0
    rev = None
    if review:
        rev = ReviewWriter(
            out / "review.mp4",
            out / "sheet.png",
            times_s=times,
            yaw_deg=yaw,
            pitch_deg=pitch,
            roll_deg=roll,
            epof_dps=epof_dps,
            opacity=op,
            hfov_deg=hfov,
            vfov_deg=vfov,
            fps=info.fps,
            audio=aud,
        )
    try:
        result = render_video(
            ctx,
            source,
            (
                str(out / "left.mp4") if eyes in ("left", "both") else None,
                str(out / "right.mp4") if eyes in ("right", "both") else None,
            ),
            angles,
            opacity=op,
            cell_opacity=cell_op,
            config=config,
            fps=info.fps,
            n_frames=nf,
            preset=preset,
            crf=crf,
            threads=threads,
            progress=progress,
            start_frame=f0,
            on_frame=None if rev is None else rev.add_yuv,
            audio=aud,
            review_eye=plan.epof_eye,
        )
    except BaseException:
        if rev is not None:
            rev.close(ok=False)
        raise
    if rev is not None:
        rev.close(ok=True)

    if aud is None:
        audio_info = {
            "copied": False,
            "why": "off (--no-audio)" if not audio else "no audio stream in the source",
        }
    else:
        audio_info = {
            "copied": True,
            "codec": aud.codec,
            "mode": "packets copied" if aud.copy else "re-encoded to AAC",
            "range_s": [aud.start_s, aud.end_s],
        }
    fr_ = plan.epof_frustum
    settings = {
        "epof_method": epof_method,
        "epof_eye": plan.epof_eye,
        "frustum_deg": None
        if fr_ is None
        else {"left": fr_.left_deg, "right": fr_.right_deg, "down": fr_.down_deg, "up": fr_.up_deg},
        "fov_deg": [hfov, vfov],
        "mitigation": mit.kind,
        "opacity": "off" if not drawn else str(opacity),
        "opacity_rule": rule.describe() if grid is not None and opacity == "auto" else None,
        "opacity_thresholds_dps": list(thresholds),
    }
    # epof.csv: one row per video frame, the settings as '#' lines above the header, the
    # visible flow after the EPOF columns.
    write_epof_csv(
        out / "epof.csv",
        EpofResult(
            frames, times, yaw, pitch, roll, epof_dps, op, thresholds, coverage=plan.coverage
        ),
        extra=dict(zip(VISIBLE_COLUMNS, (vis.visible_dps, vis.ratio, vis.blocked))),
        settings=settings,
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
        "layout": source.layout,
        "right": source.right,
        "projection": source.projection,
        "source": source.settings(),
        "coverage_mean": _mean(plan.coverage) if plan.coverage is not None else None,
        "eyes": eyes,
        "audio": audio_info,
        "fps": info.fps,
        "frames_video": info.n_frames,
        "range_s": [float(times[0]), float(times[-1])],
        "frames_range": [int(f0), int(f1)],
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
        "grf": grf_settings(grf),
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
        "opacity_rule": rule.describe() if grid is not None and opacity == "auto" else None,
        "opacity_thresholds_dps": list(thresholds),
        "epof_method": epof_method,
        "epof_eye": plan.epof_eye,
        "epof_frustum_deg": settings["frustum_deg"],
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
        "review": list(REVIEW_FILES) if review else None,
    }
    if note:
        summary["note"] = note
    # Last: the manifest saying which files are ours, then the completion marker.
    folder.complete()
    with atomic_output(out / "summary.json") as tmp:
        Path(tmp).write_text(json_text(summary) + "\n")
    return summary
