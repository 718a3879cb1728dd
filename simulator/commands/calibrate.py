"""``vimsim calibrate RATINGS.csv -o MODEL.json``: a discomfort model fitted on a lab's ratings, with its held-out accuracy."""

from __future__ import annotations

import argparse

from simulator.commands._types import nonneg_int

__all__ = ["OPTIONS", "register", "run"]

#: The command's options, declared once: (flags, argparse keywords).
OPTIONS: tuple[tuple[tuple[str, ...], dict], ...] = (
    (("-o", "--output"), {"required": True, "metavar": "MODEL.json",
                          "help": "the model to write (plain JSON); beside it MODEL.weights.csv, "
                          "MODEL.calibration.png and MODEL.features.csv"}),
    (("--grids",), {"default": None, "metavar": "DIR",
                    "help": "cache folder of the videos' sphere-mode grids (made where missing, "
                    "reused when they are the grid of that very video); default MODEL.grids "
                    "beside the model"}),
    (("--seed",), {"type": nonneg_int, "default": 0, "metavar": "N",
                   "help": "seed of the bootstrap intervals (default 0)"}),
    (("--no-progress",), {"action": "store_true", "help": "no progress bar"}),
)  # fmt: skip


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``calibrate`` parser."""
    p = subparsers.add_parser(
        "calibrate",
        help="fit a discomfort model to ratings (RidgeCV, held-out accuracy) -> MODEL.json",
        description="Fit a regularised linear model (standardised features, RidgeCV) from the "
        "features vimsim measures in each rated video or viewing (EPOF, its rotational and "
        "translational parts, the camera's yaw/pitch/roll rates from 'vimsim ego', opacity, "
        "duration) to RATINGS.csv (columns video,rating[,group][,trace][,participant]; paths "
        "relative to the CSV), and judge it by cross-validation holding whole groups out "
        "(GroupKFold; leave-one-out without groups): LCC, SROCC, RMSE with bootstrap 95 % "
        "intervals. See docs/calibrate.md.",
    )
    p.add_argument("ratings", metavar="RATINGS.csv", help="one rated video or viewing a row")
    for flags, kw in OPTIONS:
        p.add_argument(*flags, **kw)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Write the model and its side files; 0 when written, 2 on bad input (nothing written)."""
    from simulator.commands._progress import progress_bar, warnings_to_stderr
    from simulator.discomfort.calibrate import calibrate, describe

    with (
        warnings_to_stderr("vimsim calibrate"),
        progress_bar("grids", unit="video", enabled=not args.no_progress) as bar,
    ):
        res = calibrate(args.ratings, args.output, grids=args.grids, seed=args.seed, progress=bar)
    print(f"wrote {args.output}: {describe(res.model)}")
    return 0
