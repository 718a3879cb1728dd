"""The one-viewing job: head path -> EPOF -> render -> files in OUTDIR (``vimsim render``, the demo, studies)."""

from __future__ import annotations

import os
import time
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np

from simulator.audio import audio_source
from simulator.cells import Frustum
from simulator.epof.viewing import EpofResult, compute_epof, read_epof_csv, write_epof_csv
from simulator.errors import InputError
from simulator.fileio import atomic_output, check_output_dir, json_text
from simulator.grf import OpacityRule, grain_count
from simulator.gridfile import GridFile, load_grid
from simulator.headpath import HeadPath
from simulator.inputs import check_right_eye, csv_opacity, frame_range
from simulator.progress import Progress
from simulator.readers import load_headpath
from simulator.render.eye import RenderConfig
from simulator.render.gl import create_context
from simulator.render.video import render_video
from simulator.review import ReviewWriter
from simulator.video import MediaInfo, probe

__all__ = [
    "OUTDIR_FILES",
    "REVIEW_FILES",
    "ViewingPlan",
    "frame_range",
    "grf_settings",
    "plan_viewing",
    "render_viewing",
]

#: What :func:`render_viewing` writes into OUTDIR, in this order; ``summary.json`` last.
OUTDIR_FILES = ("left.mp4", "right.mp4", "epof.csv", "summary.json")
#: Written besides with ``review=True`` (before ``summary.json``).
REVIEW_FILES = ("review.mp4", "sheet.png")


def _clear_outputs(out) -> None:
    """Remove a previous run's :data:`OUTDIR_FILES` from ``out`` (only those names)."""
    for name in OUTDIR_FILES + REVIEW_FILES:
        p = out / name
        try:
            p.unlink(missing_ok=True)
        except OSError as e:
            raise InputError(
                f"{p}: cannot remove the previous run's output ({e.strerror})"
            ) from None


@dataclass(frozen=True)
class ViewingPlan:
    """One viewing's inputs, checked, and its per-frame poses and GRF opacity.

    info : the video's :class:`simulator.video.MediaInfo`
    headpath : the head path; grid : the grid file or None
    frames : ndarray, shape (N,), the video frame numbers of the plan (``f0 .. f1 - 1``)
    times_s : ndarray, shape (N,), time of each frame ``i / fps`` (seconds)
    angles_deg : ndarray, shape (N, 3), (yaw, pitch, roll) of each frame, degrees
    epof_dps : ndarray, shape (N,), EPOF (deg/s; NaN without a grid)
    opacity : ndarray, shape (N,), the GRF opacity rendered at each frame (0 without GRF)
    thresholds_dps : the opacity rule's 0 and 1 thresholds (NaN without a grid)
    epof_method : ``paper`` or ``sphere`` (None without a grid)
    opacity_label : what ``opacity`` was given as: ``auto``, a number, or the EPOF CSV's path
    right : the right eye's equirect file (two per-eye files), or None
    epof_eye : the eye whose view the EPOF measures: the grid's eye (its meta) for a
        stereo source, else ``left``
    epof_frustum : the frustum the EPOF was computed over (that eye's; the right eye's
        mirrors the left eye's left and right half-angles)
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
    right: str | None = None
    epof_eye: str = "left"
    epof_frustum: Frustum | None = None

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
    }


def plan_viewing(
    video,
    headpath,
    *,
    grid=None,
    config: RenderConfig = RenderConfig(),
    opacity: float | str | os.PathLike | Literal["auto"] = "auto",
    layout: str = "mono",
    hold: bool = False,
    start_s: float | None = None,
    end_s: float | None = None,
    rule: OpacityRule = OpacityRule(),
    method: str = "auto",
    right=None,
) -> ViewingPlan:
    """Check a viewing's inputs and work out what every frame shows (no GL, no output).

    What :func:`render_viewing` renders and ``vimsim frames`` renders at chosen moments:
    the head pose at each frame's time ``i / fps`` and, with ``config.grf``, the opacity
    (``"auto"``: from the EPOF of ``grid`` through ``rule``, over ``config.frustum``; an
    EPOF CSV's path: its opacity column; else the constant). ``start_s``/``end_s`` limit
    it to a time range (:func:`frame_range`). ``right``: the right eye's equirect file
    (``video`` is then the left eye's; both mono, same size, frame rate and frame count).
    Raises InputError for a bad video, right-eye file, head path, grid, range or opacity.
    """
    grf = config.grf
    op_csv = None
    if isinstance(opacity, (str, os.PathLike)) and opacity != "auto":
        op_csv = read_epof_csv(opacity)  # InputError naming the file if malformed
        opacity = str(opacity)
    elif isinstance(opacity, str):
        pass
    elif not (0.0 <= float(opacity) <= 1.0):
        raise InputError(f"opacity must be 'auto' or a number in [0, 1], e.g. 0.5; got {opacity!r}")

    info = probe(video)
    info.eye_size(layout)  # 2:1 per eye (or squeezed stereo), else InputError
    if not info.is_video:
        raise InputError(
            f"{video}: a still image; render needs a video (vimsim viewport renders images)"
        )
    if right is not None:
        right = str(right)
        check_right_eye(info, right, layout)
    hp = headpath if isinstance(headpath, HeadPath) else load_headpath(headpath)
    f0, f1 = frame_range(info.n_frames, info.fps, start_s, end_s, video=str(video))
    ranged = (f0, f1) != (0, info.n_frames)
    nf = f1 - f0
    frames = np.arange(f0, f1)
    times = frames / info.fps
    hp.check_covers(float(times[-1]), hold=hold, video=str(video), start_s=float(times[0]))

    if grid is not None and not isinstance(grid, GridFile):
        grid = load_grid(grid)
    if grid is not None:
        grid.check_video(info, source=grid.path, frames=(f0, f1) if ranged else None)
    if op_csv is not None:
        op_from_csv = csv_opacity(op_csv, opacity, frames, info.n_frames)
    if grf is not None and opacity == "auto" and grid is None:
        raise InputError(
            "--opacity auto follows the EPOF and needs --grid GRID.npz; or give --opacity 0..1"
        )

    # Per-frame head angles and opacity (EPOF rows when a grid is given).
    yaw, pitch, roll = hp.sample_angles_deg(times, hold=hold)
    epof_dps = np.full(nf, np.nan)
    thresholds = (float("nan"), float("nan"))
    op_auto = None
    epof_method = None
    stereo = layout != "mono" or right is not None
    epof_eye = str(grid.meta.get("eye", "left")) if grid is not None and stereo else "left"
    epof_frustum = config.frustum
    if epof_eye == "right":  # the grid holds the right eye's flow: that eye's view
        epof_frustum = Frustum(
            config.frustum.right_deg,
            config.frustum.left_deg,
            config.frustum.down_deg,
            config.frustum.up_deg,
        )
    if grid is not None:
        # A range: EPOF of its frames only, plus a warm-up before it so that smoothing
        # and easing have their state at the range's start (cost ~ the range).
        warm = 0
        if ranged:
            warm = int(
                np.ceil(info.fps * (rule.ease_in_s + rule.ease_out_s + 5 * rule.smoothing_s))
            )
        res = compute_epof(
            grid,
            hp,
            frustum=epof_frustum,
            hold=True if ranged else hold,
            rule=rule,
            method=method,
            frames=(max(0, f0 - warm), f1) if ranged else None,
        )
        epof_method = res.meta["method"]
        # Grid rows by video frame number (a grid may start later or lack the last frame).
        rows = np.clip(frames - int(res.frame[0]), 0, len(res.frame) - 1)
        epof_dps = res.epof_dps[rows].astype(float)
        op_auto = res.opacity[rows].astype(float)
        thresholds = tuple(float(v) for v in res.thresholds_dps)
    if grf is None:
        op = np.zeros(nf)
    elif op_csv is not None:
        op = op_from_csv
    elif opacity == "auto":
        op = op_auto
    else:
        op = np.full(nf, float(opacity))
    angles = np.stack([yaw, pitch, roll], axis=-1)
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
        right,
        epof_eye,
        epof_frustum,
    )


def render_viewing(
    video,
    headpath,
    outdir,
    *,
    grid=None,
    config: RenderConfig = RenderConfig(),
    opacity: float | str | os.PathLike | Literal["auto"] = "auto",
    layout: str = "mono",
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
    right=None,
    audio: bool = True,
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
    config : eye size, exact FOVs (degrees) and GRF (``config.grf=None``: no overlay)
    opacity : ``"auto"`` (from the EPOF, needs ``grid``), a constant in [0, 1], or the path
        of an EPOF CSV (its ``opacity`` column; it must have a row for every rendered
        frame, numbered as the video's frames); ignored without ``config.grf``
    rule : the opacity rule of ``"auto"`` (:class:`simulator.grf.OpacityRule`; default
        the paper's unsmoothed rule, ``vimsim render`` uses :func:`simulator.grf.comfort_rule`)
    method : EPOF method (``auto``, ``paper``, ``sphere``; :func:`compute_epof`)
    eyes : ``left``, ``right`` or ``both``: which eye files to write; None (default) =
        ``left`` for a mono video (both eyes would be the same, so ``right.mp4`` would be a
        byte copy) and ``both`` for a stereo one
    right : the right eye's equirect file: ``video`` and ``right`` are then a stereo
        source of two per-eye files (same size, frame rate and frame count; layout mono)
    audio : copy the source's audio (of ``video``; the range's part) into every output
        video (:mod:`simulator.audio`); False: silent outputs. A source without audio
        gives silent outputs either way (``summary.json`` says which)
    review : also write :data:`REVIEW_FILES` (:class:`simulator.review.ReviewWriter`):
        ``review.mp4`` (equirect with the viewport outline, the left eye view, EPOF and
        opacity strip) and ``sheet.png`` (contact sheet)
    layout : ``mono``, ``top-bottom`` (left eye top) or ``side-by-side`` (left eye left)
    hold : hold the head path's first/last pose where it does not cover the video
    preset, crf : x264 speed preset and quality
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
    grf = config.grf
    if w % 2 or h % 2:
        raise InputError(
            f"--eye-size must be even for H.264 (yuv420p); got {w}x{h}, e.g. {w + w % 2}x{h + h % 2}"
        )
    if eyes is None:
        eyes = "left" if layout == "mono" and right is None else "both"
    if eyes not in ("left", "right", "both"):
        raise InputError(f"eyes must be left, right or both; got {eyes!r}")
    plan = plan_viewing(
        video,
        headpath,
        grid=grid,
        config=config,
        opacity=opacity,
        layout=layout,
        hold=hold,
        start_s=start_s,
        end_s=end_s,
        rule=rule,
        method=method,
        right=right,
    )
    info, hp, grid, opacity = plan.info, plan.headpath, plan.grid, plan.opacity_label
    frames, times = plan.frames, plan.times_s
    f0, f1 = int(frames[0]), int(frames[-1]) + 1
    nf = f1 - f0
    yaw, pitch, roll = plan.angles_deg.T
    epof_dps, op, thresholds = plan.epof_dps, plan.opacity, plan.thresholds_dps
    epof_method = plan.epof_method
    ranged = plan.ranged
    aud = None
    if audio:
        aud = audio_source(video, times[0] if ranged else None, f1 / info.fps if ranged else None)

    if ctx is None:
        ctx = create_context()
    out = check_output_dir(outdir)
    _clear_outputs(out)  # a failed run must not leave the previous run's files beside new ones
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
            str(video),
            (
                str(out / "left.mp4") if eyes in ("left", "both") else None,
                str(out / "right.mp4") if eyes in ("right", "both") else None,
            ),
            np.stack([yaw, pitch, roll], axis=-1),
            opacity=op,
            config=config,
            layout=layout,
            fps=info.fps,
            n_frames=nf,
            preset=preset,
            crf=crf,
            progress=progress,
            start_frame=f0,
            on_frame=None if rev is None else rev.add_yuv,
            audio=aud,
            right_path=plan.right,
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
        "opacity": "off" if grf is None else str(opacity),
        "opacity_rule": rule.describe() if grid is not None and opacity == "auto" else None,
        "opacity_thresholds_dps": list(thresholds),
    }
    # epof.csv: one row per video frame, the settings as '#' lines above the header.
    write_epof_csv(
        out / "epof.csv",
        EpofResult(frames, times, yaw, pitch, roll, epof_dps, op, thresholds),
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
        "layout": layout,
        "right": plan.right,
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
        "opacity": "off" if grf is None else opacity,
        "opacity_rule": rule.describe() if grid is not None and opacity == "auto" else None,
        "opacity_thresholds_dps": list(thresholds),
        "epof_method": epof_method,
        "epof_eye": plan.epof_eye,
        "epof_frustum_deg": settings["frustum_deg"],
        "epof_dps_percentiles": pct(epof_dps),
        "opacity_percentiles": pct(op),
        "x264": {"preset": preset, "crf": crf},
        "timings_s": timings,
        "frames_per_s": result.frames_per_s,
        "renderer": ctx.info.get("GL_RENDERER"),
        "outdir": str(out),
        "review": list(REVIEW_FILES) if review else None,
    }
    if note:
        summary["note"] = note
    # Last: the completion marker.
    with atomic_output(out / "summary.json") as tmp:
        Path(tmp).write_text(json_text(summary) + "\n")
    return summary
