"""The ``vimsim`` command line (also ``python -m simulator``).

One subcommand per job. Each lives in ``simulator/commands/<name>.py`` with two
functions: ``register(subparsers)`` adds its parser (light: no heavy imports) and
``run(args) -> int`` does the work (heavy imports inside). Exit status: 0 success,
2 bad input or usage (one line on stderr), 1 an environment error (disk full, read-only
or vanished folder, permission; one line naming the file and the OS error) or an
internal error (one line; ``VIMSIM_DEBUG=1`` shows the traceback), 130 / 143 after
SIGINT / SIGTERM (temporary files removed). Before any work the outputs are checked:
not empty, not a directory where a file is expected, not the same file as an input.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import os
import sys

from simulator.core.errors import InputError

__all__ = ["build_parser", "main"]

# Subcommand name -> module under simulator.commands. Order = order in --help.
COMMANDS: dict[str, str] = {
    "viewport": "viewport",
    "preprocess": "preprocess",
    "grid": "grid",
    "ego": "ego",
    "headpath": "headpath",
    "epof": "epof",
    "render": "render",
    "frames": "frames",
    "compare": "compare",
    "synth": "synth",
    "demo": "demo",
    "analyze": "analyze",
    "calibrate": "calibrate",
    "export": "export",
    "study": "study",
    "report": "report",
    "screen": "screen",
}


#: Commands whose ``-o`` is a folder (the rest write one file).
FOLDER_OUTPUTS = frozenset(
    {"render", "analyze", "demo", "frames", "export", "study", "report", "screen"}
)
#: Suffixes ``--plot`` / ``headpath plot -o`` may have (matplotlib writes these).
PLOT_SUFFIXES = (".png", ".pdf", ".svg", ".jpg", ".jpeg", ".tif", ".tiff", ".webp", ".eps", ".ps")
_OUTPUT_KEYS = ("output", "plot", "log")


def _inputs_named(args: argparse.Namespace) -> list[str]:
    """Every argument value (not an output) naming an existing file: the run's inputs."""
    found = []
    for key, val in vars(args).items():
        if key in _OUTPUT_KEYS or key in ("func", "command"):
            continue
        for v in val if isinstance(val, (list, tuple)) else [val]:
            if isinstance(v, str) and v.strip() and os.path.isfile(v):
                found.append(v)
    return found


def _check_outputs(args: argparse.Namespace, inputs: list[str]) -> None:
    """InputError before any work for an unusable output name (see the module text)."""
    from simulator.core.fileio import check_not_input, check_output_file

    out = getattr(args, "output", None)
    folder = args.command in FOLDER_OUTPUTS or (
        args.command == "headpath" and getattr(args, "user", None) == "all"
    )
    if folder:
        if out is not None:
            if str(out).strip() == "":
                raise InputError("output folder name is empty; give a folder, e.g. -o out")
            if os.path.exists(out) and not os.path.isdir(out):
                raise InputError(f"{out}: output folder is an existing file; expected a folder")
            check_not_input(out, inputs)
    elif out is not None:
        check_output_file(out, inputs)
        if args.command == "synth":
            base = out[: -len(os.path.splitext(out)[1])] if os.path.splitext(out)[1] else out
            check_output_file(base + ".truth.npz", inputs)
    plot = getattr(args, "plot", None)
    if args.command == "headpath" and getattr(args, "headpath_command", "") == "show":
        plot = out
    for p in [plot] if plot else []:
        if not str(p).lower().endswith(PLOT_SUFFIXES):
            raise InputError(
                f"{p}: plot suffix {os.path.splitext(p)[1] or '(none)'} cannot be written; "
                f"use one of {', '.join(PLOT_SUFFIXES)}"
            )
        if plot is not out:
            check_output_file(p, [*inputs, out] if out else inputs)


def _os_error_line(e: OSError) -> str:
    name = e.filename if e.filename is not None else None
    what = e.strerror or str(e) or type(e).__name__
    return f"{name}: {what}" if name else what


class _Parser(argparse.ArgumentParser):
    """ArgumentParser whose usage errors are one line and exit status 2."""

    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(2, f"{self.prog}: error: {message}\n")


def build_parser() -> argparse.ArgumentParser:
    """Build the parser with every available subcommand registered."""
    parser = _Parser(
        prog="vimsim",
        description="Viewport-aware optical flow in 360-degree video and granulated rest "
        "frames, headless. Angles are in degrees; positive yaw turns right, positive pitch "
        "looks up, positive roll tilts the head right ear down.",
    )
    from simulator import __version__

    parser.add_argument("--version", action="version", version=f"vimsim {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    for module in COMMANDS.values():
        importlib.import_module(f"simulator.commands.{module}").register(sub)
    _add_output_options(sub)
    return parser


def _add_output_options(sub: argparse._SubParsersAction) -> None:
    """``--quiet`` and ``--log FILE`` on every command (and subcommand)."""
    for p in sub.choices.values():
        g = p.add_argument_group("what the command says")
        g.add_argument(
            "--quiet",
            action="store_true",
            help="no progress bar, warnings or notes on the terminal: the result line and "
            "errors only (--log still gets everything)",
        )
        g.add_argument(
            "--log",
            metavar="FILE",
            default=None,
            help="also append everything the command says (result, warnings, notes, errors; "
            "no progress bars) to FILE",
        )
        for action in p._actions:
            if isinstance(action, argparse._SubParsersAction):
                _add_output_options(action)


#: BLAS threads of a vimsim process unless the user sets them: vimsim runs its work side by
#: side already (a decoding thread beside the flow, worker processes in a study), and
#: OpenBLAS's own threads spin-wait between its many small calls, taking the CPU those
#: need (sphere preprocess: ~25 % of its CPU time at 512x256, for no gain in wall time).
BLAS_THREADS = "1"


def _set_blas_threads() -> None:
    """``OPENBLAS_NUM_THREADS`` defaults to :data:`BLAS_THREADS`, before numpy loads; a
    value the user set wins, and so does a numpy already loaded (the library called
    in-process). OpenMP's setting is left alone (torch's neural flow uses it)."""
    if "numpy" not in sys.modules:
        os.environ.setdefault("OPENBLAS_NUM_THREADS", BLAS_THREADS)


def main(argv: list[str] | None = None) -> int:
    """Run the CLI; return the exit status (0 ok, 2 bad input/usage, 1 internal error)."""
    _set_blas_threads()
    parser = build_parser()
    args = parser.parse_args(argv)
    if getattr(args, "func", None) is None:  # bare `vimsim` (or `vimsim headpath`)
        sub = f" {args.command}" if getattr(args, "command", None) else ""
        print(
            f"usage: vimsim{sub} COMMAND ...\nvimsim{sub}: error: no command given; "
            f"`vimsim{sub} --help` lists the commands",
            file=sys.stderr,
        )
        return 2
    from simulator.commands._log import open_log
    from simulator.commands._signals import exit_status, handle_signals, signal_name
    from simulator.core.fileio import before_output, input_scope, known_inputs

    name = f"vimsim {args.command}"
    log = None
    refused = False
    saved = sys.stdout, sys.stderr
    try:
        with handle_signals():
            inputs = _inputs_named(args)
            with input_scope(inputs):
                _check_outputs(args, inputs)
                log = open_log(args, inputs, argv, FOLDER_OUTPUTS)
                if log is not None or getattr(args, "quiet", False):
                    from simulator.commands._progress import Tee

                    quiet = getattr(args, "quiet", False)
                    sys.stdout = Tee(saved[0], log)
                    sys.stderr = Tee(saved[1], log, quiet=quiet)
                from simulator.core.mapcache import deprecation_note

                if deprecation_note():
                    print(f"{name}: {deprecation_note()}", file=sys.stderr)
                try:
                    with before_output(log.open if log is not None else lambda: None):
                        rc = int(args.func(args) or 0)
                    if log is not None:
                        log.open()  # a run that wrote nothing (a dry run): checked now
                    return rc
                finally:
                    if log is not None:
                        log.inputs = known_inputs()
    except InputError as e:
        refused = log is None or log.fh is None  # refused before its checks passed: no log
        print(f"{name}: error: {_one_line(e)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"{name}: {signal_name()}; temporary files removed", file=sys.stderr)
        return exit_status()
    except MemoryError:
        print(
            f"{name}: error: out of memory (choose smaller sizes or fewer frames)", file=sys.stderr
        )
        return 1
    except OSError as e:
        print(f"{name}: error: {_one_line(_os_error_line(e))}", file=sys.stderr)
        return 1
    except Exception as e:
        if os.environ.get("VIMSIM_DEBUG"):
            raise
        print(
            f"{name}: internal error: {type(e).__name__}: {_one_line(e)[:300]} "
            "(VIMSIM_DEBUG=1 shows the traceback; please report it)",
            file=sys.stderr,
        )
        return 1
    finally:
        for s in (sys.stdout, sys.stderr):
            if s not in saved:
                with contextlib.suppress(OSError):  # a full disk under the log: said above
                    s.flush()
        sys.stdout, sys.stderr = saved
        if log is not None and refused:
            log.close()
        elif log is not None:
            log.finish()


#: The most characters of one word (a name, a value: often user text) a message quotes,
#: and of the whole message; longer ones are cut in the middle (``abc...xyz``).
WORD_MAX = 120
LINE_MAX = 600


def _excerpt(word: str, n: int) -> str:
    if len(word) <= n:
        return word
    keep = n - 3
    return f"{word[: keep - keep // 3]}...{word[len(word) - keep // 3 :]}"


def _one_line(e: object) -> str:
    """``e`` as one line quoting a bounded excerpt of any user text in it: every word at
    most :data:`WORD_MAX` characters, the line at most :data:`LINE_MAX`."""
    words = [_excerpt(w, WORD_MAX) for w in str(e).split()]
    return _excerpt(" ".join(words), LINE_MAX)


if __name__ == "__main__":
    sys.exit(main())
