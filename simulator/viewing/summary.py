"""The record of one rendered viewing: the settings ``epof.csv`` carries and the ``summary.json`` dict.

Built from the job (:class:`simulator.viewing.job.ViewingJob`: the source, the view, the
plan of every frame, the visible flow) and what the draw did
(:class:`simulator.render.video.VideoRenderResult`); nothing here touches a file. Angles
in degrees, flow in deg/s, times in seconds.
"""

from __future__ import annotations

import numpy as np

from simulator.viewing.plan import grf_settings

__all__ = ["REVIEW_FILES", "audio_summary", "epof_settings", "viewing_summary"]

#: Written beside the eye videos with ``review=True`` (before ``summary.json``).
REVIEW_FILES = ("review.mp4", "sheet.png")


def _mean(a) -> float | None:
    a = np.asarray(a, float)
    a = a[np.isfinite(a)]
    return float(a.mean()) if a.size else None


def _ratio(num, den) -> float | None:
    """sum(visible) / sum(EPOF) over frames: the share of the viewing's flow let through."""
    n, d = np.asarray(num, float), np.asarray(den, float)
    ok = np.isfinite(n) & np.isfinite(d)
    return float(n[ok].sum() / d[ok].sum()) if ok.any() and d[ok].sum() > 0 else None


def _pct(a) -> dict | None:
    a = np.asarray(a, float)
    a = a[np.isfinite(a)]
    return {f"p{q}": float(np.percentile(a, q)) for q in (10, 50, 90)} if a.size else None


def _frustum_deg(fr) -> dict | None:
    if fr is None:
        return None
    return {"left": fr.left_deg, "right": fr.right_deg, "down": fr.down_deg, "up": fr.up_deg}


def _rule(job) -> dict | None:
    """The opacity rule's settings when the opacity follows the EPOF, else None."""
    if job.plan.grid is not None and job.plan.opacity_label == "auto":
        px = job.plan.px_rule  # --preset cao2021-code: the fixed px/frame scale
        return job.view.rule.describe() if px is None else px.describe()
    return None


def epof_settings(job) -> dict:
    """The settings written as ``# key: JSON`` lines above ``epof.csv``'s header."""
    plan, config = job.plan, job.view.config
    return {
        "preset": job.view.preset,
        "epof_method": plan.epof_method,
        "epof_eye": plan.epof_eye,
        "frustum_deg": _frustum_deg(plan.epof_frustum),
        "fov_deg": [config.hfov_deg, config.vfov_deg],
        "mitigation": config.mitigation.kind,
        "opacity": "off" if not job.view.drawn else str(plan.opacity_label),
        "opacity_rule": _rule(job),
        "opacity_thresholds_dps": list(plan.thresholds_dps),
        # the source's initial orientation each head pose was turned by (docs/sources.md)
        **({"orientation_deg": list(pose)} if (pose := _pose(plan)) else {}),
    }


def _pose(plan):
    """The initial orientation the plan's source applies, or None."""
    return None if plan.source is None else plan.source.orientation_deg


def audio_summary(aud, requested: bool) -> dict:
    """What became of the source's audio (``aud``: :func:`simulator.media.audio.audio_source`'s
    result or None; ``requested``: audio was asked for)."""
    if aud is None:
        why = "off (--no-audio)" if not requested else "no audio stream in the source"
        return {"copied": False, "why": why}
    return {
        "copied": True,
        "codec": aud.codec,
        "mode": "packets copied" if aud.copy else "re-encoded to AAC",
        "range_s": [aud.start_s, aud.end_s],
    }


def _mitigation(job) -> dict:
    mit = job.view.mitigation
    vignette = None
    if mit.vignette:
        vignette = {
            "aperture_min_deg": mit.aperture_min_deg,
            "feather_deg": mit.feather_deg,
            "color_rgb": [round(c * 255) for c in mit.color],
        }
    local = "per-cell flow (sphere-mode field)" if job.cell_opacity is not None else None
    return {"kind": mit.kind, "vignette": vignette, "grain_opacity": local}


def _visible(job) -> dict:
    vis = job.visible
    return {
        "what": "viewport flow weighted by 1 - alpha of what is drawn over each direction",
        "flow_per_direction": "sphere-mode field" if job.per_direction else "uniform (EPOF)",
        "visible_flow_dps_mean": _mean(vis.visible_dps),
        "visible_ratio_mean": _mean(vis.ratio),
        "visible_ratio_flow_weighted": _ratio(vis.visible_dps, job.plan.epof_dps),
        "blocked_share_mean": _mean(vis.blocked),
        "visible_flow_dps_percentiles": _pct(vis.visible_dps),
    }


def viewing_summary(job, result, *, settings: dict, run: dict) -> dict:
    """The ``summary.json`` dict of a render.

    job : the :class:`simulator.viewing.job.ViewingJob`; result : the draw's
    :class:`simulator.render.video.VideoRenderResult`; settings : :func:`epof_settings`;
    run : ``x264`` (preset, crf), ``timings_s``, ``renderer`` (GL_RENDERER), ``outdir``,
    ``note`` (None: none) of this run.
    """
    plan, view, source = job.plan, job.view, job.source
    config, info, frames = view.config, plan.info, plan.frames
    fr = config.frustum
    summary = {
        "video": str(source.path),
        "headpath": job.headpath_label,
        "grid": None if plan.grid is None else (plan.grid.path or None),
        "layout": source.layout,
        "right": source.right,
        "projection": source.projection,
        "source": source.settings(),
        "coverage_mean": None if plan.coverage is None else _mean(plan.coverage),
        "eyes": job.eyes,
        "audio": audio_summary(job.audio, job.audio_requested),
        "fps": info.fps,
        "frames_video": info.n_frames,
        "range_s": [float(plan.times_s[0]), float(plan.times_s[-1])],
        "frames_range": [int(frames[0]), int(frames[-1]) + 1],
        "frames_written": result.n_frames,
        "eye_size": list(config.eye_size),
        "hfov_deg": config.hfov_deg,
        "vfov_deg": config.vfov_deg,
        "frustum_deg": {"eye": "left (the right eye mirrors left and right)", **_frustum_deg(fr)},
        "grf": grf_settings(config.grains),
        "mitigation": _mitigation(job),
        "preset": view.preset,
        "opacity": "off" if not view.drawn else plan.opacity_label,
        "opacity_rule": _rule(job),
        "opacity_thresholds_dps": list(plan.thresholds_dps),
        "epof_method": plan.epof_method,
        "epof_eye": plan.epof_eye,
        "epof_frustum_deg": settings["frustum_deg"],
        "epof_dps_percentiles": _pct(plan.epof_dps),
        "opacity_percentiles": _pct(plan.opacity),
        "visible_flow": _visible(job),
        "x264": run["x264"],
        "timings_s": run["timings_s"],
        "frames_per_s": result.frames_per_s,
        "renderer": run["renderer"],
        "outdir": run["outdir"],
        "review": list(REVIEW_FILES) if job.review else None,
    }
    if run.get("note"):
        summary["note"] = run["note"]
    return summary
