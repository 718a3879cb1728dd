"""``vimsim headpath``: scripted head paths, dataset conversion, plots.

``synth KIND -o PATH.csv --seconds S``, ``convert IN -o PATH.csv [--format ...]``,
``show PATH.csv -o PLOT.png``. Angles in degrees: positive yaw turns right, positive
pitch looks up, positive roll tilts the head right ear down.
"""

from __future__ import annotations

import argparse
import sys

from simulator.commands._progress import warnings_to_stderr
from simulator.commands._types import finite_float, nonneg_int, number, positive_float
from simulator.core.choices import SYNTH_KINDS

__all__ = ["add_reader_options", "load_headpath_args", "print_warnings", "register", "run", "trace_options"]


_user = number("expected a user number >= 1", "1", integer=True, lo=1)


def _user_or_all(text: str) -> int | str:
    return "all" if text == "all" else _user(text)


def add_reader_options(
    p: argparse.ArgumentParser, *, allow_all: bool = False, exclude: tuple[str, ...] = ()
) -> None:
    """The trace options (:data:`simulator.core.traceopts.TRACE_OPTIONS`, the one table the
    study manifest's trace keys come from too) as argparse options, for every command that
    reads a head path (``vimsim headpath``, ``epof``, ``render``, ``frames``); ``allow_all``:
    ``--user all``; ``exclude``: keys this command has no use for."""
    from simulator.core.traceopts import TRACE_OPTIONS

    g = p.add_argument_group("head trace (the same keys in a study manifest's [traces] table)")
    for o in TRACE_OPTIONS:
        if o.key in exclude:
            continue
        kw: dict = {"default": o.default, "help": o.help.replace("%", "%%")}
        if o.kind == "flag":
            kw["action"] = "store_true"
        elif o.kind == "choice":
            kw["choices"] = o.choices
        else:
            kw["metavar"] = o.metavar
            kw["type"] = _ARG_TYPES[o.kind](o)
        if o.key == "user" and allow_all:
            kw.update(type=_user_or_all, metavar="N|all", help=o.help + "; all = every user, "
                      "one CSV each into the folder -o DIR (the file is read once)")  # fmt: skip
        g.add_argument(o.flag, **kw)


def _number_type(o):
    if o.lo is None:
        return finite_float
    op = ">" if o.lo_open else ">="
    return number(f"expected a number {op} {o.lo:g}", "0.001", lo=o.lo, lo_open=o.lo_open)


_ARG_TYPES = {
    "str": lambda o: str,
    "float": _number_type,
    "int": lambda o: nonneg_int,
    "user": lambda o: _user,
}


def trace_options(args: argparse.Namespace):
    """The :class:`simulator.core.traceopts.TraceOptions` of parsed ``args`` (options a
    command lacks take their defaults); InputError for a contradictory set."""
    from simulator.core.traceopts import TraceOptions

    return TraceOptions.from_values(lambda k, d: getattr(args, k, d))


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``headpath`` parser and its ``synth``, ``convert`` and ``show`` subcommands."""
    p = subparsers.add_parser(
        "headpath",
        help="make, convert and plot head paths (time_s,yaw_deg,pitch_deg,roll_deg CSV)",
        description="Head paths: scripted (synth), converted from recorded datasets (convert) "
        "or plotted (show). Canonical CSV: time_s,yaw_deg,pitch_deg,roll_deg; degrees, positive "
        "yaw turns right, positive pitch looks up, positive roll = right ear down.",
    )
    sub = p.add_subparsers(dest="headpath_command", metavar="ACTION", parser_class=type(p))
    p.set_defaults(func=lambda args: (p.print_help(sys.stderr), 2)[1])

    s = sub.add_parser(
        "synth",
        help="a scripted head path",
        description=(
            "Write a scripted head path. static: fixed --yaw/--pitch/--roll. sweep: yaw turns at "
            "--yaw-rate deg/s. sine: --yaw-amp/--yaw-freq, --pitch-amp/--pitch-freq around "
            "--yaw/--pitch. look-around: seeded random exploration tuned to real viewers' speed "
            "statistics. keyframes: --keyframes FILE (JSON or CSV of time_s,yaw_deg,pitch_deg,"
            "roll_deg), Slerp between them."
        ),
    )
    s.add_argument("kind", choices=SYNTH_KINDS, metavar="KIND", help=", ".join(SYNTH_KINDS))
    s.add_argument("-o", "--output", required=True, metavar="PATH.csv")
    s.add_argument(
        "--seconds",
        type=positive_float,
        default=None,
        metavar="S",
        help="duration in seconds (required except for keyframes: default = last keyframe)",
    )
    s.add_argument(
        "--rate",
        type=positive_float,
        default=60.0,
        metavar="HZ",
        help="samples per second (default 60)",
    )
    s.add_argument(
        "--seed", type=nonneg_int, default=0, metavar="N", help="random seed >= 0 (look-around)"
    )
    s.add_argument(
        "--yaw",
        type=finite_float,
        default=None,
        metavar="D",
        help="yaw in degrees (static, start of sweep, centre of sine); + turns right",
    )
    s.add_argument(
        "--pitch",
        type=finite_float,
        default=None,
        metavar="D",
        help="pitch in degrees; + looks up (e.g. -70 stares at the ground)",
    )
    s.add_argument(
        "--roll",
        type=finite_float,
        default=None,
        metavar="D",
        help="roll in degrees; + right ear down",
    )
    s.add_argument(
        "--yaw-rate",
        type=finite_float,
        default=None,
        metavar="DPS",
        help="sweep: yaw speed in deg/s (default 30; negative turns left)",
    )
    s.add_argument(
        "--yaw-amp",
        type=finite_float,
        default=None,
        metavar="D",
        help="sine: yaw amplitude (default 60)",
    )
    s.add_argument(
        "--yaw-freq",
        type=finite_float,
        default=None,
        metavar="HZ",
        help="sine: yaw frequency (default 0.1)",
    )
    s.add_argument(
        "--pitch-amp",
        type=finite_float,
        default=None,
        metavar="D",
        help="sine: pitch amplitude (default 20)",
    )
    s.add_argument(
        "--pitch-freq",
        type=finite_float,
        default=None,
        metavar="HZ",
        help="sine: pitch frequency (default 0.15)",
    )
    s.add_argument(
        "--keyframes",
        default=None,
        metavar="FILE",
        help="keyframes: JSON list or CSV of time_s,yaw_deg,pitch_deg[,roll_deg]",
    )
    s.set_defaults(func=run, headpath_command="synth")

    c = sub.add_parser(
        "convert",
        help="convert a recorded trace to the canonical CSV",
        description="Read a head path (canonical CSV, quaternion CSV, Corbillon "
        "MMSys'18, Salient360 raw, AVTrack360 JSON, 360VidStr aggregated) and "
        "write the canonical CSV in our conventions.",
    )
    c.add_argument("input", metavar="IN")
    c.add_argument(
        "-o",
        "--output",
        required=True,
        metavar="PATH.csv",
        help="output CSV (a folder with --user all)",
    )
    add_reader_options(c, allow_all=True, exclude=("hold_last",))
    c.set_defaults(func=run, headpath_command="convert")

    w = sub.add_parser(
        "show",
        help="plot yaw/pitch/roll over time",
        description="Plot a head path's yaw, pitch and roll (degrees) over time.",
    )
    w.add_argument("input", metavar="PATH.csv")
    w.add_argument("-o", "--output", required=True, metavar="PLOT.png")
    add_reader_options(w, exclude=("hold_last",))
    w.set_defaults(func=run, headpath_command="show")


def load_headpath_args(args: argparse.Namespace, path, prog: str, video_s: float | None = None,
                       video: str = "", notes: list | None = None):  # fmt: skip
    """Load the head path ``path`` with the trace options in ``args`` (missing ones =
    defaults; :func:`simulator.traces.clock.read_trace`), reader warnings printed as
    ``<prog>: warning: ...`` on stderr; its span checked against a video of ``video_s``
    seconds (None: only the one-day limit; :func:`simulator.traces.clock.check_span`), the
    span warnings appended to ``notes`` (printed by the caller once its work is done; None:
    printed now). InputError on bad input."""
    from simulator.traces.clock import check_span, read_trace

    _check_columns_without_user(args)  # not silently ignored
    opts = trace_options(args)
    with warnings_to_stderr(prog):
        hp = read_trace(path, opts)
        found = check_span(hp, video_s, opts, video=video, warn=notes is None)
    if notes is not None:
        notes.extend(found)
    return hp


def _check_columns_without_user(args: argparse.Namespace) -> None:
    """InputError for ``--columns`` with ``--user``: a column map reads the one trace of a
    lab log; ``--user`` picks one of a multi-user (360VidStr) file's and would be ignored."""
    from simulator.core.errors import InputError

    user = getattr(args, "user", None)
    if getattr(args, "columns", None) and user is not None:
        raise InputError(
            f"--columns with --user {user}: a column map reads the one head path of a lab log; "
            "--user picks a user of a 360VidStr file (use one or the other)"
        )


def print_warnings(prog: str, notes: list[str]) -> None:
    """``<prog>: warning: <note>`` on stderr for each of ``notes`` (after the work)."""
    for n in notes:
        print(f"{prog}: warning: {n}", file=sys.stderr)


def run(args: argparse.Namespace) -> int:
    """Run ``headpath synth|convert|show``; 0 on success, InputError -> exit 2."""
    from simulator.core.errors import InputError
    from simulator.traces import path as hp_mod
    from simulator.traces.readers import load_keyframes

    with warnings_to_stderr("vimsim headpath"):
        if args.headpath_command == "synth":
            params = {
                "yaw": args.yaw,
                "pitch": args.pitch,
                "roll": args.roll,
                "yaw_rate": args.yaw_rate,
                "yaw_amp": args.yaw_amp,
                "yaw_freq": args.yaw_freq,
                "pitch_amp": args.pitch_amp,
                "pitch_freq": args.pitch_freq,
            }
            if args.kind == "keyframes":
                params = {"keyframes": load_keyframes(args.keyframes)}
            elif args.seconds is None:
                raise InputError(f"synth {args.kind}: --seconds is required")
            hp = hp_mod.synth(
                args.kind, args.seconds or 0.0, rate_hz=args.rate, seed=args.seed, **params
            )
            hp_mod.save_headpath_csv(args.output, hp)
            print(f"wrote {args.output}: {hp.n} samples, {hp.end_s:.3f} s")
            return 0
        if args.headpath_command == "convert" and args.user == "all":
            _check_columns_without_user(args)  # not silently ignored
            return _convert_all(args)
        hp = load_headpath_args(args, args.input, "vimsim headpath")
        if args.headpath_command == "convert":
            hp_mod.save_headpath_csv(args.output, hp)
            print(f"wrote {args.output}: {hp.n} samples, {hp.start_s:.3f}..{hp.end_s:.3f} s")
            return 0
        hp_mod.plot_headpath(args.output, hp)
        print(f"wrote {args.output}")
        return 0


def _convert_all(args: argparse.Namespace) -> int:
    """``convert IN --user all -o DIR``: every user of IN, read once, as DIR/<stem>_user<N>.csv."""
    from pathlib import Path

    from simulator.core.errors import InputError
    from simulator.core.fileio import OutputFolder, check_not_input
    from simulator.traces.path import save_headpath_csv
    from simulator.traces.readers import load_all_users

    src = Path(args.input)
    out = Path(args.output)
    if out.exists() and not out.is_dir():
        raise InputError(
            f"{out}: --user all writes one CSV per user into a folder; {out} is a file"
        )
    from simulator.traces.clock import check_span, place

    opts = trace_options(args)
    if opts.columns:
        raise InputError("--user all reads a file of many users (360VidStr); a column map "
                         "reads one trace: drop --user all")  # fmt: skip
    with warnings_to_stderr("vimsim headpath"):
        users = {u: place(hp, opts) for u, hp in load_all_users(src, args.format).items()}
        for hp in users.values():
            check_span(hp, None, opts)
    width = len(str(max(users)))
    targets = {u: out / f"{src.stem}_user{u:0{width}d}.csv" for u in users}
    for t in targets.values():
        check_not_input(t, [src])  # one line, exit 2: an output would replace the input
    # The one folder rule: a CSV of an output name that no earlier run wrote is refused.
    folder = OutputFolder(out, [t.name for t in targets.values()], "headpath convert")
    folder.prepare([src])
    for u, hp in users.items():
        save_headpath_csv(targets[u], hp)
    folder.complete()
    print(f"wrote {len(users)} head paths to {out}/ ({src.stem}_user{1:0{width}d}.csv ..)")
    return 0
