"""``vimsim study STUDY.toml -o OUTDIR``: every viewing of a study, locally or on a Ray cluster."""

from __future__ import annotations

import argparse
import sys

from simulator.commands._types import positive_int
from simulator.commands.report import add_browser_width

__all__ = ["register", "run"]


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``study`` parser."""
    p = subparsers.add_parser(
        "study",
        help="a whole study (videos x viewings): preprocess, EPOF, renders, plots, analysis",
        description="Run every viewing of a study manifest (TOML: [[videos]], [[viewings]], "
        "optional [questionnaires], [epof], [render], [grf]; see docs/study.md and "
        "examples/study.toml). Each video is preprocessed once (grids cached by content hash "
        "and options), every viewing's EPOF and opacity computed, the viewings with render = "
        "true rendered. Writes OUTDIR/viewings.csv, OUTDIR/epof/<viewing>.csv, "
        "OUTDIR/render/<viewing>/, OUTDIR/videos/<video>/ (plots, provocative moments), "
        "OUTDIR/analysis/ (with questionnaires), OUTDIR/study.json and then the HTML report "
        "OUTDIR/report/ (docs/report.md). Exit status 3 when some viewings failed (their "
        "status says why) or the analysis or the report could not be made, 2 for a bad manifest.",
    )
    p.add_argument("manifest", metavar="STUDY.toml", help="the study manifest")
    p.add_argument("-o", "--output", required=True, metavar="OUTDIR", help="output folder")
    p.add_argument(
        "--executor",
        default="local",
        metavar="local|ray|ray:ADDRESS",
        help="local: a process pool (default); ray: a local Ray runtime; ray:HOST:PORT: join "
        "a running Ray cluster (needs pip install 'vimsim[ray]')",
    )
    p.add_argument(
        "--workers",
        type=positive_int,
        default=None,
        metavar="N",
        help="parallel tasks (default: CPU count; on a joined cluster its CPUs decide)",
    )
    p.add_argument(
        "--resume",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="skip viewings whose inputs and options are unchanged since the last run on "
        "OUTDIR (default; --no-resume recomputes every viewing)",
    )
    p.add_argument(
        "--cache-dir",
        default=None,
        metavar="DIR",
        help="grid cache (default: $VIMSIM_CACHE_DIR, else $XDG_CACHE_HOME/vimsim or "
        "~/.cache/vimsim; the old $VIMSIM_CACHE still works, deprecated)",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument(
        "--no-artefacts",
        action="store_true",
        help="keep every frame: codec keyframes, cuts, fades and screen-fixed graphics are "
        "detected by default (cached in the grid) and left out of the opacity thresholds, "
        "statistics and moments (as [epof] artefacts = false)",
    )
    p.add_argument(
        "--dry-run",
        action="store_true",
        help="check everything the run would (globs, users, that every trace covers its "
        "video, render ranges, cache hits and misses) and print the plan and the count of "
        "tasks; writes nothing (exit 2 when a viewing would fail)",
    )
    p.add_argument(
        "--no-report",
        action="store_true",
        help="do not write OUTDIR/report/ (the HTML report; vimsim report OUTDIR makes it later)",
    )
    add_browser_width(p)
    p.set_defaults(func=run)


def _print_warnings(pairs: list[tuple[str, str]]) -> None:
    """Each distinct warning once on stderr, with the viewings it belongs to."""
    by_text: dict[str, list[str]] = {}
    for vid, text in pairs:
        by_text.setdefault(text, []).append(vid)
    for text, vids in by_text.items():
        who = ", ".join(vids[:3]) + (f" and {len(vids) - 3} more" if len(vids) > 3 else "")
        print(f"vimsim study: warning: {who}: {text}", file=sys.stderr)


def _dry_run(args: argparse.Namespace, manifest) -> int:
    from simulator.study.plan import dry_run

    plan = dry_run(manifest, args.output, cache_dir=args.cache_dir, resume=args.resume)
    for vid, v in plan["videos"].items():
        what = "preprocess" if v["preprocess"] else "no preprocessing needed"
        print(f"video {vid}: grid cache {v['cache']} ({v['method']} mode), {what}")
    for w in plan["viewings"]:
        rng = ""
        if w["render"]:
            a, b = w["start_s"], w["end_s"]
            rng = " render" + (f" {a or 0:g}..{'end' if b is None else f'{b:g}'} s"
                               if a is not None or b is not None else "")  # fmt: skip
            rng += " +review" if w["review"] else ""
        user = f" user {w['user']}" if w["user"] != "" else ""
        print(f"viewing {w['viewing']}: {w['action']}, video {w['video']}, "
              f"{w['trace']}{user}{rng}")  # fmt: skip
    _print_warnings([(v, x) for v, xs in plan["warnings"].items() for x in xs])
    for line in plan["problems"]:
        print(f"vimsim study: error: {line}", file=sys.stderr)
    n = len(plan["viewings"])
    todo = sum(w["action"] == "compute" for w in plan["viewings"])
    renders = sum(bool(w["render"]) for w in plan["viewings"])
    n_warn = sum(bool(x) for x in plan["warnings"].values())
    print(f"vimsim study: dry run: {n} viewings ({todo} to compute, {n - todo} unchanged, "
          f"{renders} to render, {n_warn} with warnings), {plan['tasks']} tasks, "
          f"{len(plan['problems'])} problems; nothing written")  # fmt: skip
    return 2 if plan["problems"] else 0


def _check_browser_width(width, manifest) -> None:
    """InputError unless ``--browser-width`` is an even width no wider than any mono
    equirect video of the study (other layouts are checked when their copy is made)."""
    from simulator.core.errors import InputError
    from simulator.media.video import probe
    from simulator.report.build import check_browser_width

    w = check_browser_width(width)
    for v in manifest.videos:
        if v.layout == "mono" and v.projection == "equirect" and v.path.is_file():
            vw = probe(v.path).width
            if w > vw:
                raise InputError(f"{v.path}: --browser-width {w} is wider than the video "
                                 f"({vw} px); give at most {vw - vw % 2}")  # fmt: skip


def run(args: argparse.Namespace) -> int:
    """Run the study; 0 all viewings ok, 3 some failed, 2 bad manifest (nothing done)."""
    from simulator.commands._progress import progress_bar
    from simulator.study import load_manifest, run_study
    from simulator.study.executors import parse_executor

    parse_executor(args.executor)  # an unknown executor is a usage error before anything
    manifest = load_manifest(args.manifest)
    if args.no_artefacts:  # wins over the manifest's [epof] artefacts
        from dataclasses import replace

        manifest = replace(manifest, epof={**manifest.epof, "artefacts": False},
                           videos=tuple(replace(v, artefacts=False) for v in manifest.videos))  # fmt: skip
    if args.browser_width is not None and not args.no_report:  # before any work, dry run too
        _check_browser_width(args.browser_width, manifest)
    if args.dry_run:
        return _dry_run(args, manifest)
    if not args.no_report:  # a report folder holding others' files: refused before any work
        from pathlib import Path

        from simulator.report.build import check_report_folder

        check_report_folder(Path(args.output) / "report")
    with progress_bar("study", unit="task", enabled=not args.no_progress) as bar:
        s = run_study(
            manifest,
            args.output,
            executor=args.executor,
            workers=args.workers,
            cache_dir=args.cache_dir,
            resume=args.resume,
            progress=None if bar is None else (lambda done, failed, total: bar(done, total, failed)),
        )
    c = s["counts"]
    report_error = None
    if not args.no_report:
        from simulator.core.errors import InputError
        from simulator.report.build import build_report

        try:
            with progress_bar("report (browser copy)", enabled=not args.no_progress) as bar:
                rep = build_report(args.output, browser_width=args.browser_width, progress=bar)
            print(f"vimsim study: report {rep.seconds:.1f} s (plots and tables "
                  f"{s['timings_s']['outputs']:.1f} s) -> {rep.index}", file=sys.stderr)  # fmt: skip
        except InputError as e:  # the study is complete; only its report is missing
            report_error = str(e)
            print(f"vimsim study: report not made: {e}", file=sys.stderr)
    _print_warnings([(w["viewing"], w["warning"]) for w in s["warnings"]])
    for f in s["failures"]:
        print(f"vimsim study: failed {f['viewing']}: {f['status']}", file=sys.stderr)
    an = s["outputs"].get("analysis")
    if an and an.get("error"):
        print(f"vimsim study: analysis not made: {an['error']}", file=sys.stderr)
    for note in (an or {}).get("notes") or []:
        print(f"vimsim study: analysis: {note}", file=sys.stderr)
    for vid, vo in s["outputs"]["videos"].items():
        if "error" in vo:
            print(f"vimsim study: video {vid}: {vo['error']}", file=sys.stderr)
    print(
        f"vimsim study: {c['ok']} ok, {c['with_warnings']} with warnings, {c['failed']} failed "
        f"(of {c['viewings']} viewings; {c['resumed']} unchanged), "
        f"{s['timings_s']['total']:.1f} s -> {args.output}/study.json"
    )
    return 3 if c["failed"] or (an and an.get("error")) or report_error else 0
