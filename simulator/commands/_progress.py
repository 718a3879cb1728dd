"""Progress bars, warnings, ``--quiet`` and ``--log FILE`` of the CLI: the talkative side of the quiet library.

Every command prints its result line on stdout and its diagnostics (warnings, notes,
errors) on stderr. A progress bar is drawn only on a terminal (never into a pipe or a
log file) and never with ``--quiet``. ``--quiet`` keeps the result line and error lines
and drops the other diagnostics; ``--log FILE`` appends everything the command says
(result, warnings, notes, errors; no progress bars) to FILE as well.
"""

from __future__ import annotations

import contextlib
import io
import sys
import warnings
from collections.abc import Iterator

__all__ = ["Tee", "progress_bar", "progress_stream", "warnings_to_stderr"]


class Tee(io.TextIOBase):
    """A stdout/stderr stand-in: writes to the terminal stream (all of it, or with
    ``quiet`` only lines that report an error or a failure) and to an open log file."""

    def __init__(self, terminal, log=None, *, quiet: bool = False):
        self.terminal, self.log, self.quiet = terminal, log, quiet
        self._line = ""

    def write(self, s: str) -> int:
        if self.log is not None:
            self.log.write(s)
        if not self.quiet:
            self.terminal.write(s)
            return len(s)
        self._line += s
        *lines, self._line = self._line.split("\n")
        for ln in lines:
            low = ln.lower()
            if "error" in low or "failed" in low or "fail " in low:
                self.terminal.write(ln + "\n")
        return len(s)

    def flush(self) -> None:
        self.terminal.flush()
        if self.log is not None:
            self.log.flush()

    def isatty(self) -> bool:
        return False if self.quiet else self.terminal.isatty()

    def writable(self) -> bool:
        return True


def progress_stream():
    """The stream a progress bar may draw on: the terminal behind stderr, or None when
    stderr is not a terminal (a pipe, a file) or ``--quiet`` is given."""
    err = sys.stderr
    if isinstance(err, Tee):
        return None if err.quiet or not err.terminal.isatty() else err.terminal
    try:
        return err if err.isatty() else None
    except (AttributeError, ValueError):
        return None


@contextlib.contextmanager
def progress_bar(desc: str, *, unit: str = "frame", enabled: bool = True) -> Iterator:
    """A ``progress(done, total)`` callback drawing a tqdm bar on the terminal (None if
    disabled, or when stderr is not a terminal: :func:`progress_stream`)."""
    stream = progress_stream()
    if not enabled or stream is None:
        yield None
        return
    from tqdm import tqdm

    bar = None

    def cb(done: int, total: int) -> None:
        nonlocal bar
        if bar is not None and (total != bar.total or done < bar.n):
            bar.close()  # a new step (e.g. the demo's next stage) starts a new bar
            bar = None
        if bar is None:
            bar = tqdm(
                total=total,
                initial=done,
                unit=unit,
                desc=desc,
                mininterval=0.5,
                dynamic_ncols=True,
                leave=False,
                file=stream,
            )
        else:
            bar.update(done - bar.n)

    try:
        yield cb
    finally:
        if bar is not None:
            bar.close()


@contextlib.contextmanager
def warnings_to_stderr(prog: str) -> Iterator[None]:
    """Print each warning the library raises as one line ``<prog>: warning: ...`` on stderr."""
    with warnings.catch_warnings():
        warnings.simplefilter("always")
        # Third-party deprecations are for developers, not users of the CLI.
        warnings.simplefilter("ignore", DeprecationWarning)
        warnings.simplefilter("ignore", PendingDeprecationWarning)
        warnings.showwarning = lambda msg, *a, **k: print(
            f"{prog}: warning: {msg}", file=sys.stderr
        )
        yield
