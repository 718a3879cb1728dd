"""``vimsim report OUTDIR [--serve]``: (re)build a study's HTML report, and serve it on loopback."""

from __future__ import annotations

import argparse
import sys

__all__ = ["register", "run"]


def add_browser_width(p: argparse.ArgumentParser) -> None:
    """``--browser-width PX`` (report and study): the width of the report's browser copies."""
    p.add_argument(
        "--browser-width", default=None, metavar="PX",
        help="width of the report's browser copy of each video, an even number of pixels "
        "(default 2048; a wider source is scaled down, never up)",
    )  # fmt: skip


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``report`` parser."""
    p = subparsers.add_parser(
        "report",
        help="a study's self-contained HTML report with viewing replay (OUTDIR/report/)",
        description="Rebuild OUTDIR/report/ of a complete study (vimsim study writes it too): "
        "index.html (summary), viewings.html (sortable, filterable), a page per video (EPOF "
        "across viewers, time x yaw map, provocative moments) and per viewing (EPOF/opacity "
        "timeline and the replay: the study's browser copy of the video along the recorded "
        "head path with the mitigation at the viewing's opacity; free look with live EPOF), "
        "analysis.html. Offline: nothing is fetched from outside the folder. Browsers block "
        "the replay under file://; --serve serves the folder on 127.0.0.1 only. See docs/report.md.",
    )
    p.add_argument("outdir", metavar="OUTDIR", help="the output folder of vimsim study")
    p.add_argument(
        "--serve",
        action="store_true",
        help="then serve OUTDIR/report on 127.0.0.1 (loopback only) until Ctrl-C; prints the address",
    )
    p.add_argument(
        "--port", type=int, default=0, metavar="N", help="port for --serve (default: any free)"
    )
    p.add_argument(
        "--no-build", action="store_true", help="with --serve: serve the report as it is"
    )
    add_browser_width(p)
    p.add_argument("--no-progress", action="store_true", help="no progress bar or lines")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Build (InputError -> exit 2, nothing written), then optionally serve."""
    import time

    from simulator.commands._progress import progress_bar
    from simulator.core.errors import InputError
    from simulator.report.build import build_report, check_study
    from simulator.report.serve import start_server

    if not (0 <= args.port <= 65535):
        raise InputError(f"--port must be 0..65535; got {args.port}")
    if args.no_build:
        out, _ = check_study(args.outdir)
        folder = out / "report"
        if not (folder / "index.html").is_file():
            raise InputError(f"{folder}: no report yet; run vimsim report {args.outdir}")
    else:
        with progress_bar("report (browser copy)", enabled=not args.no_progress) as bar:
            res = build_report(args.outdir, browser_width=args.browser_width, progress=bar)
        folder = res.folder
        print(f"vimsim report: {res.files} files in {res.seconds:.1f} s -> {res.index}")
    if not args.serve:
        return 0
    try:
        srv = start_server(folder, args.port)
    except OSError as e:
        print(
            f"vimsim report: cannot serve on 127.0.0.1:{args.port} ({e.strerror})", file=sys.stderr
        )
        return 1
    print(f"vimsim report: serving {folder} at {srv.url} (loopback only; Ctrl-C stops)", flush=True)
    try:
        while True:
            time.sleep(3600)
    finally:
        srv.close()
