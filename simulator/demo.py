"""The end-to-end demo (``vimsim demo``, what ``make demo`` runs).

Steps, each printed with its wall-clock time:

1. ``synth``: a short stereo (top-bottom) coaster clip with analytic ground truth
   (:mod:`simulator.synth`).
2. ``headpath``: a seeded look-around head path (:func:`simulator.traces.path.synth`).
3. ``preprocess``: the POF matrix of the left eye (:func:`simulator.preprocess.preprocess_video`,
   DIS flow, the default 24 x 11 window grid at a small window size).
4. ``epof``: EPOF and GRF opacity of the viewing (:func:`simulator.epof.compute_epof`).
5. ``render``: per-eye MP4s with the GRF overlay (:func:`simulator.viewing.job.render_viewing`,
   what ``vimsim render`` runs).
6. plots (EPOF and opacity over time; POF heat maps over yaw x pitch for a few frames
   and averaged, estimated beside the analytic truth), ``README.txt`` and
   ``summary.json``.

Deterministic given ``seed`` (texture placement, head path, grain layout).
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from simulator.core.errors import InputError
from simulator.core.fileio import OutputFolder, atomic_output, json_text
from simulator.core.progress import Progress
from simulator.epof.viewing import compute_epof, write_epof_csv
from simulator.media.gridfile import load_grid
from simulator.media.source import Source
from simulator.mitigation.grf import GrfConfig, rule_from_options
from simulator.preprocess.paper import preprocess_video
from simulator.render.eye import RenderConfig
from simulator.sphere.geometry import head_rotation, perspective_rays
from simulator.sphere.windows import grid_preset
from simulator.synth.clip import load_truth, synthesize
from simulator.synth.scenes import SynthConfig, make_scene, window_truth_dps
from simulator.traces.path import save_headpath_csv
from simulator.traces.path import synth as synth_headpath
from simulator.viewing.job import render_viewing
from simulator.viewing.spec import ViewSpec

__all__ = ["DemoConfig", "run_demo"]


@dataclass(frozen=True)
class DemoConfig:
    """Sizes of the demo (defaults fit in about a minute or two on 2 cores).

    seconds : clip length (s); fps : frames/s; eye_size : (W, H) of each equirect eye
    (2:1); window : window size (px) of the POF grid; render_size : per-eye review
    video size (px); seed : texture placement, head path and grains; render : False
    skips step 5 (the per-eye videos).
    """

    seconds: float = 3.0
    fps: float = 30.0
    eye_size: tuple[int, int] = (768, 384)
    window: int = 128
    render_size: tuple[int, int] = (480, 480)
    seed: int = 0
    render: bool = True

    def __post_init__(self) -> None:
        if not (self.seconds > 0 and self.fps > 0 and math.isfinite(self.seconds * self.fps)):
            raise InputError(f"demo seconds and fps must be > 0; got {self.seconds}, {self.fps}")
        if self.window < 16:
            raise InputError(f"demo window size must be >= 16 px; got {self.window}")


_FILES = {
    "coaster.mp4": "the synthetic stereo clip (top-bottom, left eye on top, eyes 64 mm apart): a "
    "figure-eight coaster ride with hills, turns, banking and changing speed through a "
    "textured room (vimsim synth --scene coaster --layout top-bottom)",
    "coaster.truth.npz": "its analytic ground truth: angular speed (deg/s) per frame on a 4-degree "
    "lon/lat grid for each eye, the parameters and the camera trajectory (docs/synth.md)",
    "headpath.csv": "a seeded look-around head path (time_s,yaw_deg,pitch_deg,roll_deg)",
    "grid.npz": "the POF matrix of the left eye (vimsim preprocess; pof_dps (T, P, Y) in deg/s, "
    "frame t = flow from t-1 to t)",
    "epof.csv": "EPOF (deg/s) and GRF opacity per video frame along the head path",
    "epof_opacity.png": "EPOF and GRF opacity over time; the exact truth EPOF (analytic speed "
    "averaged over the viewport) dashed",
    "pof_heatmaps.png": "POF over yaw x pitch for a few frames and averaged over the clip: "
    "estimated (top row) and analytic truth (bottom row), same colour scale",
    "render/left.mp4": "what the left eye saw (107 deg FOV) with the GRF overlay",
    "render/right.mp4": "what the right eye saw",
    "render/epof.csv": "the EPOF and opacity the renderer used (same columns as epof.csv)",
    "render/summary.json": "the renderer's settings and timings",
    "summary.json": "this demo's settings, step timings, accuracy against the truth and files",
    "README.txt": "this file",
}


def _step(log: list, name: str, t0: float, note: Callable[[str], None] | None) -> float:
    dt = time.perf_counter() - t0
    log.append((name, dt))
    if note is not None:
        note(f"{name} done in {dt:.1f} s")
    return time.perf_counter()


def _plot_epof(path: Path, res, exact: np.ndarray) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(9, 3.6), dpi=110)
    ax.plot(res.time_s, res.epof_dps, color="tab:blue", lw=1.4, label="EPOF (estimated)")
    ax.plot(res.time_s, exact, color="tab:blue", lw=1.0, ls="--", label="exact viewport truth")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("EPOF (deg/s)", color="tab:blue")
    ax.set_ylim(bottom=0)
    ax2 = ax.twinx()
    ax2.plot(res.time_s, res.opacity, color="tab:red", lw=1.0, label="GRF opacity")
    ax2.set_ylim(-0.02, 1.02)
    ax2.set_ylabel("GRF opacity", color="tab:red")
    lines = ax.get_lines() + ax2.get_lines()
    ax.legend(lines, [ln.get_label() for ln in lines], loc="upper left", fontsize=8)
    ax.set_title("EPOF and GRF opacity along the look-around head path (coaster, left eye)")
    fig.tight_layout()
    with atomic_output(path) as tmp:
        fig.savefig(tmp)
    plt.close(fig)


def _plot_heatmaps(
    path: Path, est: np.ndarray, truth: np.ndarray, yaw: np.ndarray, pitch: np.ndarray, fps: float
) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    T = est.shape[0]
    frames = sorted({1, T // 3, (2 * T) // 3, T - 1})
    cols = [(f"frame {f} ({f / fps:.2f} s)", est[f], truth[f]) for f in frames]
    cols.append(("average over the clip", est[1:].mean(0), truth[1:].mean(0)))
    vmax = float(np.percentile(np.concatenate([est[1:].ravel(), truth[1:].ravel()]), 99))
    fig, axes = plt.subplots(
        2,
        len(cols),
        figsize=(3.0 * len(cols) + 1.2, 5.6),
        dpi=100,
        squeeze=False,
        layout="constrained",
    )
    dy = (yaw[1] - yaw[0]) / 2 if len(yaw) > 1 else 7.5
    dp = (pitch[1] - pitch[0]) / 2 if len(pitch) > 1 else 3.75
    extent = (yaw[0] - dy, yaw[-1] + dy, pitch[0] - dp, pitch[-1] + dp)
    im = None
    for j, (title, e, t) in enumerate(cols):
        for i, (m, label) in enumerate(((e, "estimated"), (t, "truth"))):
            ax = axes[i, j]
            im = ax.imshow(
                m, origin="lower", extent=extent, aspect="auto", cmap="magma", vmin=0, vmax=vmax
            )
            ax.set_title(f"{label}: {title}", fontsize=8)
            ax.set_xlabel("window yaw (deg)", fontsize=7)
            ax.set_ylabel("window pitch (deg)", fontsize=7)
            ax.tick_params(labelsize=6)
    fig.colorbar(im, ax=axes, shrink=0.8, label="POF (deg/s)")
    fig.suptitle("POF matrix (left eye), estimated by DIS flow vs analytic truth", fontsize=10)
    with atomic_output(path) as tmp:
        fig.savefig(tmp)
    plt.close(fig)


def _exact_epof(scene, time_s, res) -> np.ndarray:
    """The viewport's exact mean flow (deg/s) per frame of ``res``: the scene's analytic
    speed over 32 x 32 rays of the 107 deg view, solid-angle weighted (the truth)."""
    dirs, sa = perspective_rays((32, 32), 107.0, 107.0)
    d = dirs.reshape(-1, 3).astype(np.float64)
    w = sa.ravel().astype(np.float64)
    return np.array(
        [
            np.sum(
                scene.speed_dps(
                    float(time_s[k]),
                    head_rotation(res.yaw_deg[k], res.pitch_deg[k], res.roll_deg[k]).apply(d),
                    "left",
                )
                * w
            )
            / w.sum()
            for k in range(len(res.frame))
        ]
    )


#: The commands' default opacity rule (absolute, docs/epof.md), as ``vimsim epof`` and ``render``.
_RULE = rule_from_options(lambda name: None, str)


def _render(cfg: DemoConfig, source, hpath, outdir, grid, progress) -> None:
    """Render the per-eye videos with GRFs (what ``vimsim render`` runs). The demo stops at
    the first failed step (as every step before it): a failed render raises, and the
    folder keeps no completion marker."""
    view = ViewSpec(RenderConfig(eye_size=cfg.render_size, grf=GrfConfig(seed=cfg.seed)),
                    rule=_RULE)  # fmt: skip
    render_viewing(source, hpath, outdir, grid=grid, view=view, progress=progress)


def _epof_and_truth(grid, grid_def, hp, scfg, tpath, out):
    """``(EPOF result, window truth, EPOF of the truth grid, exact viewport EPOF)``; the
    EPOF CSV written to ``out/epof.csv``."""
    res = compute_epof(grid, hp, rule=_RULE)
    write_epof_csv(out / "epof.csv", res)
    tr = load_truth(tpath)
    scene = make_scene(scfg)
    truth_win = window_truth_dps(scene, grid_def, tr.time_s, "left", rays=16)
    res_truth_grid = compute_epof(replace(grid, pof_dps=truth_win.astype(np.float32)), hp)
    return res, truth_win, res_truth_grid, _exact_epof(scene, tr.time_s, res)


def _accuracy(grid, truth_win, res, res_truth_grid, exact) -> dict:
    """Relative errors of the window POFs and the EPOF against the analytic truth."""
    est = grid.pof_dps[1:].astype(np.float64)
    rel = np.abs(est - truth_win[1:]) / truth_win[1:]
    e_rel = np.abs(res.epof_dps[1:] - res_truth_grid.epof_dps[1:]) / res_truth_grid.epof_dps[1:]
    x_rel = np.abs(res.epof_dps[1:] - exact[1:]) / exact[1:]
    return {
        "window_pof_rel_error_median": float(np.median(rel)),
        "window_pof_rel_error_p90": float(np.percentile(rel, 90)),
        "epof_rel_error_vs_truth_grid_median": float(np.median(e_rel)),
        "epof_rel_error_vs_exact_viewport_median": float(np.median(x_rel)),
    }


def _summary(cfg, scfg, grid_def, grid, res, accuracy, render_error, log, t_all, files) -> dict:
    """The demo's ``summary.json``."""
    summary = {
        "what": "vimsim end-to-end demo: synthetic stereo coaster clip -> POF matrix -> EPOF/opacity -> per-eye GRF videos",
        "seed": cfg.seed,
        "clip": {
            "scene": "coaster",
            "layout": "top-bottom",
            "eye_size": list(cfg.eye_size),
            "fps": cfg.fps,
            "frames": scfg.n_frames,
            "seconds": cfg.seconds,
        },
        "grid": {
            "preset": "default",
            "windows": list(grid_def.shape),
            "window_px": cfg.window,
            "fov_deg": grid_def.hfov_deg,
            "flow": grid.meta.get("flow"),
        },
        "epof_dps": {"median": float(np.median(res.epof_dps)), "max": float(np.max(res.epof_dps))},
        "opacity_rule": _RULE.describe(),
        "opacity_thresholds_dps": [float(v) for v in res.thresholds_dps],
        "accuracy_vs_truth": accuracy,
        "render": {
            "ok": render_error is None,
            "skipped": not cfg.render,
            "error": render_error,
            "eye_size": list(cfg.render_size),
        },
        "timings_s": {name: round(dt, 2) for name, dt in log}
        | {"total": round(time.perf_counter() - t_all, 2)},
        "files": files,
    }
    return summary


def _readme(summary: dict, files: dict, output, cfg: DemoConfig, render_error) -> list[str]:
    """The lines of the demo's ``README.txt``."""
    lines = [
        "vimsim demo",
        "===========",
        "",
        "The whole pipeline on an embedded default: a synthetic stereo 360 coaster clip with",
        "known motion, a scripted look-around viewing, the POF matrix of the clip, the EPOF",
        "and GRF opacity of the viewing, and what each eye saw with the granulated rest frame.",
        f"Regenerate: vimsim demo -o {output} --seed {cfg.seed}   (deterministic given --seed)",
        "",
        "Files",
        "-----",
    ]
    lines += [f"{k}\n    {v}" for k, v in files.items()]
    acc = summary["accuracy_vs_truth"]
    lines += [
        "",
        "Accuracy against the analytic truth (this clip)",
        "-----------------------------------------------",
        f"window POF relative error: median {acc['window_pof_rel_error_median']:.3f}, 90th percentile {acc['window_pof_rel_error_p90']:.3f}",
        f"EPOF relative error vs EPOF of the truth grid: median {acc['epof_rel_error_vs_truth_grid_median']:.3f}",
        f"EPOF relative error vs exact viewport truth: median {acc['epof_rel_error_vs_exact_viewport_median']:.3f}",
        "(the latter includes the paper's window averaging; see docs/accuracy.md)",
        "",
        "Render: "
        + (
            "skipped"
            if not cfg.render
            else "ok"
            if render_error is None
            else "FAILED: " + render_error
        ),
        f"Total time: {summary['timings_s']['total']:.1f} s",
    ]
    return lines


def run_demo(
    output: str | os.PathLike = "outputs/demo",
    cfg: DemoConfig = DemoConfig(),
    *,
    progress: Progress | None = None,
    note: Callable[[str], None] | None = None,
) -> dict:
    """Run the whole pipeline into ``output``; returns the summary (also ``summary.json``).

    ``progress(done, total)`` follows each long step's frames; ``note(text)`` receives one
    line per finished step (the CLI prints them).

    Raises InputError for an unusable output folder or options sizing too much work
    (checked before the folder is touched). The demo stops at the first failed step (a
    renderer failure too, e.g. no EGL): no completion marker, the manifest incomplete.
    """

    # Every option that sizes the work is checked before the folder is touched.
    scfg = SynthConfig(
        "coaster",
        seconds=cfg.seconds,
        fps=cfg.fps,
        size=cfg.eye_size,
        layout="top-bottom",
        seed=cfg.seed,
        truth_cell_deg=4.0,
    )
    folder = OutputFolder(
        output, [k for k in _FILES if "/" not in k] + ["grid.npz.partial.npz"], "demo"
    )
    out = folder.prepare()  # refuses files we did not write; clears our previous run's
    log: list[tuple[str, float]] = []
    t_all = time.perf_counter()
    t0 = t_all
    if note is not None:
        note(f"writing to {out}")

    # 1. The clip and its truth.
    video, tpath = synthesize(scfg, out / "coaster.mp4", crf=18, progress=progress)
    t0 = _step(
        log,
        f"synth: {scfg.n_frames} frames of {cfg.eye_size[0]}x{cfg.eye_size[1]} x 2 eyes",
        t0,
        note,
    )

    # 2. Head path (covers the last frame; 60 Hz).
    hp = synth_headpath("look-around", cfg.seconds + 0.5, rate_hz=60.0, seed=cfg.seed)
    hpath = out / "headpath.csv"
    save_headpath_csv(hpath, hp)
    t0 = _step(log, "headpath: look-around", t0, note)

    # 3. Preprocess the left eye.
    grid_def = grid_preset("default", size=(cfg.window, cfg.window))
    gpath = out / "grid.npz"
    source = Source.open(video, layout="top-bottom", eye="left")
    preprocess_video(source, gpath, grid=grid_def, flow="dis", progress=progress)
    grid = load_grid(gpath)
    t0 = _step(
        log,
        f"preprocess: {grid_def.n_windows} windows of {cfg.window}x{cfg.window} px per frame",
        t0,
        note,
    )

    # 4. EPOF and opacity; the truth beside them.
    res, truth_win, res_truth_grid, exact = _epof_and_truth(grid, grid_def, hp, scfg, tpath, out)
    t0 = _step(log, "epof: EPOF, opacity and truth", t0, note)

    # 5. Render the per-eye videos with GRFs (what ``vimsim render`` runs); a failure raises.
    render_error = None  # a failed render raises (above); the summary keeps the field
    if cfg.render:
        _render(cfg, source, hpath, out / "render", grid, progress)
        t0 = _step(log, f"render: two eyes at {cfg.render_size[0]}x{cfg.render_size[1]}", t0, note)

    # 6. Plots, README, summary.
    _plot_epof(out / "epof_opacity.png", res, exact)
    _plot_heatmaps(
        out / "pof_heatmaps.png", grid.pof_dps, truth_win, grid.yaw_deg, grid.pitch_deg, grid.fps
    )
    t0 = _step(log, "plots", t0, note)

    files = {
        k: v
        for k, v in _FILES.items()
        if (out / k).exists() or k == "README.txt" or k == "summary.json"
    }
    accuracy = _accuracy(grid, truth_win, res, res_truth_grid, exact)
    summary = _summary(cfg, scfg, grid_def, grid, res, accuracy, render_error, log, t_all, files)
    lines = _readme(summary, files, output, cfg, render_error)
    with atomic_output(out / "README.txt") as tmp:
        Path(tmp).write_text("\n".join(lines) + "\n")
    folder.complete()  # the manifest, then the completion marker
    with atomic_output(out / "summary.json") as tmp:
        Path(tmp).write_text(json_text(summary) + "\n")
    return summary
