"""``vimsim compare``: frames folders against goldens (PSNR, mean absolute difference, SSIM); exit 1 when a frame regresses.

Parses the options; the work is :func:`simulator.testing.compare.compare_dirs`.
"""

from __future__ import annotations

import argparse
import sys

__all__ = ["register", "run"]


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``compare`` parser."""
    p = subparsers.add_parser(
        "compare",
        help="compare a vimsim frames folder with goldens (exit 0 all pass, 1 regression, 2 bad input)",
        description="Match the PNG frames of DIR and GOLDEN_DIR by name and report PSNR, mean "
        "absolute difference (8-bit levels) and SSIM (scikit-image) per frame. A frame passes "
        "when PSNR >= --psnr and mean abs diff <= --max-diff; for each failing frame "
        "REPORT_DIR gets NAME.diff.png (|new - golden| x 8) and NAME.side.png (golden | new "
        "| diff), and compare.json every frame's measures. Exit 0 when all pass, 1 when some "
        "frame regresses, 2 on bad input (missing or extra frames, other sizes, non-PNG files).",
    )
    p.add_argument("frames_dir", metavar="DIR", help="new frames (vimsim frames -o DIR)")
    p.add_argument("golden_dir", metavar="GOLDEN_DIR", help="golden frames")
    p.add_argument(
        "--psnr",
        type=float,
        default=None,
        metavar="DB",
        help="lowest PSNR that passes, dB (default 40)",
    )
    p.add_argument(
        "--max-diff",
        type=float,
        default=None,
        metavar="F",
        help="largest mean absolute difference that passes, 8-bit levels (default 1.0)",
    )
    p.add_argument(
        "--report",
        metavar="REPORT_DIR",
        help="where diffs and compare.json go (default DIR/compare)",
    )
    p.add_argument(
        "--update",
        action="store_true",
        help="after the comparison, copy the new frames (and frames.json) over the goldens "
        "(after review); refused when a frame fails unless --force; the replaced goldens are "
        "kept in GOLDEN_DIR.backup-DATE beside them",
    )
    p.add_argument(
        "--force",
        action="store_true",
        help="with --update: update even though some frames fail the comparison",
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Compare; print one line per failing frame; 0 pass, 1 regression, 2 bad input."""
    from pathlib import Path

    from simulator.core.errors import InputError
    from simulator.testing.compare import (
        DEFAULT_MAX_DIFF,
        DEFAULT_PSNR_DB,
        compare_dirs,
        update_goldens,
    )

    psnr = DEFAULT_PSNR_DB if args.psnr is None else args.psnr
    mad = DEFAULT_MAX_DIFF if args.max_diff is None else args.max_diff
    if args.force and not args.update:
        raise InputError("--force goes with --update (update goldens although frames fail)")
    if args.update and not Path(args.golden_dir).is_dir():
        names, _ = update_goldens(args.frames_dir, args.golden_dir)
        print(f"vimsim compare: {len(names)} goldens created in {args.golden_dir}")
        return 0
    rep = compare_dirs(
        args.frames_dir, args.golden_dir, psnr_db=psnr, max_diff=mad, report_dir=args.report
    )
    for line in rep.changes:  # what changed, before the pixel figures
        print(f"vimsim compare: {line}")
    for s in rep.failures:
        print(f"vimsim compare: FAIL {s.why(psnr, mad)}", file=sys.stderr)
    worst = min(s.psnr_db for s in rep.scores)
    print(
        f"vimsim compare: {len(rep.scores) - len(rep.failures)}/{len(rep.scores)} frames pass "
        f"(lowest PSNR {worst:.2f} dB); report {rep.report_dir}/compare.json"
    )
    if args.update and not rep.passed and not args.force:
        print(
            f"vimsim compare: goldens NOT updated: {len(rep.failures)} frames fail; review "
            "them, then --update --force",
            file=sys.stderr,
        )
        return 1
    if args.update:
        names, backup = update_goldens(args.frames_dir, args.golden_dir)
        kept = f"; the replaced goldens kept in {backup}" if backup else ""
        print(f"vimsim compare: {len(names)} goldens updated in {args.golden_dir}{kept}")
        return 0
    return 0 if rep.passed else 1
