"""The one-viewing job: head path -> EPOF -> render -> files in OUTDIR (``vimsim render``, the demo, studies).

:func:`render_viewing` is three steps: :func:`plan_job` (every check and the plan of every
frame, nothing written), :func:`draw` (the eye videos) and the record
(:mod:`simulator.viewing.summary`: ``epof.csv``'s settings and ``summary.json``).
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from simulator.core.errors import InputError
from simulator.core.fileio import OutputFolder, atomic_output, json_text
from simulator.core.progress import Progress
from simulator.epof.nearest import FLOW_PX_COLUMN
from simulator.epof.viewing import EpofResult, write_epof_csv
from simulator.media.audio import audio_source
from simulator.media.gridfile import require_field
from simulator.media.lazyfield import take_rows
from simulator.media.source import Source, as_source
from simulator.mitigation.kinds import VisibleFlow, cell_opacity, visible_flow
from simulator.render.gl import create_context
from simulator.render.video import VideoRenderResult, render_video
from simulator.traces.path import HeadPath
from simulator.viewing.plan import ViewingPlan, plan_viewing
from simulator.viewing.review import ReviewWriter
from simulator.viewing.spec import ViewSpec
from simulator.viewing.summary import REVIEW_FILES, epof_settings, viewing_summary

__all__ = [
    "OUTDIR_FILES",
    "REVIEW_FILES",
    "VISIBLE_COLUMNS",
    "ViewingJob",
    "draw",
    "plan_job",
    "render_viewing",
]

#: What :func:`render_viewing` writes into OUTDIR, in this order; ``summary.json`` last.
OUTDIR_FILES = ("left.mp4", "right.mp4", "epof.csv", "summary.json")

#: Columns ``epof.csv`` of a render has after the EPOF columns: what reaches the eye
#: (:func:`simulator.mitigation.kinds.visible_flow`).
VISIBLE_COLUMNS = ("visible_flow_dps", "visible_ratio", "blocked_share")


@dataclass(frozen=True)
class ViewingJob:
    """One render's work, checked before OUTDIR is touched: the source, the view, the plan
    of every frame, what reaches the eye, the audio, and the outputs.

    eyes : ``left``, ``right`` or ``both``; review : write :data:`REVIEW_FILES` too
    folder, inputs : the :class:`simulator.core.fileio.OutputFolder` and the input files
        it must never write over
    visible : :class:`simulator.mitigation.kinds.VisibleFlow` per frame; per_direction :
        it used the sphere-mode field's flow of each direction (else the EPOF, uniform)
    cell_opacity : local-grf's per-cell grain opacity ``(N, n_lat, n_lon)``, or None
    audio : the source's audio to copy (or None); audio_requested : audio was asked for
    headpath_label : the head path as ``summary.json`` names it
    """

    source: Source
    view: ViewSpec
    plan: ViewingPlan
    eyes: str
    review: bool
    folder: OutputFolder
    inputs: list
    visible: VisibleFlow
    per_direction: bool
    cell_opacity: np.ndarray | None
    audio: object
    audio_requested: bool
    headpath_label: str


def plan_job(source, headpath, outdir, *, grid=None, view: ViewSpec, start_s=None,
             end_s=None, review=False, eyes=None, audio=True) -> ViewingJob:  # fmt: skip
    """Check everything of one render and work out what it draws (no GL, nothing written);
    the parameters are :func:`render_viewing`'s. InputError for any bad input."""
    w, h = view.config.eye_size
    if w % 2 or h % 2:
        raise InputError(
            f"--eye-size must be even for H.264 (yuv420p); got {w}x{h}, e.g. {w + w % 2}x{h + h % 2}"
        )
    source = as_source(source)
    if eyes is None:
        eyes = "both" if source.stereo else "left"
    if eyes not in ("left", "right", "both"):
        raise InputError(f"eyes must be left, right or both; got {eyes!r}")
    plan = plan_viewing(source, headpath, grid=grid, view=view, start_s=start_s, end_s=end_s)
    # Only our own earlier outputs are removed (a failed run must not leave them beside new
    # ones); a file of one of our names that we did not write, or an input, is refused.
    folder = OutputFolder(outdir, OUTDIR_FILES + (REVIEW_FILES if review else ()), "render")
    grid, label = plan.grid, plan.opacity_label
    inputs = [*source.files, *([] if isinstance(headpath, HeadPath) else [headpath])]
    inputs += [grid.path] if grid is not None and getattr(grid, "path", None) else []
    if isinstance(label, str) and label != "auto":
        inputs.append(label)  # an EPOF CSV
    folder.check(inputs)  # before the GL context and any work
    visible, per_direction, cell_op = _what_reaches_the_eye(view, plan)
    aud = None
    if audio:
        f1 = int(plan.frames[-1]) + 1
        ranged = plan.ranged
        aud = audio_source(
            source.path, plan.times_s[0] if ranged else None, f1 / plan.info.fps if ranged else None
        )
    return ViewingJob(source, view, plan, eyes, review, folder, inputs, visible, per_direction,
                      cell_op, aud, audio, plan.headpath.source or str(headpath))  # fmt: skip


def _what_reaches_the_eye(view: ViewSpec, plan: ViewingPlan):
    """``(visible flow, per direction?, local-grf's cell opacity)``: the flow of each
    direction (the sphere-mode field, rows of the plan's frames) weighted by what is drawn
    over it (:func:`simulator.mitigation.kinds.visible_flow`)."""
    grid, mit, grf = plan.grid, view.mitigation, view.grains
    field_dps = cells = None
    if grid is not None and (getattr(grid, "field_dps", None) is not None or mit.local):
        field_dps, cells = require_field(grid)  # local-grf on a paper-mode grid: the hint
        start = int(grid.meta.get("start_frame", 0) or 0)
        field_dps = take_rows(field_dps, np.clip(plan.frames - start, 0, len(field_dps) - 1))
    cell_op = None
    if mit.local and grf is not None:
        cell_op = cell_opacity(field_dps, plan.thresholds_dps)
    vis = visible_flow(
        mit,
        view.frustum,
        plan.angles_deg,
        plan.opacity,
        plan.epof_dps,
        grf=grf,
        field_dps=field_dps,
        cell_deg=None if cells is None else cells.cell_deg,
        cell_op=cell_op,
    )
    return vis, field_dps is not None, cell_op  # the field itself is not kept


def draw(job: ViewingJob, ctx, out: Path, *, x264_preset="veryfast", crf=18, threads=None,
         progress: Progress | None = None) -> VideoRenderResult:  # fmt: skip
    """Render and encode the job's eye videos into ``out`` (and the review video and sheet
    with ``job.review``): :func:`simulator.render.video.render_video`."""
    plan, eyes = job.plan, job.eyes
    rev = None
    if job.review:
        yaw, pitch, roll = plan.angles_deg.T
        rev = ReviewWriter(
            out / "review.mp4",
            out / "sheet.png",
            times_s=plan.times_s,
            yaw_deg=yaw,
            pitch_deg=pitch,
            roll_deg=roll,
            epof_dps=plan.epof_dps,
            opacity=plan.opacity,
            hfov_deg=job.view.config.hfov_deg,
            vfov_deg=job.view.config.vfov_deg,
            fps=plan.info.fps,
            audio=job.audio,
            thresholds_dps=plan.thresholds_dps,
            opacity_used=not job.view.mitigation.local,
            # a variable-rate source's timing, as the eye videos keep it
            video_times_s=plan.times_s if plan.info.variable_rate else None,
        )
    try:
        result = render_video(
            ctx,
            job.source,
            (
                str(out / "left.mp4") if eyes in ("left", "both") else None,
                str(out / "right.mp4") if eyes in ("right", "both") else None,
            ),
            plan.angles_deg,
            opacity=plan.opacity,
            cell_opacity=job.cell_opacity,
            config=job.view.config,
            fps=plan.info.fps,
            n_frames=len(plan.frames),
            preset=x264_preset,
            crf=crf,
            threads=threads,
            progress=progress,
            start_frame=int(plan.frames[0]),
            on_frame=None if rev is None else rev.add_yuv,
            audio=job.audio,
            review_eye=plan.epof_eye,
        )
    except BaseException:
        if rev is not None:
            rev.close(ok=False)
        raise
    if rev is not None:
        rev.close(ok=True)
    return result


def render_viewing(
    source,
    headpath,
    outdir,
    *,
    grid=None,
    view: ViewSpec | None = None,
    x264_preset: str = "veryfast",
    crf: int = 18,
    progress: Progress | None = None,
    note: str | None = None,
    ctx=None,
    start_s: float | None = None,
    end_s: float | None = None,
    review: bool = False,
    eyes: str | None = None,
    audio: bool = True,
    threads: int | None = None,
    **view_fields,
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
    view : :class:`simulator.viewing.spec.ViewSpec`, what the eye sees (or its fields as
        keywords: ``config=``, ``opacity=``, ``rule=``, ``method=``, ``hold=``); its
        ``opacity`` ``"auto"`` needs ``grid``, an EPOF CSV's needs a row for every
        rendered frame; local-grf needs a grid with a sphere-mode field. Default rule: the
        paper's (:meth:`ViewSpec.from_options` and ``vimsim render``: the eased one)
    eyes : ``left``, ``right`` or ``both``: which eye files to write; None (default) =
        ``left`` for a mono video (both eyes would be the same, so ``right.mp4`` would be a
        byte copy) and ``both`` for a stereo one
    audio : copy the source's audio (of ``video``; the range's part) into every output
        video (:mod:`simulator.media.audio`); False: silent outputs. A source without audio
        gives silent outputs either way (``summary.json`` says which)
    review : also write :data:`REVIEW_FILES` (:class:`simulator.viewing.review.ReviewWriter`):
        ``review.mp4`` (equirect with the viewport outline, the left eye view, EPOF and
        opacity strip) and ``sheet.png`` (contact sheet)
    x264_preset, crf : x264 speed preset and quality (the system preset is ``view.preset``)
    threads : the render's CPU budget (:func:`simulator.render.render_video`; None: no
        bound; a study passes its task's declared CPUs, 1: one core, no pipeline threads)
    note : one line for the user, printed on stderr once the inputs are checked and kept
        in ``summary.json``
    ctx : moderngl.Context, or None to create one (:func:`create_context`)
    start_s, end_s : render only video frames with ``start_s <= i / fps < end_s``
        (seconds of video time; None = the video's start / end). Head path and grid stay
        in video time; a grid made of part of the video is accepted if it covers the range.

    The inputs and the GL context are checked before OUTDIR is touched (GL size limits
    once rendering starts): :func:`plan_job`. Then the previous run's
    :data:`OUTDIR_FILES` (only those names) are removed, :func:`draw` renders, each
    output appears only when complete (temporary name, then rename), and
    ``summary.json`` (:func:`simulator.viewing.summary.viewing_summary`) is written last:
    a run is complete when it exists. Returns the summary dict (settings, grain count,
    opacity thresholds, EPOF, opacity and visible-flow figures, timings, GL renderer).
    """
    t0 = time.perf_counter()
    view = ViewSpec.given(view, **view_fields)
    job = plan_job(source, headpath, outdir, grid=grid, view=view, start_s=start_s,
                   end_s=end_s, review=review, eyes=eyes, audio=audio)  # fmt: skip
    if ctx is None:
        ctx = create_context()
    out = job.folder.prepare(job.inputs)
    if note:
        warnings.warn(note, stacklevel=2)
    t_setup = time.perf_counter() - t0
    result = draw(job, ctx, out, x264_preset=x264_preset, crf=crf, threads=threads,
                  progress=progress)  # fmt: skip
    # epof.csv: one row per video frame, the settings as '#' lines above the header, the
    # visible flow after the EPOF columns.
    plan, vis = job.plan, job.visible
    settings = epof_settings(job)
    head = plan.angles_deg if plan.head_angles_deg is None else plan.head_angles_deg
    res = EpofResult(plan.frames, plan.times_s, *head.T, plan.epof_dps,
                     plan.opacity, plan.thresholds_dps, coverage=plan.coverage,
                     artefact=plan.artefact)  # fmt: skip
    extra = dict(zip(VISIBLE_COLUMNS, (vis.visible_dps, vis.ratio, vis.blocked)))
    if plan.flow_px is not None:  # --preset cao2021-code: the px/frame its opacity came from
        extra[FLOW_PX_COLUMN] = plan.flow_px
    write_epof_csv(out / "epof.csv", res, extra=extra, settings=settings)
    timings = dict(result.timings_s, setup=t_setup, total_with_setup=time.perf_counter() - t0)
    run = {"x264": {"preset": x264_preset, "crf": crf}, "timings_s": timings, "note": note,
           "renderer": ctx.info.get("GL_RENDERER"), "outdir": str(out)}  # fmt: skip
    summary = viewing_summary(job, result, settings=settings, run=run)
    # Last: the manifest saying which files are ours, then the completion marker.
    job.folder.complete()
    with atomic_output(out / "summary.json") as tmp:
        Path(tmp).write_text(json_text(summary) + "\n")
    return summary
