"""``vimsim render``: per-eye videos of what the viewer saw, with the GRF overlay."""

from __future__ import annotations

import argparse
import sys

from simulator.commands._types import add_fov_arguments, fov_from_args, nonneg_int, size_wxh

__all__ = ["register", "run"]

_LAYOUTS = ("mono", "top-bottom", "side-by-side")  # = simulator.geometry.LAYOUTS (light import)
_PRESETS = ("ultrafast", "superfast", "veryfast", "faster", "fast", "medium", "slow")


def _opacity(text: str) -> float | str:
    if text == "auto":
        return text
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected auto or a number in [0, 1], e.g. 0.5; got {text!r}"
        ) from None
    if not (0.0 <= v <= 1.0):
        raise argparse.ArgumentTypeError(
            f"expected auto or a number in [0, 1], e.g. 0.5; got {text!r}"
        )
    return v


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``render`` parser."""
    p = subparsers.add_parser(
        "render",
        help="per-eye H.264 videos of what the viewer saw, with the GRF overlay (headless EGL)",
        description="Render what each eye saw along a head path (OpenGL over EGL, no display "
        "needed) and composite the granulated rest frame (GRF: world-fixed black grains of "
        "1.5 deg covering 50%% of the view, transparent within 18 deg of the view centre, "
        "opaque beyond 40 deg) at the EPOF-driven opacity. Writes OUTDIR/left.mp4, "
        "OUTDIR/right.mp4 (H.264, the video's frame rate, one frame per video frame), "
        "OUTDIR/epof.csv and OUTDIR/summary.json. Angles in degrees: positive yaw turns "
        "right, positive pitch looks up, positive roll tilts the head right ear down.",
    )
    p.add_argument("video", metavar="VIDEO", help="equirectangular video (mono or stereo)")
    p.add_argument(
        "headpath",
        metavar="PATH.csv",
        help="head path (time_s,yaw_deg,pitch_deg,roll_deg or another format vimsim headpath reads)",
    )
    p.add_argument(
        "-o", "--output", metavar="OUTDIR", required=True, help="output folder (created)"
    )
    p.add_argument(
        "--grid",
        metavar="GRID.npz",
        help="grid file of VIDEO (vimsim preprocess): GRF opacity follows the EPOF",
    )
    p.add_argument(
        "--eye-size",
        type=size_wxh,
        default=(1440, 1440),
        metavar="WxH",
        help="pixels per eye, even numbers (default 1440x1440, e.g. 480x480 for previews)",
    )
    add_fov_arguments(p, what="eye", default="107")
    p.add_argument(
        "--grf",
        choices=("on", "off"),
        help="GRF overlay (default: on with --grid or a numeric --opacity, off otherwise)",
    )
    p.add_argument(
        "--opacity",
        type=_opacity,
        default="auto",
        metavar="auto|0..1",
        help="GRF opacity: auto = from the EPOF (needs --grid), or a constant in [0, 1]",
    )
    p.add_argument(
        "--layout",
        choices=_LAYOUTS,
        default="mono",
        help="stereo layout of VIDEO: top-bottom = left eye on top, side-by-side = left eye on the left (default mono: both eyes see the same frame)",
    )
    p.add_argument(
        "--seed",
        type=nonneg_int,
        default=0,
        metavar="N",
        help="seed of the grain layout (default 0)",
    )
    p.add_argument(
        "--grain-size",
        type=float,
        default=1.5,
        metavar="DEG",
        help="grain diameter, degrees (default 1.5)",
    )
    p.add_argument(
        "--density",
        type=float,
        default=0.5,
        metavar="F",
        help="blocked fraction of the view, 0..1 exclusive (default 0.5)",
    )
    p.add_argument(
        "--cutout",
        type=float,
        nargs=2,
        default=(18.0, 40.0),
        metavar=("INNER", "OUTER"),
        help="cutout radii from the view centre, degrees: transparent within INNER, opaque beyond OUTER (default 18 40)",
    )
    p.add_argument(
        "--grain-distance",
        type=float,
        metavar="M",
        help="grain distance, metres, for stereo parallax (default: at infinity, identical for both eyes)",
    )
    p.add_argument(
        "--hold-last",
        action="store_true",
        help="hold the head path's first/last pose where it does not cover the video",
    )
    p.add_argument(
        "--preset", choices=_PRESETS, default="veryfast", help="x264 preset (default veryfast)"
    )
    p.add_argument(
        "--crf",
        type=nonneg_int,
        default=18,
        metavar="N",
        help="x264 quality, lower = better (default 18)",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import json
    import time
    from pathlib import Path

    import numpy as np

    from simulator.errors import InputError
    from simulator.fileio import atomic_output, check_output_dir
    from simulator.grf import GrfConfig, grain_count
    from simulator.headpath import load_headpath
    from simulator.render import RenderConfig, create_context, render_video
    from simulator.video import probe

    t0 = time.perf_counter()
    hfov, vfov = fov_from_args(args, (107.0, 107.0))
    w, h = args.eye_size
    if w % 2 or h % 2:
        raise InputError(
            f"--eye-size must be even for H.264 (yuv420p); got {w}x{h}, e.g. {w + w % 2}x{h + h % 2}"
        )

    info = probe(args.video)
    info.eye_size(args.layout)  # 2:1 per eye (or squeezed stereo), else InputError
    if not info.is_video:
        raise InputError(
            f"{args.video}: a still image; render needs a video (vimsim viewport renders images)"
        )
    hp = load_headpath(args.headpath)
    duration = (info.n_frames - 1) / info.fps  # time of the last frame
    hp.check_covers(duration, hold=args.hold_last, video=args.video)
    times = np.arange(info.n_frames) / info.fps

    grid = None
    if args.grid:
        from simulator.gridfile import load_grid

        grid = load_grid(args.grid)
        grid.check_video(info, source=args.grid)

    # GRF on/off and opacity source.
    grf_on = args.grf == "on" or (args.grf is None and (grid is not None or args.opacity != "auto"))
    note = None
    if args.grf is None and not grf_on:
        note = "GRF off: no --grid and no --opacity given (give --grid GRID.npz or --opacity 0..1 to overlay it)"
    if grf_on and args.opacity == "auto" and grid is None:
        raise InputError(
            "--opacity auto follows the EPOF and needs --grid GRID.npz; or give --opacity 0..1"
        )
    grf = None
    if grf_on:
        grf = GrfConfig(
            grain_deg=args.grain_size,
            density=args.density,
            inner_deg=args.cutout[0],
            outer_deg=args.cutout[1],
            seed=args.seed,
            distance_m=args.grain_distance,
        )

    # Per-frame head angles and opacity (EPOF rows when a grid is given).
    epof_dps = np.full(info.n_frames, np.nan)
    thresholds = (float("nan"), float("nan"))
    if grid is not None:
        from simulator.epof import compute_epof

        res = compute_epof(grid, hp, hfov_deg=hfov, vfov_deg=vfov, hold=args.hold_last)
        yaw, pitch, roll = hp.sample_angles_deg(times, hold=args.hold_last)
        n = min(len(res.epof_dps), info.n_frames)
        epof_dps[:n] = res.epof_dps[:n]
        epof_dps[n:] = res.epof_dps[-1]
        op_auto = np.empty(info.n_frames)
        op_auto[:n] = res.opacity[:n]
        op_auto[n:] = res.opacity[-1]
        thresholds = tuple(float(v) for v in res.thresholds_dps)
    else:
        yaw, pitch, roll = hp.sample_angles_deg(times, hold=args.hold_last)
        op_auto = None
    if not grf_on:
        opacity = np.zeros(info.n_frames)
    elif args.opacity == "auto":
        opacity = op_auto
    else:
        opacity = np.full(info.n_frames, float(args.opacity))

    out = check_output_dir(args.output)
    if note:
        print(f"vimsim render: note: {note}", file=sys.stderr)
    ctx = create_context()
    config = RenderConfig(eye_size=(w, h), hfov_deg=hfov, vfov_deg=vfov, grf=grf)
    t_setup = time.perf_counter() - t0
    result = render_video(
        ctx,
        args.video,
        (str(out / "left.mp4"), str(out / "right.mp4")),
        np.stack([yaw, pitch, roll], axis=-1),
        opacity=opacity,
        config=config,
        layout=args.layout,
        fps=info.fps,
        n_frames=info.n_frames,
        preset=args.preset,
        crf=args.crf,
        progress=not args.no_progress,
    )

    # epof.csv: one row per video frame.
    from simulator.epof import EpofResult, write_epof_csv

    nf = info.n_frames
    write_epof_csv(
        out / "epof.csv",
        EpofResult(np.arange(nf), times, yaw, pitch, roll, epof_dps, opacity, thresholds),
    )

    def pct(a):
        a = np.asarray(a, float)
        a = a[np.isfinite(a)]
        return {f"p{q}": float(np.percentile(a, q)) for q in (10, 50, 90)} if a.size else None

    timings = dict(result.timings_s, setup=t_setup, total_with_setup=time.perf_counter() - t0)
    summary = {
        "video": str(args.video),
        "headpath": str(args.headpath),
        "grid": args.grid,
        "layout": args.layout,
        "fps": info.fps,
        "frames_video": info.n_frames,
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
        "opacity": args.opacity if grf_on else "off",
        "opacity_thresholds_dps": list(thresholds),
        "epof_dps_percentiles": pct(epof_dps),
        "opacity_percentiles": pct(opacity),
        "x264": {"preset": args.preset, "crf": args.crf},
        "timings_s": timings,
        "frames_per_s": result.frames_per_s,
        "renderer": ctx.info.get("GL_RENDERER"),
    }
    if note:
        summary["note"] = note
    with atomic_output(out / "summary.json") as tmp:
        Path(tmp).write_text(json.dumps(summary, indent=2, default=str) + "\n")
    print(
        f"vimsim render: {result.n_frames} frames x 2 eyes {w}x{h} -> {out}/left.mp4, right.mp4 "
        f"({result.frames_per_s:.2f} frames/s)",
        file=sys.stderr,
    )
    return 0
