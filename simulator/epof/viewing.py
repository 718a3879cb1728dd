"""The EPOF of one viewing: a head path sampled at every frame of a grid, its opacity, its CSV and plot.

Frame i of a grid is video frame ``start_frame + i`` at ``(start_frame + i) / fps`` s (a
variable-rate video: its timestamp). ``method``: paper mode (:mod:`simulator.epof.overlaps`)
or exact sphere mode (:mod:`simulator.epof.exact`). Units: EPOF in deg/s of visual angle;
angles in degrees (yaw + right, pitch + up, roll + right ear down); times in seconds.
"""

from __future__ import annotations

import io
import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from simulator.core.errors import InputError
from simulator.core.fileio import atomic_output, check_input_file, json_value
from simulator.epof.exact import viewport_epof
from simulator.epof.overlaps import _frames, epof_from_grid, viewport_fov
from simulator.epof.parts import DEFAULT_WEIGHTS, has_parts, require_parts, viewport_parts_total
from simulator.media.coverage import coverage_masks, fade
from simulator.media.gridfile import GridFile, require_field
from simulator.media.lazyfield import take_rows
from simulator.media.spherical import view_angles_deg
from simulator.mitigation.bands import draw_bands
from simulator.mitigation.grf import OpacityRule
from simulator.preprocess.artefacts import Artefacts
from simulator.sphere.cells import Frustum
from simulator.traces.path import HeadPath

__all__ = [
    "EPOF_COLUMNS",
    "EpofResult",
    "compute_epof",
    "epof_settings",
    "plot_epof",
    "read_epof_csv",
    "write_epof_csv",
]

EPOF_COLUMNS: tuple[str, ...] = (
    "frame",
    "time_s",
    "yaw_deg",
    "pitch_deg",
    "roll_deg",
    "epof_dps",
    "opacity",
)


@dataclass(frozen=True)
class EpofResult:
    """EPOF of one viewing, one row per video frame (frame time = frame / fps, or its
    timestamp; ``frame`` counts from the video's first frame, also for a grid of part of it).

    Arrays, each shape (T,): ``frame`` (int), ``time_s``, ``yaw_deg``, ``pitch_deg``,
    ``roll_deg``, ``epof_dps`` (deg/s), ``opacity`` (0..1). ``thresholds_dps`` = the
    opacity rule's (lo, hi) in deg/s (NaN when read back from a CSV). ``coverage``: the
    covered share of each frame's viewport (a projection not covering the sphere, e.g.
    VR180; :mod:`simulator.media.coverage`), else None; written as the ``coverage`` column.
    ``epof_rot_dps``, ``epof_trans_dps``: the EPOF's rotational and translational parts
    (:mod:`simulator.epof.parts`; sphere-mode grids with the per-frame camera rotation),
    else None; with ``--flow-weights rot=A,trans=B``, ``epof_dps = A rot + B trans``.
    ``artefact``: the artefact kind of each row (``""`` = none;
    :mod:`simulator.preprocess.artefacts`), or None when artefacts were not looked for (the
    CSV then has no ``artefact`` column).
    """

    frame: NDArray[np.int64]
    time_s: NDArray[np.float64]
    yaw_deg: NDArray[np.float64]
    pitch_deg: NDArray[np.float64]
    roll_deg: NDArray[np.float64]
    epof_dps: NDArray[np.float64]
    opacity: NDArray[np.float64]
    thresholds_dps: tuple[float, float] = (math.nan, math.nan)
    meta: dict = field(default_factory=dict, compare=False)
    coverage: NDArray[np.float64] | None = None
    epof_rot_dps: NDArray[np.float64] | None = None
    epof_trans_dps: NDArray[np.float64] | None = None
    artefact: tuple[str, ...] | None = None

    def __post_init__(self) -> None:
        n = len(self.frame)
        if self.artefact is not None and len(self.artefact) != n:
            raise ValueError(f"EpofResult: artefact has {len(self.artefact)} rows; frame has {n}")
        for c in EPOF_COLUMNS:
            if len(getattr(self, c)) != n:
                raise ValueError(
                    f"EpofResult: column {c} has {len(getattr(self, c))} rows; frame has {n}"
                )


def compute_epof(
    grid: GridFile,
    hp: HeadPath,
    *,
    hfov_deg: float | None = None,
    vfov_deg: float | None = None,
    top_k: int | None = None,
    rule: OpacityRule = OpacityRule(),
    hold: bool = False,
    method: str = "auto",
    frustum: Frustum | None = None,
    frames: tuple[int, int] | None = None,
    flow_weights: tuple[float, float] | None = None,
    artefacts: Artefacts | None = None,
    orientation_deg="grid",
) -> EpofResult:
    """EPOF and GRF opacity of a viewing: the head path sampled at every frame time.

    Frame i of the grid is video frame ``start_frame + i`` (``meta["start_frame"]``, 0
    unless the grid was made with ``preprocess --start``) at ``(start_frame + i) / fps``
    seconds (a variable-rate video: its timestamps): the ``frame`` and ``time_s`` columns.
    The head path must cover every such time unless ``hold`` holds its first/last pose
    (InputError otherwise, saying where it ends).

    ``method``: ``"paper"`` = overlap-weighted mean of window POFs (section 3.5);
    ``"sphere"`` = exact EPOF, the grid's sphere-mode field integrated over the actual
    viewport (:func:`simulator.epof.exact.viewport_epof`; any FOV, roll included; InputError
    naming the command that makes a field if the grid has none); ``"auto"`` (default) =
    sphere when the grid has a field and ``top_k`` is not given, else paper.

    ``frustum`` (:class:`simulator.sphere.cells.Frustum`, e.g. a headset's asymmetric per-eye
    frustum) is the viewport; it replaces ``hfov_deg``/``vfov_deg``. Sphere mode
    integrates over exactly that frustum; paper mode's overlap table is tabulated for
    centred views and uses the frustum's total FOVs (``hfov_deg``, ``vfov_deg``).
    Default: the symmetric view of ``hfov_deg x vfov_deg`` (default the grid's FOV).

    ``frames = (f0, f1)``: only the grid rows of video frames ``f0 <= i < f1`` (a rendered
    time range; the cost is proportional to it). The head path must cover those times;
    opacity percentiles of source ``grid`` still come from the whole grid, those of
    source ``viewing`` from these rows, and smoothing / easing start at ``f0``.

    Sphere-mode EPOF of a grid with the per-frame camera rotation also gives its parts
    (:mod:`simulator.epof.parts`); ``flow_weights = (A, B)``: the EPOF (and opacity) is
    ``A rot + B trans``, InputError for a grid without the parts (re-run preprocess).

    ``artefacts`` (:class:`simulator.preprocess.artefacts.Artefacts`, one kind per grid
    row): artefact frames are left out of the opacity percentiles (both sources), their
    opacity is held from the previous clean frame, and the result's ``artefact`` column
    names their kind; their EPOF is kept as measured.

    ``orientation_deg``: the source's initial orientation (yaw, pitch, roll; None: none);
    ``"grid"``: the one the grid's source applied (``meta["source"]``). Each head pose is
    turned by it before the view is taken; the result keeps the head's angles.
    """
    if frustum is not None:
        if not isinstance(frustum, Frustum):
            raise InputError(f"EPOF frustum must be a Frustum; got {type(frustum).__name__}")
        hfov_deg, vfov_deg = frustum.hfov_deg, frustum.vfov_deg
    frames_sel = frames
    if method not in ("auto", "paper", "sphere"):
        raise InputError(f"unknown EPOF method {method!r}; expected auto, paper or sphere")
    sphere = method == "sphere" or (
        method == "auto" and grid.field_dps is not None and top_k is None
    )
    if sphere and top_k is not None:
        raise InputError(
            "--top-k applies to paper-mode EPOF (window overlaps); sphere mode integrates the "
            "field over the viewport: drop --top-k or use --method paper"
        )
    frames, t, rows = _select_frames(grid, frames_sel)
    hp.check_covers(
        float(t[-1]),
        hold=hold,
        video=grid.meta.get("video", {}).get("path", "") or grid.path,
        start_s=float(t[0]),
    )
    yaw, pitch, roll = hp.sample_angles_deg(t, hold=hold)
    h, v = viewport_fov(grid, hfov_deg, vfov_deg)
    view = frustum or Frustum.symmetric(h, v)
    sel_rows = rows if frames_sel is not None else None
    pose = orientation_deg
    if pose == "grid":  # the initial orientation the grid's source applied
        pose = (grid.meta.get("source") or {}).get("orientation_deg")
    e, cov, parts = _epof_values(
        grid, view_angles_deg(pose, yaw, pitch, roll), view, rows, sel_rows, sphere,
        flow_weights, (hfov_deg, vfov_deg, top_k, frustum),
    )  # fmt: skip
    thr, op, kinds = _opacity(rule, grid, e, rows, artefacts)
    meta = _meta(grid, (h, v), frustum, top_k, rule, sphere, flow_weights, pose)
    if cov is not None:
        meta["coverage_rule"] = grid.meta["coverage"]["rule"]
    return EpofResult(
        frames, t, yaw, pitch, roll, e, op, thr, meta, cov,
        *(parts if parts is not None else (None, None)), kinds,
    )  # fmt: skip


def _meta(grid, fov, frustum, top_k, rule, sphere: bool, flow_weights, pose) -> dict:
    """:func:`compute_epof`'s settings (``EpofResult.meta``)."""
    f = frustum
    fr = None if f is None else [f.left_deg, f.right_deg, f.down_deg, f.up_deg]
    return {
        "hfov_deg": fov[0],
        "vfov_deg": fov[1],
        "frustum_deg": fr,
        "top_k": top_k,
        "rule": rule,
        "fps": grid.fps,
        "method": "sphere" if sphere else "paper",
        "flow_weights": None if flow_weights is None else list(flow_weights),
        "video_content_hash": (grid.meta.get("video") or {}).get("content_hash"),
        "orientation_deg": None if pose is None else [float(a) for a in pose],
    }


def _opacity(rule: OpacityRule, grid: GridFile, e, rows, artefacts: Artefacts | None):
    """``(thresholds, opacity, kinds)`` of a viewing's EPOF ``e`` (grid rows ``rows``):
    artefact frames left out of the percentiles and the opacity held through them."""
    if artefacts is None:
        thr = rule.fit(grid, e)
        return thr, rule(e, thr, fps=grid.fps), None
    if len(artefacts.kind) != grid.n_frames:
        raise InputError(f"artefacts: {len(artefacts.kind)} frames; the grid has {grid.n_frames}")
    kinds = tuple(artefacts.kind[int(r)] for r in rows)
    bad = np.array([k != "" for k in kinds], bool)
    keep = ~bad if rule.source == "viewing" else ~artefacts.mask
    thr = rule.fit(grid, e, keep=keep if keep.any() else None)
    return thr, rule(_held(e, bad), thr, fps=grid.fps), kinds


def _held(e: NDArray, bad: NDArray) -> NDArray[np.float64]:
    """``e`` with each flagged sample replaced by the last clean one before it (the first
    clean one for a leading run): the opacity holds through an artefact."""
    out = np.array(e, np.float64)
    if not bad.any() or bad.all():
        return out
    idx = np.where(~bad, np.arange(out.size), -1)
    np.maximum.accumulate(idx, out=idx)
    first = int(np.flatnonzero(~bad)[0])
    idx[idx < 0] = first
    return out[idx]


def _covered_epof(grid, e, sphere: bool, yaw, pitch, roll, hfov_deg, vfov_deg, top_k, frustum):
    """EPOF over the covered part of each view and its covered share (None when the
    grid's projection covers the sphere): the mean of the flow (0 outside) over the view
    divided by the mean of the covered mask, faded below ``MIN_COVERAGE``."""
    wins, cells = coverage_masks(grid.meta)
    if cells is None:
        return e, None
    h, v = viewport_fov(grid, hfov_deg, vfov_deg)
    fr = frustum or Frustum.symmetric(h, v)
    mask = np.broadcast_to(cells.astype(np.float32), (len(e), *cells.shape))
    share = viewport_epof(mask, grid.meta["coverage"]["cell_deg"], yaw, pitch, roll, frustum=fr)
    share = np.clip(np.asarray(share, float), 0.0, 1.0)  # the viewport's covered share
    if not sphere:  # paper mode: the overlap weight of the covered windows
        norm = epof_from_grid(grid, yaw, pitch, roll, 0, hfov_deg=hfov_deg, vfov_deg=vfov_deg,
                              top_k=top_k, pof=wins.astype(np.float32))  # fmt: skip
        norm = np.clip(np.asarray(norm, float), 0.0, 1.0)
    else:
        norm = share
    covered_mean = np.where(norm > 1e-9, e / np.maximum(norm, 1e-9), 0.0)
    return covered_mean * fade(share), share


def _epof_values(grid, angles, view: Frustum, rows, sel_rows, sphere: bool, flow_weights, paper):
    """``(EPOF per row, covered share or None, (rot, trans) parts or None)``: the weighted
    parts, the field integrated over ``view`` (sphere) or the window overlaps (paper:
    ``paper = (hfov_deg, vfov_deg, top_k, frustum)``), over the covered part of the view."""
    yaw, pitch, roll = angles
    hfov_deg, vfov_deg, top_k, frustum = paper
    parts = _parts(grid, (yaw, pitch, roll), view, sel_rows, sphere, flow_weights)
    if parts is not None and tuple(flow_weights or DEFAULT_WEIGHTS) != DEFAULT_WEIGHTS:
        a, b = flow_weights
        e = a * parts[0] + b * parts[1]
    elif parts is not None:  # the same integration gave the whole EPOF
        e = parts[2]
    elif sphere:
        field, cells = require_field(grid)
        if sel_rows is not None:
            field = take_rows(field, rows)  # lazy: nothing read yet
        e = viewport_epof(field, cells.cell_deg, yaw, pitch, roll, frustum=view)
    else:
        e = epof_from_grid(
            grid, yaw, pitch, roll, rows, hfov_deg=hfov_deg, vfov_deg=vfov_deg, top_k=top_k
        )
    parts = None if parts is None else parts[:2]
    e_cov, cov = _covered_epof(grid, e, sphere, yaw, pitch, roll, hfov_deg, vfov_deg, top_k, frustum)
    if cov is not None and parts is not None:  # the parts scaled as their sum was
        k = np.where(e > 0, e_cov / np.maximum(e, 1e-12), 0.0)
        parts = (parts[0] * k, parts[1] * k)
    e = e_cov
    return e, cov, parts


def _select_frames(grid: GridFile, frames_sel):
    """``(video frames, times, grid rows)`` of the grid, only those of video frames
    ``f0 <= i < f1`` when ``frames_sel = (f0, f1)``."""
    frames, t = _frames(grid)
    rows = np.arange(grid.n_frames)  # grid rows, not video frame numbers
    if frames_sel is not None:
        keep = (frames >= frames_sel[0]) & (frames < frames_sel[1])
        if not keep.any():
            raise InputError(
                f"{grid.path or 'grid'}: no grid frame in video frames {frames_sel[0]}..{frames_sel[1]}"
            )
        frames, t, rows = frames[keep], t[keep], rows[keep]
    return frames, t, rows


def _parts(grid, angles, view: Frustum, rows, sphere: bool, flow_weights):
    """``(rot, trans)`` EPOF parts when the grid has them and sphere-mode EPOF is used (or
    ``flow_weights`` asks for them: InputError when they cannot be had), else None."""
    if flow_weights is not None:
        require_parts(grid)
        if not sphere:
            raise InputError(
                "--flow-weights needs sphere-mode EPOF (the grid's field split into rotation "
                "and translation): drop --method paper / --top-k"
            )
    if not (sphere and has_parts(grid)):
        return None
    return viewport_parts_total(grid, *angles, frustum=view, rows=rows)


def epof_settings(result: EpofResult) -> dict:
    """The settings of a computed EPOF (:func:`compute_epof`'s ``meta``) as recorded in
    the CSV's ``#`` lines: method, FOV, frustum, top-k, opacity rule and thresholds, and
    the content hash of the video the grid was made from."""
    m = result.meta
    rule = m.get("rule")
    fr = m.get("frustum_deg")
    return {
        "epof_method": m.get("method"),
        "fov_deg": [m.get("hfov_deg"), m.get("vfov_deg")],
        "frustum_deg": None if fr is None else dict(zip(("left", "right", "down", "up"), fr)),
        "top_k": m.get("top_k"),
        "opacity_rule": None if rule is None else rule.describe(),
        "opacity_thresholds_dps": [float(v) for v in result.thresholds_dps],
        **({"flow_weights": m["flow_weights"]} if m.get("flow_weights") else {}),
        # the source's initial orientation each head pose was turned by (docs/sources.md)
        **({"orientation_deg": m["orientation_deg"]} if m.get("orientation_deg") else {}),
        # the video the grid was made from (``render --opacity EPOF.csv`` checks it)
        "video_content_hash": m.get("video_content_hash"),
    }


def _json_value(v) -> str:
    """JSON of a setting, NaN as null (a threshold without a grid)."""

    def clean(x):
        if isinstance(x, float) and not math.isfinite(x):
            return None
        if isinstance(x, dict):
            return {k: clean(y) for k, y in x.items()}
        if isinstance(x, (list, tuple)):
            return [clean(y) for y in x]
        return x

    return json.dumps(clean(v), sort_keys=True, allow_nan=False)


def write_epof_csv(
    path: str | os.PathLike,
    result: EpofResult,
    *,
    extra: dict | None = None,
    settings: dict | None = None,
) -> None:
    """Write ``frame,time_s,yaw_deg,pitch_deg,roll_deg,epof_dps,opacity`` atomically, then
    the parts (``epof_rot_dps``, ``epof_trans_dps``), the ``extra`` columns (name -> array
    of one value per row), if any, in order, ``coverage``, then ``artefact`` (the kind,
    empty for a clean frame) when the result has one.

    The settings that produced it come first as ``# key: JSON value`` comment lines
    (``settings``, default :func:`epof_settings` of ``result`` when it has ``meta``):
    :func:`read_epof_csv` (and ``pandas.read_csv(path, comment="#")``) skip those lines."""
    extra = {**_parts_columns(result), **(extra or {})}
    if result.coverage is not None and "coverage" not in extra:
        extra["coverage"] = result.coverage
    buf = io.StringIO()
    if settings is None and result.meta:
        settings = epof_settings(result)
    for k, v in (settings or {}).items():
        buf.write(f"# {k}: {_json_value(v)}\n")
    art = result.artefact
    buf.write(",".join((*EPOF_COLUMNS, *extra, *(("artefact",) if art is not None else ()))) + "\n")
    cols = [np.round(getattr(result, c), 9) + 0.0 for c in EPOF_COLUMNS[1:]]
    cols += [np.round(np.asarray(v, float), 9) + 0.0 for v in extra.values()]
    for i, fr in enumerate(result.frame):
        tail = f",{art[i]}" if art is not None else ""
        buf.write(f"{int(fr)}," + ",".join(f"{c[i]:.10g}" for c in cols) + tail + "\n")
    with atomic_output(path) as tmp:
        Path(tmp).write_text(buf.getvalue())


#: The EPOF's parts, written after the EPOF columns when known.
PART_COLUMNS: tuple[str, ...] = ("epof_rot_dps", "epof_trans_dps")


def _parts_columns(result: EpofResult) -> dict:
    if result.epof_rot_dps is None or result.epof_trans_dps is None:
        return {}
    return dict(zip(PART_COLUMNS, (result.epof_rot_dps, result.epof_trans_dps)))


def read_epof_csv(path: str | os.PathLike) -> EpofResult:
    """Read an EPOF CSV written by :func:`write_epof_csv` (InputError if malformed).

    ``#`` lines are comments; those of the form ``# key: JSON`` (the settings
    :func:`write_epof_csv` records) come back in ``meta["settings"]``. Extra columns after
    the EPOF columns (e.g. ``vimsim render``'s visible flow) are ignored, but for the
    parts ``epof_rot_dps``, ``epof_trans_dps`` and the ``artefact`` kinds when present."""
    p = check_input_file(path, "EPOF")
    lines, settings = [], {}
    for ln in p.read_text(encoding="utf-8", errors="replace").splitlines():
        t = ln.strip()
        if not t:
            continue
        if t.startswith("#"):
            key, sep, val = t[1:].partition(":")
            if sep:
                settings[key.strip()] = json_value(val, p, default=val.strip())  # not JSON: text
            continue
        lines.append(ln)
    if not lines:
        raise InputError(f"{p}: EPOF file is empty; expected the header {','.join(EPOF_COLUMNS)}")
    cols = [c.strip() for c in lines[0].split(",")]
    if cols[: len(EPOF_COLUMNS)] != list(EPOF_COLUMNS):
        raise InputError(f"{p}: columns {cols}; expected {','.join(EPOF_COLUMNS)}")
    if len(lines) < 2:
        raise InputError(f"{p}: EPOF file has a header but no rows")
    ai = cols.index("artefact") if "artefact" in cols else None
    body = lines[1:]
    if any(ln.count(",") != len(cols) - 1 for ln in body):
        raise InputError(f"{p}: every row needs {len(cols)} fields")
    kinds = tuple(ln.split(",")[ai].strip() for ln in body) if ai is not None else None
    try:  # numpy's C parser: the numbers of a long viewing in milliseconds
        data = np.loadtxt(body, delimiter=",", dtype=np.float64, ndmin=2, comments=None,
                          usecols=[j for j in range(len(cols)) if j != ai])  # fmt: skip
    except ValueError:
        raise InputError(f"{p}: non-numeric value in an EPOF row") from None
    num = [c for j, c in enumerate(cols) if j != ai]  # the numeric columns, in order
    parts = {c: data[:, num.index(c)] for c in PART_COLUMNS if c in num}
    data = data[:, : len(EPOF_COLUMNS)]
    if not np.all(np.isfinite(data)) or not all(np.all(np.isfinite(v)) for v in parts.values()):
        raise InputError(f"{p}: EPOF file has NaN or infinite values")
    arrs = {c: data[:, i] for i, c in enumerate(EPOF_COLUMNS)}
    arrs["frame"] = arrs["frame"].astype(np.int64)
    thr = settings.get("opacity_thresholds_dps")
    try:
        thr = tuple(math.nan if v is None else float(v) for v in thr[:2]) if thr else None
        thr = thr if thr and len(thr) == 2 else (math.nan, math.nan)
    except (TypeError, ValueError):
        thr = (math.nan, math.nan)
    return EpofResult(
        **arrs, thresholds_dps=thr, meta={"settings": settings} if settings else {}, **parts,
        artefact=kinds,
    )  # fmt: skip


def break_at_wraps(t, yaw_deg) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``(t, yaw)`` with a NaN between samples where yaw wraps (jumps by over 180 deg at
    the +-180 seam), so a plotted line breaks there instead of crossing the panel."""
    t, y = np.asarray(t, float), np.asarray(yaw_deg, float)
    jumps = np.flatnonzero(np.abs(np.diff(y)) > 180.0) + 1
    return np.insert(t, jumps, np.nan), np.insert(y, jumps, np.nan)


def plot_epof(path: str | os.PathLike, result: EpofResult, *, title: str = "") -> None:
    """Plot a viewing into a PNG (atomic), three panels sharing the time axis: EPOF
    (deg/s) with the opacity thresholds labelled at the right edge, clear of the data;
    GRF opacity; head yaw and pitch (degrees). The figure widens with the duration so
    that 40 s and longer stay readable."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = np.asarray(result.time_s, float)
    dur = float(t[-1] - t[0]) if t.size > 1 else 1.0
    width = float(np.clip(6 + dur / 6, 9, 24))
    fig, (ax, ax_op, ax_hd) = plt.subplots(
        3, 1, figsize=(width, 6.4), dpi=110, sharex=True, height_ratios=(2.2, 1.2, 1.6)
    )
    ax.plot(t, result.epof_dps, color="tab:blue", lw=1.0)
    ax.set_ylabel("EPOF (deg/s)")
    ax.set_ylim(0, max(float(np.max(result.epof_dps)) * 1.05, 1.0))
    draw_bands(ax, labels=False)  # the named flow bands (mitigation/bands), deg/s
    if result.artefact is not None:  # artefact frames: grey, their opacity held
        half = 0.5 / (result.meta.get("fps") or 30)
        for k, a_ in enumerate(result.artefact):
            if a_:
                ax.axvspan(t[k] - half, t[k] + half, color="0.5", alpha=0.35, lw=0)
    lo, hi = result.thresholds_dps
    for v, name in ((lo, "opacity 0"), (hi, "opacity 1")):
        if math.isfinite(v):
            ax.axhline(v, color="0.35", ls=":", lw=0.9)
            ax.annotate(f"{name}: {v:.3g}", xy=(1.0, v), xycoords=("axes fraction", "data"),
                        xytext=(4, 0), textcoords="offset points", va="center", fontsize=8,
                        color="0.25", annotation_clip=False)  # fmt: skip
    ax.set_title(title or "EPOF and GRF opacity")
    ax_op.plot(t, result.opacity, color="tab:red", lw=1.0)
    ax_op.set_ylim(-0.03, 1.03)
    ax_op.set_ylabel("GRF opacity")
    ax_hd.plot(*break_at_wraps(t, result.yaw_deg), color="tab:green", lw=1.0, label="yaw")
    if np.nanmax(np.abs(result.yaw_deg)) > 150:  # a path that wraps: the whole seam range
        ax_hd.set_ylim(-185, 185)
    ax_hd.plot(t, result.pitch_deg, color="tab:purple", lw=1.0, label="pitch")
    ax_hd.set_ylabel("head (deg)")
    ax_hd.legend(loc="upper left", fontsize=8, ncol=2, frameon=False)
    ax_hd.set_xlabel("time (s)")
    for a_ in (ax, ax_op, ax_hd):
        a_.grid(alpha=0.25)
    fig.tight_layout()
    fig.subplots_adjust(right=0.9)
    with atomic_output(path) as tmp:
        fig.savefig(tmp)
    plt.close(fig)
