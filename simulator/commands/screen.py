"""``vimsim screen VIDEO... -o OUTDIR``: screen videos with scripted viewers before anyone watches them."""

from __future__ import annotations

import argparse
import sys

from simulator.commands._opacity import add_opacity_arguments
from simulator.commands._progress import progress_bar
from simulator.commands._source import add_source_arguments
from simulator.commands._types import nonneg_int
from simulator.core.choices import LAYOUTS

__all__ = ["register", "run"]


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``screen`` parser."""
    p = subparsers.add_parser(
        "screen",
        help="screen videos before release: N scripted viewers, flow bands, artefacts left out",
        description="Preprocess each video in sphere mode (through the study's grid cache, or "
        "a --grid you already made of it), watch it with N scripted viewers, and report per "
        "video the EPOF across viewers over time, the time x yaw map, the most provocative "
        "moments with thumbnails, the whole sphere's flow and a one-page summary.png, and a "
        "comparison table across videos (OUTDIR/screen/comparison.csv) with the share of "
        "time in each named flow band, all on one offline page OUTDIR/screen/index.html "
        "(docs/screen.md). Codec keyframes, hard cuts, fades "
        "and static overlays appearing are detected and left out (--no-artefacts: kept).",
    )
    p.add_argument("videos", nargs="+", metavar="VIDEO", help="the videos (equirect unless --projection or their metadata says otherwise)")
    p.add_argument("-o", "--output", required=True, metavar="OUTDIR", help="output folder")
    p.add_argument("--viewers", type=int, default=30, metavar="N",
                   help="scripted viewers per video (default 30)")  # fmt: skip
    p.add_argument("--force", action="store_true",
                   help="run a screening whose --viewers make it estimated to take over half "
                   "an hour of CPU (refused otherwise)")  # fmt: skip
    p.add_argument("--viewer-kind", default="look-around", metavar="KIND",
                   help="scripted head path of each viewer: look-around (default), sine, "
                   "sweep or static (vimsim headpath synth)")  # fmt: skip
    p.add_argument("--seed", type=nonneg_int, default=0, metavar="S",
                   help="viewer k uses seed S + k - 1 (default 0)")  # fmt: skip
    p.add_argument("--grid", action="append", default=[], metavar="GRID.npz",
                   help="a grid you already made; used for the video it was made of "
                   "(same content), repeatable")  # fmt: skip
    p.add_argument("--layout", choices=LAYOUTS, default="mono",
                   help="frame layout of every VIDEO (stereo: the left eye is screened)")  # fmt: skip
    add_source_arguments(p, orientation=False)  # --projection, --lens-fov of every VIDEO
    p.add_argument("--no-artefacts", action="store_true",
                   help="do not detect keyframes, cuts, fades and overlays (keep every frame)")  # fmt: skip
    p.add_argument("--executor", default="local", metavar="local|ray|ray:ADDRESS",
                   help="as vimsim study (default local)")  # fmt: skip
    p.add_argument("--workers", type=int, default=None, metavar="N",
                   help="parallel tasks (default: CPU count)")  # fmt: skip
    p.add_argument("--cache-dir", default=None, metavar="DIR", help="grid cache (as vimsim study)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--model", default=None, metavar="MODEL.json",
                   help="a discomfort model (vimsim calibrate): adds predicted_discomfort, "
                   "predicted_low, predicted_high (held-out 95%% band) and predicted_extrapolated "
                   "to comparison.csv and the page, beside the model's held-out SROCC and RMSE")  # fmt: skip
    add_opacity_arguments(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Screen the videos; 0 all viewers ok, 3 some failed, 2 bad input (nothing done)."""
    from simulator.commands._opacity import rule_from_args
    from simulator.core.errors import InputError
    from simulator.screen.run import check_viewers, screen_videos
    from simulator.study.executors import parse_executor

    check_viewers(args.viewers, args.viewer_kind)
    if args.workers is not None and args.workers < 1:
        raise InputError(f"--workers must be an integer >= 1; got {args.workers}")
    parse_executor(args.executor)
    model = None
    if args.model is not None:  # checked (schema, features version) before any work
        from simulator.discomfort.model import load_model

        model = load_model(args.model)
    rule = rule_from_args(args)  # bad --low-dps/--high-dps: one line before any work
    epof = {"low_pct": rule.low_pct, "high_pct": rule.high_pct, "opacity_source": rule.source,
            "smooth_s": rule.smoothing_s, "ease_in_s": rule.ease_in_s, "ease_out_s": rule.ease_out_s,
            "opacity_rule": "absolute" if rule.is_absolute else args.opacity_rule,
            "low_dps": rule.low_dps, "high_dps": rule.high_dps}  # fmt: skip
    with progress_bar("screen", unit="task", enabled=not args.no_progress) as bar:
        s = screen_videos(args.videos, args.output, viewers=args.viewers, kind=args.viewer_kind,
                          seed=args.seed, epof=epof, artefacts=not args.no_artefacts,
                          grids=args.grid, layout=args.layout, projection=args.projection,
                          lens_fov_deg=args.lens_fov, executor=args.executor, workers=args.workers,
                          cache_dir=args.cache_dir, model=model, force=args.force,
                          progress=None if bar is None else (lambda d, f, t: bar(d, t, f)))  # fmt: skip
    for f in s["failures"]:
        print(f"vimsim screen: failed {f['viewing']}: {f['status']}", file=sys.stderr)
    for vid, vo in s["screen"]["videos"].items():
        if "error" in vo:
            print(f"vimsim screen: video {vid}: {vo['error']}", file=sys.stderr)
    for vid, g in s["screen"]["reused_grids"].items():
        print(f"vimsim screen: video {vid}: reused {g}", file=sys.stderr)
    for g in s["screen"]["unused_grids"]:
        print(f"vimsim screen: note: {g} is of none of the videos (content or layout): not used",
              file=sys.stderr)  # fmt: skip
    for r in s["screen"]["rows"]:
        pred = ("" if model is None else f", predicted discomfort {r['predicted_discomfort']:.3g} "
                f"[{r['predicted_low']:.3g}, {r['predicted_high']:.3g}]"
                + (" (extrapolated)" if r["predicted_extrapolated"] else ""))  # fmt: skip
        print(f"{r['video']}: mean {r['epof_mean_dps']:.2f} deg/s, p90 {r['epof_p90_dps']:.2f} "
              f"({r['band_p90']}), artefact frames {r['artefact_frames']}{pred}")  # fmt: skip
    if model is not None:
        from simulator.discomfort.predict import model_note

        print(f"vimsim screen: {model_note(model)}")
    print(f"vimsim screen: {len(s['screen']['rows'])} video(s), {s['timings_s']['total']:.1f} s "
          f"-> {args.output}/screen/comparison.csv, index.html")  # fmt: skip
    return 3 if s["counts"]["failed"] else 0
