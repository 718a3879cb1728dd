"""``vimsim grid import DIR -o GRID.npz --fps F``: a folder of the authors' per-window CSVs as a grid file."""

from __future__ import annotations

import argparse
import sys

from simulator.commands._types import add_fov_arguments, fov_from_args, positive_float

__all__ = ["register", "run"]


def _size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected WxH pixels, e.g. 1600x1440; got {text!r}"
        ) from None
    if not (16 <= w <= 8192 and 16 <= h <= 8192):
        raise argparse.ArgumentTypeError(f"window size must be 16..8192 px a side; got {text!r}")
    return w, h


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``grid`` parser and its ``import`` action."""
    p = subparsers.add_parser(
        "grid",
        help="grid files from other tools (import the authors' per-window CSVs)",
        description="Grid files from other tools. See docs/parity.md.",
    )
    sub = p.add_subparsers(dest="grid_command", metavar="ACTION", parser_class=type(p))
    p.set_defaults(func=lambda args: (p.print_help(sys.stderr), 2)[1])
    i = sub.add_parser(
        "import",
        help="a folder of horizontal_<yaw>_vertical_<pitch>.csv files -> GRID.npz",
        description="Read a folder in the layout of the authors' Unity project (one CSV per "
        "window, horizontal_<yaw>_vertical_<pitch>.csv: a header line ',0', then frame,value "
        "rows from frame 0 in window px/frame; optional percentileData.csv) into a paper-mode "
        "grid file that vimsim's commands accept. The window grid is the one the file names "
        "declare (centres in degrees, yaw + right, pitch + up). pof_px holds the values; "
        "pof_dps converts them at the window's centre pixel pitch (value x hfov / width x fps).",
    )
    i.add_argument("folder", metavar="DIR", help="folder of window CSVs")
    i.add_argument("-o", "--output", required=True, metavar="GRID.npz", help="grid file to write")
    i.add_argument("--fps", type=positive_float, required=True, metavar="F",
                   help="frame rate of the video the CSVs were made from")  # fmt: skip
    add_fov_arguments(i, what="window", default="107 x 96.3, the cao2021 grid's", headset=False)
    i.add_argument("--window-size", type=_size, default=None, metavar="WxH",
                   help="window size in pixels (default 1600x1440, the cao2021 grid's)")  # fmt: skip
    i.set_defaults(func=run, grid_command="import")


def run(args: argparse.Namespace) -> int:
    """Import; InputError -> exit 2 with nothing written."""
    from pathlib import Path

    from simulator.core.fileio import check_not_input
    from simulator.export.caocsv import import_cao_csv

    folder = Path(args.folder)
    if folder.is_dir():
        check_not_input(args.output, [f for f in folder.iterdir() if f.is_file()])
    hfov, vfov = fov_from_args(args, (None, None))
    g = import_cao_csv(args.folder, args.output, fps=args.fps, hfov_deg=hfov, vfov_deg=vfov,
                       size=args.window_size)  # fmt: skip
    P, Y = g.pitch_deg.size, g.yaw_deg.size
    print(
        f"wrote {args.output}: {g.n_frames} frames x {P} x {Y} windows (pitch "
        f"{g.pitch_deg[0]:g}..{g.pitch_deg[-1]:g}, yaw {g.yaw_deg[0]:g}..{g.yaw_deg[-1]:g} deg), "
        f"{g.hfov_deg:g} x {g.vfov_deg:g} deg at {g.grid.size[0]}x{g.grid.size[1]} px, {g.fps:g} fps"
    )
    return 0
