"""``vimsim analyze``: SSQ, MSSQ-short, flow-normalised scores and the paper's tests."""

from __future__ import annotations

import argparse
import sys

from simulator.commands._types import nonneg_float
from simulator.core.choices import FLOW_STATS

__all__ = ["register", "run"]


def _conditions(text: str) -> tuple[str, str]:
    parts = [t.strip() for t in text.split(",")]
    if len(parts) != 2 or not all(parts) or parts[0] == parts[1]:
        raise argparse.ArgumentTypeError(
            f"expected two different labels A,B, e.g. NR,GR; got {text!r}"
        )
    return parts[0], parts[1]


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``analyze`` parser."""
    p = subparsers.add_parser(
        "analyze",
        help="study statistics: SSQ, MSSQ-short, K_OF, Shapiro-Wilk, Mann-Whitney",
        description="Score the SSQ (Kennedy 1993) and MSSQ-short (Golding 2006) of a study, "
        "normalise each SSQ score by the session optical flow and susceptibility (the paper's "
        "K_OF), exclude low-flow sessions, run Shapiro-Wilk and a two-sided Mann-Whitney U "
        "between the two conditions, and write scores, the paper's table (Markdown, CSV), "
        "box plots and a report into REPORT_DIR. Columns: see docs/analyze.md.",
    )
    p.add_argument(
        "data", metavar="DATA.csv", help="one row per participant ('#' lines are comments)"
    )
    p.add_argument(
        "-o",
        "--output",
        metavar="REPORT_DIR",
        required=True,
        help="folder for the report (created)",
    )
    p.add_argument(
        "--flow-stat",
        choices=FLOW_STATS,
        default="mean",
        help="session flow from an EPOF CSV: mean, median or sum of epof_dps (deg/s); "
        "default mean. The 'flow' column, where given, is used as is",
    )
    p.add_argument(
        "--exclude-below",
        type=nonneg_float,
        default=None,
        metavar="X",
        help="exclude sessions whose flow is below X (same unit as the session flow); "
        "reported by id. Default: none excluded (flow 0 always is)",
    )
    p.add_argument(
        "--conditions",
        type=_conditions,
        default=None,
        metavar="A,B",
        help="the two condition labels in table order, e.g. NR,GR (default: order of "
        "first appearance; required when the file has more than two)",
    )
    p.add_argument(
        "--k-of",
        choices=("invariant", "paper"),
        default="invariant",
        help="K_OF formula: invariant (default: the paper's x n_g / mean group size, "
        "independent of group size, equal to the paper's with equal groups) or paper (as "
        "printed in the paper: scales with 1 / group size); docs/analyze.md",
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run the analysis; exit 0 when scores were written (notes on stderr), 2 on bad input."""
    import math

    from simulator.analyze import analyze_study, read_study, write_report
    from simulator.analyze.report import p_text

    study = read_study(args.data, flow_stat=args.flow_stat)
    for line in study.problems:
        print(f"vimsim analyze: warning: {line}", file=sys.stderr)
    an = analyze_study(study, exclude_below=args.exclude_below, conditions=args.conditions,
                       k_of_formula=args.k_of)  # fmt: skip
    for pid, why in an.excluded:
        print(f"vimsim analyze: excluded {pid}: {why}", file=sys.stderr)
    for note in an.messages():
        print(f"vimsim analyze: note: {note}", file=sys.stderr)
    written = write_report(an, args.output)
    a, b = an.conditions
    for r in an.comparisons:
        ma, mb = ("n/a" if math.isnan(v) else f"{v:.2f}" for v in (r["mean_a"], r["mean_b"]))
        p = p_text(r["p"])
        print(f"{r['measure']}: {a} vs. {b} means {ma} vs. {mb}, p {p if p[0] == '<' else '= ' + p}")
    print(f"wrote {len(written)} files to {args.output} (K_OF formula: {args.k_of})")
    return 0
