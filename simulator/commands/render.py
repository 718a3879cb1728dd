"""``vimsim render``: per-eye videos of what the viewer saw, with the GRF overlay.

Parses the options; the work is :func:`simulator.viewing.job.render_viewing`.
"""

from __future__ import annotations

import argparse

from simulator.commands._opacity import add_opacity_arguments, add_preset_argument
from simulator.commands._types import (
    add_fov_arguments,
    nonneg_deg,
    nonneg_int,
    positive_float,
    size_wxh,
    x264_crf,
)
from simulator.core.choices import (
    EPOF_METHODS,
    LAYOUTS,
    MITIGATION_HELP,
    MITIGATIONS,
    X264_PRESETS,
)

__all__ = ["add_view_options", "register", "run", "view_from_args"]


def _opacity(text: str) -> float | str:
    if text == "auto":
        return text
    try:
        v = float(text)
    except ValueError:
        if text.lower().endswith(".csv"):
            return text  # an EPOF CSV: its opacity column
        raise argparse.ArgumentTypeError(
            f"expected auto, a number in [0, 1] (e.g. 0.5) or an EPOF CSV; got {text!r}"
        ) from None
    if not (0.0 <= v <= 1.0):
        raise argparse.ArgumentTypeError(
            f"expected auto or a number in [0, 1], e.g. 0.5; got {text!r}"
        )
    return v


def add_view_options(p: argparse.ArgumentParser) -> None:
    """The options that say what an eye sees (grid, eye size, FOV, GRF, layout, hold):
    shared by ``render`` and ``frames``; :func:`view_from_args` reads them."""
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
        "--mitigation",
        choices=MITIGATIONS,
        help="what is drawn over the video: "
        + ", ".join(f"{k} ({h})" for k, h in MITIGATION_HELP.items()),
    )
    p.add_argument(
        "--aperture-min",
        type=positive_float,
        default=60.0,
        metavar="DEG",
        help="vignette aperture diameter at opacity 1, degrees of visual field, in (0, FOV) "
        "(default 60); at opacity 0 the aperture is the full view",
    )
    p.add_argument(
        "--feather",
        type=nonneg_deg,
        default=10.0,
        metavar="DEG",
        help="width of the vignette's soft edge, degrees, linear in angle (default 10; 0 = hard)",
    )
    p.add_argument(
        "--vignette-color",
        default="0,0,0",
        metavar="R,G,B",
        help="vignette colour, R,G,B 0..255 or #RRGGBB (default black)",
    )
    p.add_argument(
        "--opacity",
        type=_opacity,
        default="auto",
        metavar="auto|0..1|EPOF.csv",
        help="GRF opacity: auto = from the EPOF (needs --grid; rule: the options below), a "
        "constant in [0, 1], or the opacity column of an EPOF CSV (vimsim epof) of VIDEO",
    )
    p.add_argument(
        "--method",
        choices=EPOF_METHODS,
        default="auto",
        help="EPOF method, as vimsim epof (auto: sphere when the grid has a field)",
    )
    add_opacity_arguments(p)
    add_preset_argument(p)
    p.add_argument(
        "--layout",
        choices=LAYOUTS,
        default=None,
        help="stereo layout of VIDEO: top-bottom = left eye on top, side-by-side = left eye on "
        "the left, mono: both eyes see the same frame (default: the grid's layout, from its "
        "meta, else mono)",
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


def view_from_args(args: argparse.Namespace, command: str = "render"):
    """``(headpath, grid, view, note, layout)`` from :func:`add_view_options`' options:
    the :class:`simulator.viewing.spec.ViewSpec` (the one builder of what the eye sees,
    shared with studies), the inputs, and the stereo layout (the grid's when not given)."""
    from simulator.commands._progress import warnings_to_stderr
    from simulator.commands.headpath import load_headpath_args
    from simulator.media.gridfile import load_grid
    from simulator.viewing.spec import ViewSpec

    # frames writes PNGs: any size the GL limits allow; render encodes H.264
    view = ViewSpec.from_options(args, video=command == "render")
    hp = load_headpath_args(args, args.headpath, f"vimsim {command}")  # --columns too
    with warnings_to_stderr(f"vimsim {command}"):
        grid = load_grid(args.grid) if args.grid else None
    meta_layout = grid.meta.get("layout") if grid is not None else None
    layout = args.layout or (meta_layout if meta_layout in LAYOUTS else None) or "mono"
    note = None
    if args.mitigation is None and args.grf is None and view.grains is None:
        note = "GRF off: no --grid and no --opacity given (give --grid GRID.npz or --opacity 0..1 to overlay it)"
    if args.layout is None and layout != "mono":
        note = (note + "; " if note else "") + f"layout {layout}, from the grid's meta"
    return hp, grid, view, note, layout


def check_trace_span(args: argparse.Namespace, hp, source) -> list[str]:
    """The head path's span checked against the source video's duration (a still: not),
    as every command where a trace meets a video (:func:`simulator.traces.clock.check_span`);
    returns the span warnings, which the command prints once its work is done."""
    import os

    from simulator.commands.headpath import trace_options
    from simulator.traces.clock import check_span

    info = source.info
    if not info.is_video:
        return []
    return check_span(hp, info.n_frames / info.fps, trace_options(args),
                      video=os.path.basename(source.path), warn=False)  # fmt: skip


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``render`` parser."""
    from simulator.commands._source import add_source_arguments
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
    add_view_options(p)
    p.add_argument(
        "--start",
        type=float,
        default=None,
        metavar="S",
        help="render only from S seconds of video time (head path and grid stay in video time)",
    )
    p.add_argument(
        "--end",
        type=float,
        default=None,
        metavar="S",
        help="render only frames before S seconds of video time (default: the video's end)",
    )
    p.add_argument(
        "--x264-preset",
        choices=X264_PRESETS,
        default="veryfast",
        help="x264 speed preset of the eye videos (default veryfast; --preset is the system's)",
    )
    p.add_argument(
        "--crf",
        type=x264_crf,
        default=18,
        metavar="N",
        help="x264 quality 0..51, lower = better (default 18)",
    )
    p.add_argument(
        "--eyes",
        choices=("left", "right", "both"),
        default=None,
        help="eye files to write (default: left for a mono video, whose two eyes are the "
        "same image; both for a stereo one)",
    )
    p.add_argument(
        "--review",
        action="store_true",
        help="also write OUTDIR/review.mp4 (equirect frame with the viewport's outline beside "
        "the eye view, EPOF and opacity strip with a cursor) and OUTDIR/sheet.png (contact sheet)",
    )
    add_source_arguments(p, still=True)
    p.add_argument(
        "--right",
        metavar="FILE",
        default=None,
        help="the right eye's equirect video: VIDEO (left eye) and FILE are a stereo source of "
        "two per-eye files (same size, frame rate and frame count)",
    )
    p.add_argument(
        "--no-audio",
        action="store_true",
        help="silent outputs (default: the source's audio, the range's part, is copied into "
        "every output video)",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    add_reader_options(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Parse the options and run :func:`simulator.viewing.job.render_viewing`; InputError -> exit 2."""
    from simulator.commands._progress import progress_bar, warnings_to_stderr
    from simulator.commands._source import source_from_args
    from simulator.viewing.job import render_viewing

    hp, grid, view, note, layout = view_from_args(args)
    source = source_from_args(
        args, args.video_file, layout=args.layout, layout_default=layout, right=args.right
    )
    notes = check_trace_span(args, hp, source)
    with (
        warnings_to_stderr("vimsim render"),
        progress_bar("render", enabled=not args.no_progress) as bar,
    ):
        s = render_viewing(
            source,
            hp,
            args.output,
            grid=grid,
            view=view,
            x264_preset=args.x264_preset,
            crf=args.crf,
            progress=bar,
            note=note,
            start_s=args.start,
            end_s=args.end,
            review=args.review,
            eyes=args.eyes,
            audio=not args.no_audio,
        )
    from simulator.commands.headpath import print_warnings

    print_warnings("vimsim render", notes)
    w, h = s["eye_size"]
    files = {"left": ["left.mp4"], "right": ["right.mp4"], "both": ["left.mp4", "right.mp4"]}
    names = files[s["eyes"]] + (s["review"] or [])
    a = s["audio"]
    sound = f"audio {a['codec']} {a['mode']}" if a["copied"] else f"silent: {a['why']}"
    print(
        f"vimsim render: {s['frames_written']} frames, eye {w}x{h} -> {s['outdir']}/"
        f"{', '.join(names)}, epof.csv, summary.json ({s['frames_per_s']:.2f} frames/s; {sound})"
    )  # the result line: stdout
    return 0
