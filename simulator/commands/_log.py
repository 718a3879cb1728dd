"""The ``--log FILE`` of every command: an output checked like the others, created only once the run's checks have passed.

A log is refused (InputError, exit 2, nothing written) when it names an input of the run
(the command line's files and every file the command reads, e.g. the traces and videos a
study manifest names), the command's output or a file inside its output folder, a folder,
or a file inside any folder holding a vimsim manifest (a folder vimsim writes). What the
command says is kept in memory until its first output is created (the moment its checks
have passed, :func:`simulator.core.fileio.before_output`) or it ends; only then is the log
checked again against every input read meanwhile and opened for appending. A run refused
as bad input before that leaves no log (nor any change to an existing one). A failed
write (a full disk) is an OSError naming the log.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import sys
from pathlib import Path

from simulator.core.errors import InputError

__all__ = ["LazyLog", "open_log"]


def _output_folders(args: argparse.Namespace, folder_commands) -> list[str]:
    """The folders the command writes into (or, for ``compare``, reads and updates)."""
    if args.command == "report":
        return [args.outdir] if getattr(args, "outdir", None) else []
    if args.command == "compare":
        keys = ("frames_dir", "golden_dir", "report")
        return [v for k in keys if isinstance(v := getattr(args, k, None), str) and v.strip()]
    if args.command in folder_commands or (
        args.command == "headpath" and getattr(args, "user", None) == "all"
    ):
        return [args.output] if getattr(args, "output", None) else []
    return []


def _within(path: Path, folder: str | None) -> bool:
    if folder is None or not str(folder).strip():
        return False
    try:
        path.relative_to(Path(folder).resolve())
        return True
    except ValueError:
        return False


def _manifest_folder(path: Path) -> Path | None:
    """The nearest folder above ``path`` holding a vimsim manifest, or None."""
    from simulator.core.fileio import MANIFEST_NAME

    for parent in path.parents:
        with contextlib.suppress(OSError):
            if (parent / MANIFEST_NAME).is_file():
                return parent
    return None


class LazyLog:
    """The log file of one run: text kept in memory until :meth:`open` (checks, then opens
    for appending and writes the header and what was said so far)."""

    def __init__(self, path: str, header: str, args: argparse.Namespace, folder_commands):
        self.path, self.header, self.args = path, header, args
        self.folder_commands = folder_commands
        self.fh = None
        self.failed = False
        self.inputs: list = []
        self._buf: list[str] = []

    def check(self, inputs=()) -> None:
        """InputError if the log may not be written (see the module text)."""
        from simulator.core.fileio import check_not_input

        path, args = self.path, self.args
        if not str(path).strip() or os.path.isdir(path):
            raise InputError(f"--log {path!r}: expected a file to append to, not a folder")
        outs = [getattr(args, k, None) for k in ("output", "plot")]
        try:
            check_not_input(path, [*inputs, *(o for o in outs if o)])
        except InputError:
            raise InputError(
                f"--log {path}: is an input or the output of this command; refusing to "
                "append to it (choose another log file)"
            ) from None
        real = Path(path).resolve()
        for folder in _output_folders(args, self.folder_commands):
            if _within(real, folder):
                raise InputError(
                    f"--log {path}: is inside the output folder {folder}; refusing to write "
                    "the log among the outputs (choose a log file outside it)"
                )
        held = _manifest_folder(real)
        if held is not None:
            raise InputError(
                f"--log {path}: is inside {held}, a folder vimsim writes (it holds a vimsim "
                "manifest); choose a log file outside it"
            )

    def open(self) -> None:
        """Check against every input read so far, then open and write what was said."""
        if self.fh is not None or self.failed:
            return
        from simulator.core.fileio import known_inputs

        self.check(known_inputs())
        try:
            self.fh = open(self.path, "a", encoding="utf-8", buffering=1)  # noqa: SIM115
        except OSError as e:
            self.failed = True
            raise InputError(f"--log {self.path}: cannot append ({e.strerror or e})") from None
        buf, self._buf = self._buf, []
        self.write(self.header + "".join(buf))

    def finish(self) -> None:
        """After a run that ended other than refused: open the log if it may be written
        (against the inputs recorded in :attr:`inputs`) so it gets what was said."""
        if self.fh is None and not self.failed:
            try:
                self.check(self.inputs)
                self.fh = open(self.path, "a", encoding="utf-8")  # noqa: SIM115
                self.fh.write(self.header + "".join(self._buf))
            except (InputError, OSError):
                self.failed = True
        self.close()

    def write(self, s: str) -> int:
        if self.failed:
            return len(s)
        if self.fh is None:
            self._buf.append(s)
            return len(s)
        try:
            self.fh.write(s)
        except OSError as e:
            self.failed = True
            self.close()
            raise OSError(e.errno, e.strerror or str(e), str(self.path)) from None
        return len(s)

    def flush(self) -> None:
        if self.fh is not None and not self.failed:
            try:
                self.fh.flush()
            except OSError as e:
                self.failed = True
                self.close()
                raise OSError(e.errno, e.strerror or str(e), str(self.path)) from None

    def close(self) -> None:
        fh, self.fh = self.fh, None
        if fh is not None:
            with contextlib.suppress(OSError):
                fh.close()


def open_log(args: argparse.Namespace, inputs: list[str], argv, folder_commands) -> LazyLog | None:
    """The run's :class:`LazyLog` (None without ``--log``), checked against the command
    line's inputs and outputs before any work; opened later (see the module text)."""
    path = getattr(args, "log", None)
    if path is None:
        return None
    from datetime import UTC, datetime

    cmd = " ".join(sys.argv[1:] if argv is None else map(str, argv))
    header = f"# {datetime.now(UTC):%Y-%m-%dT%H:%M:%SZ} vimsim {cmd}\n"
    log = LazyLog(path, header, args, folder_commands)
    log.check(inputs)
    return log
