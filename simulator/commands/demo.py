"""``vimsim demo``: the whole pipeline on an embedded default (what ``make demo`` runs)."""

from __future__ import annotations

import argparse
import sys

from simulator.commands._types import nonneg_int, positive_float

__all__ = ["register", "run"]


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``demo`` parser."""
    p = subparsers.add_parser(
        "demo",
        help="end-to-end demo: synthetic stereo coaster -> POF matrix -> EPOF -> GRF videos",
        description="Synthesise a short stereo (top-bottom) coaster clip with analytic "
        "ground truth, a look-around head path, preprocess the clip, compute EPOF and GRF "
        "opacity, render per-eye MP4s with GRFs and write plots, README.txt and "
        "summary.json into the output folder. Deterministic given --seed. See docs/demo.md.",
    )
    p.add_argument(
        "-o",
        "--output",
        default="outputs/demo",
        metavar="OUTDIR",
        help="output folder (default outputs/demo; created)",
    )
    p.add_argument(
        "--seed",
        type=nonneg_int,
        default=0,
        help="texture placement, head path and grains (default 0)",
    )
    p.add_argument(
        "--seconds", type=positive_float, default=3.0, help="clip length in seconds (default 3)"
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bars (step lines only)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run the demo; 0 when every output was written (any failed step raises: exit 1 or 2)."""
    from simulator.commands._progress import progress_bar, warnings_to_stderr
    from simulator.demo import DemoConfig, run_demo

    def note(text: str) -> None:
        print(f"vimsim demo: {text}", file=sys.stderr, flush=True)

    with (
        warnings_to_stderr("vimsim demo"),
        progress_bar("demo", enabled=not args.no_progress) as bar,
    ):
        s = run_demo(
            args.output, DemoConfig(seconds=args.seconds, seed=args.seed), progress=bar, note=note
        )
    print(
        f"wrote {len(s['files'])} files to {args.output} in {s['timings_s']['total']:.1f} s (see README.txt)"
    )
    return 0
