"""``vimsim ego VIDEO -o EGO.csv``: the camera's rotation per frame (deg/s, yaw/pitch/roll rates) of a video or a sphere-mode grid."""

from __future__ import annotations

import argparse

from simulator.commands._source import add_source_arguments
from simulator.commands._types import positive_float, seconds
from simulator.core.choices import EYES, LAYOUTS
from simulator.flow.registry import flow_help

__all__ = ["register", "run"]


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``ego`` parser."""
    p = subparsers.add_parser(
        "ego",
        help="the camera's angular velocity per frame (deg/s, yaw/pitch/roll rates) -> EGO.csv",
        description="Estimate the camera's rotation from the video alone: per frame, a robust "
        "fit over the whole sphere of sphere mode's flow (content that moves on its own does not "
        "drag it; translation is allowed for). Writes frame,time_s,omega_x_dps,omega_y_dps,"
        "omega_z_dps (world frame: +x right, +y up, +z forward),yaw_rate_dps,pitch_rate_dps,"
        "roll_rate_dps,rotation_dps,confidence. Given a grid made by 'vimsim preprocess --method "
        "sphere', reads its recorded estimate instead. See docs/ego.md.",
    )
    p.add_argument(
        "source", metavar="VIDEO", help="equirectangular video, or a sphere-mode GRID.npz"
    )
    p.add_argument("-o", "--output", required=True, metavar="EGO.csv", help="CSV to write")
    p.add_argument(
        "--layout", choices=LAYOUTS, default=None, help="stereo layout (default: the file's, else mono)"
    )
    add_source_arguments(p)
    p.add_argument("--eye", choices=EYES, default="left", help="eye of a stereo video")
    p.add_argument("--start", type=seconds, default=0.0, metavar="S", help="first frame at S s")
    p.add_argument("--end", type=seconds, default=None, metavar="S", help="stop before S s")
    p.add_argument("--flow", default="dis", metavar="METHOD", help=flow_help())
    p.add_argument(
        "--cell",
        type=positive_float,
        default=4.0,
        metavar="D",
        help="field cell size in degrees, dividing 180 (default 4)",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Write the CSV; 0 when written, 2 on bad input (nothing written)."""
    import zipfile

    import numpy as np

    from simulator.commands._progress import progress_bar, warnings_to_stderr
    from simulator.commands._source import source_from_args
    from simulator.commands.epof import _check_output_file
    from simulator.preprocess.egocsv import camera_rotation, write_ego_csv
    from simulator.preprocess.sphere import SphereConfig

    _check_output_file(args.output)
    with (
        warnings_to_stderr("vimsim ego"),
        progress_bar("ego", enabled=not args.no_progress) as bar,
    ):
        source = args.source
        if not zipfile.is_zipfile(source):  # a video: its projection and layout checked once
            source = source_from_args(args, source, layout=args.layout, eye=args.eye)
        table = camera_rotation(
            source,
            start_s=args.start,
            end_s=args.end,
            flow=args.flow,
            config=SphereConfig(cell_deg=args.cell),
            progress=bar,
        )
    write_ego_csv(args.output, table)
    mag = np.linalg.norm(table.omega_dps, axis=1)
    print(
        f"wrote {args.output}: {len(table.frame)} frames, camera rotation median "
        f"{float(np.median(mag)):.3g} deg/s, max {float(mag.max()):.3g} deg/s, "
        f"median confidence {float(np.median(table.confidence)):.2f}"
    )
    return 0
