"""The one-viewing job: head path -> EPOF -> render -> files in OUTDIR (``vimsim render``, the demo, studies)."""

from __future__ import annotations

import time
import warnings
from pathlib import Path
from typing import Literal

import numpy as np

from simulator.epof.viewing import EpofResult, compute_epof, write_epof_csv
from simulator.errors import InputError
from simulator.fileio import OutputFolder, atomic_output, json_text
from simulator.grf import grain_count
from simulator.gridfile import GridFile, load_grid
from simulator.headpath import HeadPath
from simulator.progress import Progress
from simulator.readers import load_headpath
from simulator.render.eye import RenderConfig
from simulator.render.gl import create_context
from simulator.render.video import render_video
from simulator.video import probe

__all__ = ["OUTDIR_FILES", "render_viewing"]

#: What :func:`render_viewing` writes into OUTDIR, in this order; ``summary.json`` last.
OUTDIR_FILES = ("left.mp4", "right.mp4", "epof.csv", "summary.json")


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
        (read with :func:`simulator.headpath.load_headpath`, format detected)
    outdir : output folder (created)
    grid : :class:`simulator.gridfile.GridFile`, a grid file's path, or None. With a grid
        the EPOF is computed and ``opacity="auto"`` follows it.
    config : eye size, exact FOVs (degrees) and GRF (``config.grf=None``: no overlay)
    opacity : ``"auto"`` (from the EPOF, needs ``grid``) or a constant in [0, 1]; ignored
        without ``config.grf``
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
    grf = config.grf
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
    # Only our own earlier outputs are removed (a failed run must not leave them beside new
    # ones); a file of one of our names that we did not write, or an input, is refused.
    folder = OutputFolder(outdir, OUTDIR_FILES, "render")
    inputs = [video, *([] if isinstance(headpath, HeadPath) else [headpath])]
    inputs += [grid.path] if grid is not None and getattr(grid, "path", None) else []
    folder.check(inputs)  # before the GL context and any work
    if grf is not None and opacity == "auto" and grid is None:
        raise InputError(
            "--opacity auto follows the EPOF and needs --grid GRID.npz; or give --opacity 0..1"
        )

    # Per-frame head angles and opacity (EPOF rows when a grid is given).
    yaw, pitch, roll = hp.sample_angles_deg(times, hold=hold)
    epof_dps = np.full(nf, np.nan)
    thresholds = (float("nan"), float("nan"))
    op_auto = None
    if grid is not None:
        res = compute_epof(grid, hp, hfov_deg=hfov, vfov_deg=vfov, hold=hold)
        n = min(len(res.epof_dps), nf)
        epof_dps[:n] = res.epof_dps[:n]
        epof_dps[n:] = res.epof_dps[-1]
        op_auto = np.empty(nf)
        op_auto[:n] = res.opacity[:n]
        op_auto[n:] = res.opacity[-1]
        thresholds = tuple(float(v) for v in res.thresholds_dps)
    if grf is None:
        op = np.zeros(nf)
    elif opacity == "auto":
        op = op_auto
    else:
        op = np.full(nf, float(opacity))

    if ctx is None:
        ctx = create_context()
    out = folder.prepare(inputs)
    if note:
        warnings.warn(note, stacklevel=2)
    t_setup = time.perf_counter() - t0
    result = render_video(
        ctx,
        str(video),
        (str(out / "left.mp4"), str(out / "right.mp4")),
        np.stack([yaw, pitch, roll], axis=-1),
        opacity=op,
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
        "opacity": "off" if grf is None else opacity,
        "opacity_thresholds_dps": list(thresholds),
        "epof_dps_percentiles": pct(epof_dps),
        "opacity_percentiles": pct(op),
        "x264": {"preset": preset, "crf": crf},
        "timings_s": timings,
        "frames_per_s": result.frames_per_s,
        "renderer": ctx.info.get("GL_RENDERER"),
        "outdir": str(out),
    }
    if note:
        summary["note"] = note
    # Last: the manifest saying which files are ours, then the completion marker.
    folder.complete()
    with atomic_output(out / "summary.json") as tmp:
        Path(tmp).write_text(json_text(summary) + "\n")
    return summary
