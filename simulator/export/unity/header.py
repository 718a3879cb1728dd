"""The JSON header of a Unity export: data layout, viewport, opacity rule, GRF and vignette, source length and range."""

from __future__ import annotations

import inspect
import math
import os
from pathlib import Path

import numpy as np

from simulator import __version__
from simulator.core.errors import InputError
from simulator.epof.exact import viewport_epof
from simulator.epof.overlaps import ViewportOverlaps
from simulator.export.unity.binary import FORMAT, FRAME_EPS, VERSION
from simulator.media.coverage import MIN_COVERAGE, coverage_masks
from simulator.media.gridfile import GridFile, content_hash
from simulator.mitigation.grf import GrfConfig, OpacityRule
from simulator.mitigation.kinds import Mitigation

__all__ = ["GENERATOR", "build_header", "set_data_shape"]

#: How the grain layout was drawn (the layout itself is stored: section ``grains``).
GENERATOR = (
    "numpy.random.default_rng(seed) (PCG64): z = uniform(-1, 1, n), lon = uniform(-pi, pi, n); "
    "centre (sqrt(1 - z^2) sin(lon), z, sqrt(1 - z^2) cos(lon)); n = round(log(1 - density) / "
    "log(1 - a / 4 pi)), a = 2 pi (1 - cos(grain_deg / 2)) (simulator.mitigation.grf)"
)


def _defaults(fn, names: tuple[str, ...]) -> dict:
    """Default values of ``fn``'s keyword parameters ``names``: the numbers ``vimsim epof``
    runs with, so the runtime builds the same tables."""
    sig = inspect.signature(fn)
    return {n: sig.parameters[n].default for n in names}


def _table_params() -> dict:
    """The :class:`~simulator.epof.ViewportOverlaps` table parameters ``epof_from_grid`` uses."""
    return _defaults(
        ViewportOverlaps,
        ("pitch_step_deg", "roll_step_deg", "yaw_step_deg", "rays", "lat_step_deg", "lon_step_deg"),
    )


def _data_section(data: np.ndarray, dtype: str, sphere: bool) -> dict:
    return {
        "dtype": dtype,
        "shape": [int(s) for s in data.shape],
        "offset": 0,
        "bytes": int(data.nbytes),
        "order": "C, little-endian",
        "units": "deg/s of visual angle",
        "rows": "row t = video frame start_frame + t (flow from frame t-1 to t; row 0 repeats row 1)",
        "what": (
            "field cells [t][i][j]: lat centre 90 - (i + 0.5) cell_deg, lon centre -180 + (j + 0.5) cell_deg"
            if sphere
            else "window POF [t][p][y] of the window centred at grid.pitch_deg[p], grid.yaw_deg[y]"
        ),
    }


def _opacity_section(rule: OpacityRule, lo: float, hi: float) -> dict:
    return {
        "rule": "linear",
        "formula": "clamp((epof - low_dps) / (high_dps - low_dps), 0, 1); if high_dps <= low_dps: 1 where epof > low_dps else 0",
        "name": "paper" if rule.is_paper else "eased",
        "easing": "per video frame, starting at the first value: v += a (x - v), a = 1 - exp(-1 / (fps smoothing_s)) "
        "(smoothing_s > 0); then the change is limited to at most +1 / (fps ease_in_s) and at least "
        "-1 / (fps ease_out_s) (each > 0; 0 = no limit)",
        "ease_in_s": float(rule.ease_in_s),
        "ease_out_s": float(rule.ease_out_s),
        "low_pct": float(rule.low_pct),
        "high_pct": float(rule.high_pct),
        "source": "absolute: fixed deg/s (--opacity-rule absolute), the same for every video"
        if rule.is_absolute
        else "grid: every window of every frame of pof_dps (only the windows the projection covers)",
        # relative: low/high_dps are percentiles of this video's flow; absolute: fixed deg/s
        "scale": "absolute" if rule.is_absolute else "relative",
        "low_dps": lo,
        "high_dps": hi,
        "smoothing_s": float(rule.smoothing_s),
    }


def _mitigation_sections(grf: GrfConfig, mitigation: Mitigation, n_grains: int) -> dict:
    """``grf``, ``vignette``, ``mitigation`` and ``grains`` (the layout section) of the header."""
    return {
        "mitigation": mitigation.kind,
        "grf": {
            "grain_deg": float(grf.grain_deg),
            "density": float(grf.density),
            "inner_deg": float(grf.inner_deg),
            "outer_deg": float(grf.outer_deg),
            "seed": int(grf.seed),
            "n_grains": int(n_grains),
            "layout": grf.layout,  # random (GENERATOR's draw) or fibonacci (docs/parity.md)
            "generator": GENERATOR,
            "cutout": "alpha = clamp((ecc - inner_deg) / (outer_deg - inner_deg), 0, 1) * opacity, "
            "ecc = angle from the view centre; grains at infinity (no parallax)",
        },
        "vignette": {
            "aperture_min_deg": float(mitigation.aperture_min_deg),
            "feather_deg": float(mitigation.feather_deg),
            "color": [float(c) for c in mitigation.color],
            "rule": "aperture radius r = r_full + (aperture_min_deg / 2 - r_full) opacity, r_full = the "
            "view's corner eccentricity + feather_deg / 2; alpha = clamp((ecc - r) / feather_deg + 1/2, 0, 1)",
        },
        "grains": {
            "offset": 0,
            "dtype": "float32",
            "shape": [int(n_grains), 3],
            "what": "grain centres, world unit vectors (x right, y up, z forward), C order",
        },
    }


def _range_sections(g: GridFile, start: int, T: int) -> dict:
    """``source`` (the whole video's length), ``range`` (the exported frames) and, for a
    variable-rate video, ``frame_times_s`` (each exported frame's time: the frame rule
    then looks them up instead of ``time * fps``)."""
    fps = float(g.fps)
    video = g.meta.get("video", {}) or {}
    known = video.get("n_frames")
    n_src = int(known) if known else start + T
    times = g.meta.get("frame_times_s")
    vfr = times is not None and len(times) >= T
    pose = (g.meta.get("source") or {}).get("orientation_deg")
    out: dict = {
        "source": {
            "n_frames": n_src,
            "duration_s": n_src / fps,
            "known": bool(known),
            "what": "the source video's length (known: from the grid's meta; else the grid's end)",
            # the file's initial orientation (spherical metadata), applied as vimsim applies it
            **({"orientation_deg": [float(v) for v in pose],
                "orientation_rule": "head angles are turned by it before every query and "
                "drawing: view = R(orientation) R(head), R = head_rotation (docs/sources.md)"}
               if pose is not None and any(float(v) for v in pose) else {}),
        },
        "range": {
            "start_frame": start,
            "end_frame": start + T,
            "start_s": start / fps,
            "end_s": (start + T) / fps,
            "rule": f"covered: start_frame <= floor(time_s * fps + {FRAME_EPS:g}) < end_frame",
        },
    }
    if vfr:  # the stream's own timestamps (player's clock); the last frame lasts 1 / fps
        t = [float(v) for v in times[:T]]
        out["frame_times_s"] = t
        out["range"].update(start_s=t[0], end_s=t[-1] + 1.0 / fps, rule=VFR_RULE)
    return out


#: The frame rule of a variable-rate export (``frame_times_s`` present).
VFR_RULE = (
    f"frame = start_frame + the index of the last frame_times_s <= time_s + {FRAME_EPS:g} / fps; "
    "covered: range.start_s <= time_s + that tolerance < range.end_s"
)


def _coverage_section(g: GridFile, cells) -> dict | None:
    """``coverage`` of a sphere-mode export whose source's projection does not cover the
    sphere (VR180): the covered cells (row-major, as the data's rows) and the rule the
    runtimes apply, as ``vimsim epof`` does (:mod:`simulator.media.coverage`); None when
    everything is covered."""
    _, mask = coverage_masks(g.meta)
    if mask is None:
        return None
    if tuple(mask.shape) != tuple(cells.shape):
        raise InputError(
            f"{g.path}: the grid's coverage cells {mask.shape} do not match its field "
            f"{tuple(cells.shape)}; preprocess it again"
        )
    return {
        "cells": [int(v) for v in np.asarray(mask, bool).ravel()],
        "min_coverage": float(MIN_COVERAGE),
        "rule": "share = the viewport query of the covered cells (1 covered, 0 not), clamped to "
        "0..1; epof = (query of the field) / share * min(1, share / min_coverage), 0 where "
        "share <= 1e-9 (the covered part's mean, faded where the viewer sees mostly no content)",
    }


def build_header(g: GridFile, data: np.ndarray, *, sphere: bool, dtype: str, fov: tuple,
                 rule: OpacityRule, thresholds: tuple, grf: GrfConfig, mitigation: Mitigation,
                 n_grains: int, cache_bins: int, cells=None) -> dict:  # fmt: skip
    """The whole header (see ``docs/unity.md``); offsets are filled in by ``binary.pack``."""
    start = int(g.meta.get("start_frame", 0) or 0)
    T = int(data.shape[0])
    video = dict(g.meta.get("video", {}))
    grid_dict = dict(g.meta["grid"])
    grid_dict.update(yaw_deg=[float(x) for x in g.yaw_deg], pitch_deg=[float(x) for x in g.pitch_deg])
    src = g.path or "grid"
    header: dict = {
        "format": FORMAT,
        "version": VERSION,
        "mode": "sphere" if sphere else "paper",
        "data": _data_section(data, dtype, sphere),
        "fps": float(g.fps),
        "n_frames": T,
        "start_frame": start,
        "frame_rule": f"frame = floor(time_s * fps + {FRAME_EPS:g}) (a variable-rate video: "
        "range.rule, from frame_times_s); outside range: not covered "
        "(Covers false; Epof clamps to the first / last exported frame)",
        "viewport": {"hfov_deg": fov[0], "vfov_deg": fov[1]},
        "grid": grid_dict,
        "opacity": _opacity_section(rule, *thresholds),
        "conventions": "degrees; yaw + turns right, pitch + looks up, roll + right ear down; applied yaw, "
        "then pitch, then roll (intrinsic); world +x right, +y up, +z forward (equirect centre)",
        "video": {
            "content_hash": video.get("content_hash", ""),
            "path": os.path.basename(str(video.get("path", ""))),
            "width": video.get("width"),
            "height": video.get("height"),
            "layout": g.meta.get("layout"),
            "eye": g.meta.get("eye"),
        },
        "grid_file": {
            "name": os.path.basename(src),
            "content_hash": content_hash(g.path) if g.path and Path(g.path).is_file() else "",
        },
        "flow": g.meta.get("flow"),
        "vimsim_version": __version__,
        **_mitigation_sections(grf, mitigation, n_grains),
        **_range_sections(g, start, T),
    }
    if sphere:
        header["field"] = {
            "cell_deg": float(cells.cell_deg),
            "n_lat": int(cells.shape[0]),
            "n_lon": int(cells.shape[1]),
            "query_step_deg": float(_defaults(viewport_epof, ("step_deg",))["step_deg"]),
            "cache_bins": int(cache_bins),
        }
        cov = _coverage_section(g, cells)
        if cov is not None:
            header["coverage"] = cov
    else:
        if coverage_masks(g.meta)[0] is not None:
            raise InputError(
                f"{g.path}: a paper-mode export of a source that does not cover the sphere "
                f"({g.meta.get('projection')}) is not supported (the runtimes would count its "
                "uncovered windows as still); export a sphere-mode grid (vimsim preprocess "
                "--method sphere)"
            )
        table = _table_params()
        header["overlap_table"] = {k: float(x) for k, x in table.items()}
        header["overlap_table"]["rays"] = int(table["rays"])
    return header


def set_data_shape(header: dict, g: GridFile, shape) -> None:
    """Give a header of :func:`build_header` another data shape of the same dtype (rows =
    frames from ``start_frame``): ``n_frames``, ``data.shape``, ``data.bytes``, ``source`` and
    ``range``, as :func:`build_header` makes them for data of that shape. For a writer that
    streams the data instead of holding it (the web export of a float16 field)."""
    shape = [int(s) for s in shape]
    itemsize = {"float16": 2, "float32": 4}[header["data"]["dtype"]]
    header["n_frames"] = shape[0]
    header["data"]["shape"] = shape
    header["data"]["bytes"] = itemsize * math.prod(shape)
    header.update(_range_sections(g, int(header["start_frame"]), shape[0]))
