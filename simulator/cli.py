"""The ``vimsim`` command line (also ``python -m simulator``).

One subcommand per job. Each lives in ``simulator/commands/<name>.py`` with two
functions: ``register(subparsers)`` adds its parser (light: no heavy imports) and
``run(args) -> int`` does the work (heavy imports inside). Exit status: 0 success,
2 bad input or usage (one line on stderr), 1 internal error.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from simulator.errors import InputError

__all__ = ["build_parser", "main"]

# Subcommand name -> module under simulator.commands. Order = order in --help.
COMMANDS: dict[str, str] = {
    "viewport": "viewport",
    "preprocess": "preprocess",
    "headpath": "headpath",
    "epof": "epof",
    "render": "render",
    "synth": "synth",
    "demo": "demo",
    "analyze": "analyze",
    "study": "study",
}


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
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run the CLI; return the exit status (0 ok, 2 bad input/usage, 1 internal error)."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if getattr(args, "func", None) is None:
        parser.print_help(sys.stderr)
        return 2
    try:
        return int(args.func(args) or 0)
    except InputError as e:
        print(f"vimsim {args.command}: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"vimsim {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
