"""``vimsim analyze``: SSQ, MSSQ-short, flow-normalised scores and the paper's tests."""

from __future__ import annotations

import argparse
import sys

from simulator.commands._types import nonneg_float
from simulator.core.choices import FLOW_STATS
from simulator.core.errors import InputError
from simulator.core.statsopts import STATS_OPTIONS, check_stats_option

__all__ = ["register", "run"]


def _conditions(text: str) -> tuple[str, str]:
    parts = [t.strip() for t in text.split(",")]
    if len(parts) != 2 or not all(parts) or parts[0] == parts[1]:
        raise argparse.ArgumentTypeError(
            f"expected two different labels A,B, e.g. NR,GR; got {text!r}"
        )
    return parts[0], parts[1]


def _option_type(name: str):
    """An argparse ``type=`` from the option table's check (one line with an example)."""
    opt = next(o for o in STATS_OPTIONS if o.name == name)

    def parse(text: str):
        try:
            return check_stats_option(name, opt.kind(text) if opt.kind is not int else text)
        except (InputError, ValueError) as e:
            raise argparse.ArgumentTypeError(str(e).removeprefix(f"{opt.flag}: ")) from None

    parse.__name__ = opt.kind.__name__
    return parse


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
    for opt in STATS_OPTIONS:  # generated from the one table the library checks with
        kw = {"choices": opt.choices} if opt.choices else {"type": _option_type(opt.name)}
        dflt = "" if opt.default is None else f" (default {opt.default})"
        p.add_argument(opt.flag, dest=opt.name, default=opt.default, help=opt.help + dflt,
                       metavar=None if opt.choices else opt.name.upper(), **kw)  # fmt: skip
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run the analysis; exit 0 when scores were written (notes on stderr), 2 on bad input."""
    import math

    from simulator.analyze import StatsOptions, analyze_study, read_study, write_report
    from simulator.analyze.report import p_text

    opts = StatsOptions(**{o.name: getattr(args, o.name) for o in STATS_OPTIONS})

    study = read_study(args.data, flow_stat=args.flow_stat)
    for line in study.problems:
        print(f"vimsim analyze: warning: {line}", file=sys.stderr)
    an = analyze_study(study, exclude_below=args.exclude_below, conditions=args.conditions,
                       k_of_formula=args.k_of, stats=opts)  # fmt: skip
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
    st = an.statistics
    for r in st.tests if st is not None else ():
        if r["effect_name"]:
            p = p_text(r["p"])
            print(f"{r['measure']}: {st.design.name} design, {r['test']} p "
                  f"{p if p[0] == '<' else '= ' + p} (Holm {p_text(r['p_holm'])}), "
                  f"{r['effect_name']} = {r['effect']:.3f} "
                  f"[{r['effect_ci_low']:.3f}, {r['effect_ci_high']:.3f}], n = {r['n']}")  # fmt: skip
    for r in st.power if st is not None else ():
        print(f"power: {r['participants_needed']} participants needed"
              f"{'' if st.design.paired else ' per group'} ({r['test']}, effect {r['effect']:.3f},"
              f" power {r['power']:g}, alpha {r['alpha']:g})")  # fmt: skip
    print(f"wrote {len(written)} files to {args.output} (K_OF formula: {args.k_of})")
    return 0
