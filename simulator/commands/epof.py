"""``vimsim epof GRID.npz PATH.csv -o EPOF.csv``: EPOF and GRF opacity of one viewing."""

from __future__ import annotations

import argparse
import sys

from simulator.commands._opacity import (
    add_opacity_arguments,
    add_preset_argument,
    rule_from_args,
)
from simulator.commands._types import add_fov_arguments, frustum_from_args, positive_int
from simulator.core.choices import EPOF_METHODS

__all__ = ["register", "run"]


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``epof`` parser."""
    from simulator.commands.headpath import add_reader_options

    p = subparsers.add_parser(
        "epof",
        help="EPOF (deg/s) and GRF opacity of a viewing, one row per video frame",
        description="Estimated perceived optical flow (paper 3.5): for every video frame, the "
        "overlap-weighted mean of the flow of the windows the viewport overlaps (overlap = "
        "fraction of the viewport's solid angle inside the window), and the GRF opacity "
        "(0 at the 10th, 1 at the 90th percentile of the whole video's flow). Writes "
        "frame,time_s,yaw_deg,pitch_deg,roll_deg,epof_dps,opacity, and for a sphere-mode grid "
        "with the per-frame camera rotation the EPOF's rotational and translational parts "
        "epof_rot_dps,epof_trans_dps (they add up to epof_dps; docs/epof.md).",
    )
    p.add_argument("grid", metavar="GRID.npz", help="grid file from vimsim preprocess")
    p.add_argument(
        "headpath", metavar="PATH.csv", help="head path (any format of vimsim headpath convert)"
    )
    p.add_argument("-o", "--output", required=True, metavar="EPOF.csv")
    p.add_argument(
        "--plot", default=None, metavar="EPOF.png", help="also plot EPOF and opacity over time"
    )
    add_fov_arguments(p, what="viewport", default="the grid's window FOV")
    p.add_argument(
        "--method",
        choices=EPOF_METHODS,
        default="auto",
        help="paper: overlap-weighted window POFs (paper 3.5); sphere: exact EPOF, the field of a "
        "'vimsim preprocess --method sphere' grid integrated over the actual viewport (any FOV); "
        "auto (default): sphere when the grid has a field",
    )
    p.add_argument(
        "--top-k",
        type=positive_int,
        default=None,
        metavar="K",
        help="use only the K largest overlaps (the paper's figure shows 4); default all",
    )
    p.add_argument(
        "--flow-weights",
        default=None,
        metavar="rot=A,trans=B",
        help="weighted EPOF = A x rotational part + B x translational part; it drives the "
        "opacity and is written as epof_dps (default rot=1,trans=1: the EPOF itself). Needs a "
        "sphere-mode grid with the per-frame camera rotation",
    )
    add_opacity_arguments(p)
    add_preset_argument(p)
    p.add_argument(
        "--artefacts",
        action="store_true",
        help="detect codec keyframes, hard cuts, fades and static overlays appearing (from the "
        "grid's video when it is there, else from the flow), leave them out of the opacity "
        "percentiles, hold the opacity through them and name them in an artefact column",
    )
    add_reader_options(p)
    p.set_defaults(func=run)


def _check_output_file(path: str) -> None:
    """InputError unless ``path`` can be written: its folder exists and is writable and
    it is not a folder (checked before any work, so that nothing is left half done)."""
    import os
    from pathlib import Path

    from simulator.core.errors import InputError

    target = Path(path)
    parent = target.parent if str(target.parent) else Path(".")
    if not parent.is_dir():
        raise InputError(f"{target}: output directory {parent} does not exist")
    if not os.access(parent, os.W_OK):
        raise InputError(f"{target}: output directory {parent} is not writable")
    if target.is_dir():
        raise InputError(f"{target}: is a directory; expected an output file name")


def run(args: argparse.Namespace) -> int:
    """Compute and write the EPOF CSV (and plot); InputError -> exit 2 with nothing written."""
    from pathlib import Path

    from simulator.commands._progress import warnings_to_stderr
    from simulator.commands.headpath import load_headpath_args, print_warnings
    from simulator.epof import compute_epof, plot_epof, write_epof_csv
    from simulator.media.gridfile import load_grid

    for out in (args.output, args.plot):
        if out:
            _check_output_file(out)
    frustum = frustum_from_args(args, (None, None))  # None: the grid's window FOV
    from simulator.epof.parts import parse_flow_weights

    weights = None if args.flow_weights is None else parse_flow_weights(args.flow_weights)
    _apply_preset(args)
    with warnings_to_stderr("vimsim epof"):
        rule = rule_from_args(args)
        grid = load_grid(args.grid)
    vid = grid.meta.get("video") if isinstance(grid.meta.get("video"), dict) else {}
    n_video = int(vid.get("n_frames") or grid.n_frames)  # the whole video, not the grid's part
    notes: list[str] = []  # span warnings: printed once the EPOF is written
    hp = load_headpath_args(args, args.headpath, "vimsim epof", n_video / grid.fps,
                            Path(str(vid.get("path") or args.grid)).name, notes)  # fmt: skip
    if args.preset == "cao2021-code":
        return _run_nearest(args, grid, hp)
    art = None
    if args.artefacts:
        from simulator.preprocess.artefacts import artefacts_for_grid

        art = artefacts_for_grid(grid)
    res = compute_epof(
        grid,
        hp,
        frustum=frustum,
        top_k=args.top_k,
        rule=rule,
        hold=args.hold_last,
        method=args.method,
        flow_weights=weights,
        artefacts=art,
    )
    if args.method == "auto" and args.top_k is not None and grid.field_dps is not None:
        print(
            f"vimsim epof: note: --top-k uses paper-mode EPOF (window overlaps), not the grid's "
            f"sphere field; method {res.meta['method']} recorded in {args.output}",
            file=sys.stderr,
        )
    write_epof_csv(args.output, res)  # the CSV first: a plot is never left without it
    if args.plot:
        plot_epof(args.plot, res, title=f"{args.headpath} on {args.grid}")
    print_warnings("vimsim epof", notes)
    lo, hi = res.thresholds_dps
    print(
        f"wrote {args.output}: {len(res.frame)} frames, EPOF median {float(_median(res.epof_dps)):.3g} deg/s, "
        f"opacity 0 at {lo:.3g}, 1 at {hi:.3g} deg/s ({res.meta['method']} EPOF, "
        f"{'paper' if rule.is_paper else 'eased'} opacity rule)"
    )
    return 0


def _apply_preset(args: argparse.Namespace) -> None:
    """``--preset paper`` sets the paper's method and rule; ``cao2021-code`` refuses the
    options its rule has no use for (InputError, one line)."""
    from simulator.core.errors import InputError

    if args.preset == "vimsim":
        return
    given = [o for o, on in (("--method sphere", args.method == "sphere"),
                             ("--flow-weights", args.flow_weights is not None),
                             ("--opacity-rule absolute", args.opacity_rule == "absolute"))
             if on]  # fmt: skip
    if args.preset == "cao2021-code":
        given += [o for o, on in (("--top-k", args.top_k is not None),
                                  ("--artefacts", args.artefacts),
                                  ("--method paper", args.method == "paper"),
                                  ("a viewport FOV (the nearest window has none)",
                                   any(getattr(args, k, None) is not None
                                       for k in ("fov", "hfov", "vfov", "headset"))))
                  if on]  # fmt: skip
    if given:
        raise InputError(f"--preset {args.preset} cannot be combined with {', '.join(given)}")
    if args.preset == "paper":
        args.method, args.opacity_rule = "paper", "paper"


def _run_nearest(args: argparse.Namespace, grid, hp) -> int:
    """``--preset cao2021-code``: the authors' runtime, with the ``flow_px`` column."""
    from simulator.epof import plot_epof, write_epof_csv
    from simulator.epof.nearest import FLOW_PX_COLUMN, nearest_epof

    res = nearest_epof(grid, hp, hold=args.hold_last)  # the grid's imported scale, if any
    write_epof_csv(args.output, res, extra={FLOW_PX_COLUMN: res.meta["flow_px"]})
    if args.plot:
        plot_epof(args.plot, res, title=f"{args.headpath} on {args.grid} (cao2021-code)")
    rule = res.meta["rule"]
    print(
        f"wrote {args.output}: {len(res.frame)} frames, nearest-window flow median "
        f"{float(_median(res.meta['flow_px'])):.3g} px/frame, opacity 0 at {rule.low_px:g}, 1 at "
        f"{rule.high_px:g} px/frame (cao2021-code: the authors' runtime)"
    )
    return 0


def _median(x):
    import numpy as np

    return np.median(x)
