"""``vimsim render``: per-eye videos of what the viewer saw, with the GRF overlay.

Parses the options; the work is :func:`simulator.render.render_viewing`.
"""

from __future__ import annotations

import argparse
import sys

from simulator.choices import LAYOUTS, X264_PRESETS
from simulator.commands._types import add_fov_arguments, crf, fov_from_args, nonneg_int, size_wxh

__all__ = ["register", "run"]

#: H.264 level 6.2's largest frame in 16x16 macroblocks (8192x4320 and the like).
MAX_H264_MACROBLOCKS = 139264
#: Estimated bytes per eye pixel while rendering (framebuffers, read-back, encoder frames).
BYTES_PER_EYE_PIXEL = 48
#: Grains the mask pass takes, and their estimated bytes each (directions, buckets).
MAX_GRAINS = 5_000_000
BYTES_PER_GRAIN = 64


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
    from simulator.commands.headpath import add_reader_options

    p = subparsers.add_parser(
        "render",
        help="per-eye H.264 videos of what the viewer saw, with the GRF overlay (headless EGL)",
        description="Render what each eye saw along a head path (OpenGL over EGL, no display "
        "needed) and composite the granulated rest frame (GRF: world-fixed black grains of "
        "1.5 deg covering 50% of the view, transparent within 18 deg of the view centre, "
        "opaque beyond 40 deg) at the EPOF-driven opacity. Writes OUTDIR/left.mp4, "
        "OUTDIR/right.mp4 (H.264, the video's frame rate, one frame per video frame), "
        "OUTDIR/epof.csv and, last, OUTDIR/summary.json (the run is complete when it exists). "
        "Angles in degrees: positive yaw turns "
        "right, positive pitch looks up, positive roll tilts the head right ear down.",
    )
    # dest video_file: --video (add_reader_options) names the trace of an AVTrack360 file
    p.add_argument("video_file", metavar="VIDEO", help="equirectangular video (mono or stereo)")
    p.add_argument(
        "headpath",
        metavar="PATH.csv",
        help="head path (time_s,yaw_deg,pitch_deg,roll_deg or another format vimsim headpath "
        "reads; --format, --video, --user below choose the format and the trace)",
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
        choices=LAYOUTS,
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
        "--preset", choices=X264_PRESETS, default="veryfast", help="x264 preset (default veryfast)"
    )
    p.add_argument(
        "--crf",
        type=crf,
        default=18,
        metavar="N",
        help="x264 quality, lower = better (default 18)",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    add_reader_options(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Parse the options and run :func:`simulator.render.render_viewing`; InputError -> exit 2."""
    from simulator.commands._progress import progress_bar, warnings_to_stderr
    from simulator.errors import InputError
    from simulator.grf import GrfConfig, grain_count
    from simulator.gridfile import load_grid
    from simulator.readers import load_headpath
    from simulator.render import RenderConfig
    from simulator.resources import check_fits
    from simulator.viewing import render_viewing

    hfov, vfov = fov_from_args(args, (107.0, 107.0))
    w, h = args.eye_size
    if w % 2 or h % 2:
        raise InputError(f"--eye-size {w}x{h}: H.264 needs even numbers, e.g. 480x480")
    if -(-w // 16) * -(-h // 16) > MAX_H264_MACROBLOCKS or max(w, h) > 8192:
        raise InputError(
            f"--eye-size {w}x{h}: beyond H.264's largest frame (level 6.2: 8192x4320); "
            "e.g. 2048x2048"
        )
    check_fits(2 * w * h * BYTES_PER_EYE_PIXEL, f"--eye-size {w}x{h}")
    if not (0.0 < args.grain_size < 90.0):
        raise InputError(f"--grain-size must be degrees in (0, 90); got {args.grain_size}")
    if not (0.0 < args.density < 1.0):
        raise InputError(f"--density must be in (0, 1); got {args.density}")
    with warnings_to_stderr("vimsim render"):
        hp = load_headpath(args.headpath, args.format, video=args.video, user=args.user)
        grid = load_grid(args.grid) if args.grid else None

    # GRF on/off: on with --grid or a numeric --opacity unless --grf says otherwise.
    grf_on = args.grf == "on" or (args.grf is None and (grid is not None or args.opacity != "auto"))
    note = None
    if args.grf is None and not grf_on:
        note = "GRF off: no --grid and no --opacity given (give --grid GRID.npz or --opacity 0..1 to overlay it)"
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
        n = grain_count(grf)
        if n > MAX_GRAINS:
            raise InputError(
                f"--grain-size {args.grain_size:g} with --density {args.density:g} needs {n} "
                f"grains (at most {MAX_GRAINS}); choose a larger --grain-size, e.g. 0.5"
            )
        check_fits(n * BYTES_PER_GRAIN, f"--grain-size {args.grain_size:g}")
    config = RenderConfig(eye_size=args.eye_size, hfov_deg=hfov, vfov_deg=vfov, grf=grf)
    with (
        warnings_to_stderr("vimsim render"),
        progress_bar("render", enabled=not args.no_progress) as bar,
    ):
        s = render_viewing(
            args.video_file,
            hp,
            args.output,
            grid=grid,
            config=config,
            opacity=args.opacity,
            layout=args.layout,
            hold=args.hold_last,
            preset=args.preset,
            crf=args.crf,
            progress=bar,
            note=note,
        )
    w, h = s["eye_size"]
    print(
        f"vimsim render: {s['frames_written']} frames x 2 eyes {w}x{h} -> {s['outdir']}/left.mp4, "
        f"right.mp4 ({s['frames_per_s']:.2f} frames/s)",
        file=sys.stderr,
    )
    return 0
