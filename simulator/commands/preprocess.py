"""``vimsim preprocess``: a video's sliding-window optical-flow matrix (the grid file)."""

from __future__ import annotations

import argparse
import sys

from simulator.commands._source import add_source_arguments, source_from_args
from simulator.commands._types import add_fov_arguments, fov_from_args, positive_float, seconds
from simulator.core.choices import EYES, GRID_PRESET_NAMES, LAYOUTS, PREPROCESS_METHODS
from simulator.flow.registry import flow_help

__all__ = ["register", "run"]


def _window_size(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"window size must be pixels, e.g. 256; got {text!r}"
        ) from None
    if not (16 <= v <= 2048):
        raise argparse.ArgumentTypeError(
            f"window size must be 16..2048 pixels, e.g. 256; got {text!r}"
        )
    return v


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``preprocess`` parser."""
    p = subparsers.add_parser(
        "preprocess",
        help="per-window optical flow of a video (the paper's POF matrix) -> GRID.npz",
        description="Extract every window of the sliding-window grid (default 24 x 11 windows, "
        "15 deg yaw x 7.5 deg pitch steps, 107 deg FOV, 256x256 px) from each frame, compute the "
        "optical flow between consecutive frames inside each window and write pof_dps (deg/s of "
        "visual angle) and pof_px (window px/frame) per frame and window. Long runs save a "
        "checkpoint beside the output (GRID.npz.partial.npz) every minute and on Ctrl-C; "
        "--resume continues it. See docs/preprocess.md.",
    )
    p.add_argument(
        "video", metavar="VIDEO", help="equirectangular video (2:1 per eye), any FFmpeg format"
    )
    p.add_argument("-o", "--output", metavar="GRID.npz", required=True, help="grid file to write")
    p.add_argument(
        "--grid",
        choices=GRID_PRESET_NAMES,
        default="default",
        help="window grid: default (15 deg yaw steps, 264 windows), paper-198 (20 deg, 198) or "
        "cao2021 (the authors' code: 15 x 15 deg steps with the poles, 312 windows of 1600 x "
        "1440 px, 107 deg wide with the linear vertical FOV 96.3 deg; docs/parity.md)",
    )
    add_fov_arguments(p, what="window", default="107; cao2021: 107 x 96.3")
    p.add_argument(
        "--window-size",
        type=_window_size,
        default=None,
        metavar="N",
        help="window size N x N pixels (default 256; cao2021: 1600 x 1440)",
    )
    p.add_argument(
        "--flow",
        default="dis",
        metavar="METHOD",
        help=flow_help(),
    )
    p.add_argument(
        "--layout",
        choices=LAYOUTS,
        default=None,
        help="stereo layout: mono, top-bottom (left eye on top), side-by-side (left eye left) "
        "(default: the file's spherical metadata, else mono)",
    )
    p.add_argument(
        "--eye",
        choices=EYES,
        default="left",
        help="eye of a stereo video (default left)",
    )
    add_source_arguments(p)
    p.add_argument(
        "--start",
        type=seconds,
        default=0.0,
        metavar="S",
        help="first frame at S seconds (default 0)",
    )
    p.add_argument(
        "--end",
        type=seconds,
        default=None,
        metavar="S",
        help="stop before S seconds (default: the end)",
    )
    p.add_argument(
        "--method",
        choices=PREPROCESS_METHODS,
        default="sphere",
        help="sphere (default): flow once per frame on 6 cube tiles, stored as an "
        "angular-speed field on lon/lat cells (field_dps) from which the window matrix of "
        "--grid/--fov is derived; epof/render then integrate the field over any viewport FOV; "
        "real time, no checkpoints (docs/sphere.md). paper: the paper's method, flow per "
        "window (slower; resumable with --resume)",
    )
    p.add_argument(
        "--cell",
        type=positive_float,
        default=4.0,
        metavar="D",
        help="sphere mode: field cell size in degrees, dividing 180 (default 4)",
    )
    p.add_argument(
        "--artefacts",
        action="store_true",
        help="sphere mode: also detect codec keyframes, cuts, fades and overlays appearing in "
        "the same decoding pass and store them in the grid (epof --artefacts, screen use them)",
    )
    p.add_argument(
        "--resume",
        action="store_true",
        help="continue an interrupted run from GRID.npz.partial.npz (same video and options)",
    )
    p.add_argument(
        "--checkpoint-every",
        type=positive_float,
        default=60.0,
        metavar="S",
        help="seconds between checkpoints (default 60)",
    )
    p.add_argument(
        "--threads",
        type=int,
        default=None,
        metavar="N",
        help="flow worker threads (default: CPU count)",
    )
    p.add_argument(
        "--no-cache",
        action="store_true",
        help="build the window maps without reading or writing the map cache "
        "($VIMSIM_CACHE_DIR, else $XDG_CACHE_HOME/vimsim or ~/.cache/vimsim; docs/paper_speed.md)",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Preprocess; 0 when the grid file was written, 2 on bad input, 130 when interrupted."""
    from simulator.commands._progress import progress_bar, warnings_to_stderr
    from simulator.core.errors import InputError
    from simulator.preprocess import PreprocessInterrupted, preprocess_video
    from simulator.sphere.windows import grid_preset

    hfov, vfov = fov_from_args(args, (None, None))  # None: the preset's window
    size = None if args.window_size is None else (args.window_size, args.window_size)
    grid = grid_preset(args.grid, hfov_deg=hfov, vfov_deg=vfov, size=size)
    if args.threads is not None and args.threads < 1:
        raise InputError(f"--threads must be >= 1; got {args.threads}")
    if args.artefacts and args.method != "sphere":
        raise InputError("--artefacts needs --method sphere (detected in its decoding pass)")
    if args.method == "sphere":
        from simulator.preprocess import SphereConfig, preprocess_sphere

        if args.resume:
            raise InputError(
                "--resume is for --method paper; sphere mode runs in real time and keeps no checkpoint"
            )
        with (
            warnings_to_stderr("vimsim preprocess"),
            progress_bar("preprocess (sphere)", enabled=not args.no_progress) as bar,
        ):
            out = preprocess_sphere(
                source_from_args(args, args.video, layout=args.layout, eye=args.eye),
                args.output,
                grid=grid,
                config=SphereConfig(cell_deg=args.cell),
                flow=args.flow,
                start_s=args.start,
                end_s=args.end,
                progress=bar,
                artefacts=args.artefacts,
            )
        print(f"wrote {out}")
        return 0
    try:
        with (
            warnings_to_stderr("vimsim preprocess"),
            progress_bar("preprocess", enabled=not args.no_progress) as bar,
        ):
            out = preprocess_video(
                source_from_args(args, args.video, layout=args.layout, eye=args.eye),
                args.output,
                grid=grid,
                flow=args.flow,
                start_s=args.start,
                end_s=args.end,
                resume=args.resume,
                checkpoint_every_s=args.checkpoint_every,
                threads=args.threads,
                cache=not args.no_cache,
                progress=bar,
            )
    except PreprocessInterrupted as e:
        from simulator.commands._signals import exit_status

        print(f"vimsim preprocess: {e.message}", file=sys.stderr)
        return exit_status()
    print(f"wrote {out}")
    return 0
