"""``vimsim frames``: the eye views at chosen moments as lossless PNGs plus frames.json (visual regression tests).

Parses the options (those of ``render``); the work is :func:`simulator.viewing.frames.render_frames`.
"""

from __future__ import annotations

import argparse
import sys

__all__ = ["register", "run"]


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``frames`` parser."""
    from simulator.commands._source import add_source_arguments
    from simulator.commands.headpath import add_reader_options
    from simulator.commands.render import add_view_options

    p = subparsers.add_parser(
        "frames",
        help="eye views at chosen video times as lossless PNGs + frames.json (as render draws them)",
        description="Render, with the GL renderer exactly as vimsim render does, the eye views "
        "at chosen video times (the frame on screen at time T is floor(T * fps)) to lossless "
        "PNGs named by time and eye (tSSSS.mmm_left.png / _right.png for stereo, _both.png "
        "when both eyes see the same image) and DIR/frames.json (time, frame, pose, EPOF, "
        "opacity, renderer settings, versions), written last. The same inputs give "
        "byte-identical PNGs on the same machine; compare them with vimsim compare. Angles "
        "in degrees: positive yaw turns right, positive pitch looks up.",
    )
    p.add_argument("video_file", metavar="VIDEO", help="equirectangular video (mono or stereo)")
    p.add_argument("headpath", metavar="PATH.csv", help="head path (as vimsim render)")
    p.add_argument("-o", "--output", metavar="DIR", required=True, help="output folder (created)")
    when = p.add_mutually_exclusive_group(required=True)
    when.add_argument(
        "--at", metavar="T1,T2,...", help="video times in seconds, e.g. 1,2.5,10 (1 ms precision)"
    )
    when.add_argument(
        "--every", type=float, metavar="S", help="every S seconds from 0 to the end of the video"
    )
    add_view_options(p)
    add_source_arguments(p, still=True)
    p.add_argument(
        "--right",
        metavar="FILE",
        default=None,
        help="the right eye's equirect video or image: VIDEO (left eye) and FILE are a stereo "
        "source of two per-eye files (same size, frame rate and frame count)",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    add_reader_options(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run :func:`simulator.viewing.frames.render_frames`; InputError -> exit 2."""
    from simulator.commands._progress import progress_bar, warnings_to_stderr
    from simulator.commands._source import source_from_args
    from simulator.commands.headpath import print_warnings
    from simulator.commands.render import check_trace_span, view_from_args
    from simulator.viewing.frames import render_frames

    hp, grid, view, note, layout = view_from_args(args, "frames")
    source = source_from_args(
        args, args.video_file, layout=args.layout, layout_default=layout, right=args.right
    )
    notes = check_trace_span(args, hp, source)
    with (
        warnings_to_stderr("vimsim frames"),
        progress_bar("frames", enabled=not args.no_progress) as bar,
    ):
        index = render_frames(
            source,
            hp,
            args.output,
            at=args.at,
            every=args.every,
            grid=grid,
            view=view,
            progress=bar,
        )
    if note:
        print(f"vimsim frames: note: {note}", file=sys.stderr)
    print_warnings("vimsim frames", notes)
    n = len({f["time_s"] for f in index["frames"]})
    print(
        f"vimsim frames: {len(index['frames'])} PNGs ({n} moments) -> {args.output}/"
    )  # the result line: stdout
    return 0
