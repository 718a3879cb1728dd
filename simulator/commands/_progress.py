"""Progress bars, warnings, ``--quiet`` and ``--log FILE`` of the CLI: the talkative side of the quiet library.

Every command prints its result line on stdout and its diagnostics (warnings, notes,
errors) on stderr. A progress bar is drawn only on a terminal (never into a pipe or a
log file) and never with ``--quiet``. Where no bar is drawn (stderr a pipe or a file:
nohup, a cluster job, ``2> log``), long work writes a plain line instead,
``vimsim study: 12/48 tasks, elapsed 31 s, eta 93 s``, at most every
:data:`LINE_INTERVAL_S` seconds (and a last one when it ends, if it wrote any); ``--log``
receives those lines too, with or without a terminal. ``--quiet`` keeps the result line
and error lines and drops the other diagnostics; ``--log FILE`` appends everything the
command says (result, warnings, notes, errors, progress lines; no bars) to FILE as well.
"""

from __future__ import annotations

import contextlib
import io
import sys
import time
import warnings
from collections.abc import Iterator

__all__ = ["LINE_INTERVAL_S", "ProgressLines", "Tee", "progress_bar", "progress_stream", "warnings_to_stderr"]

#: Seconds between two plain progress lines (a stream that is not a terminal, and --log).
LINE_INTERVAL_S = 10.0


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


def _line_sink():
    """Where plain progress lines go: stderr when it is not a terminal (through the
    :class:`Tee`, so the log gets them too), the log alone when a bar is drawn on the
    terminal, None when there is a terminal and no log."""
    err = sys.stderr
    if isinstance(err, Tee):
        return err if (err.quiet or not err.terminal.isatty()) else err.log
    try:
        return None if err.isatty() else err
    except (AttributeError, ValueError):
        return None


class ProgressLines:
    """``progress(done, total, failed=0)`` writing ``"<desc>: k/n <unit>s, elapsed, eta"``
    lines to a stream, at most every ``interval_s`` seconds, and a last line at the end
    (when it wrote any): the progress of a command whose stderr is not a terminal."""

    def __init__(self, desc: str, unit: str, stream, *, interval_s: float = LINE_INTERVAL_S,
                 clock=time.monotonic):  # fmt: skip
        self.desc, self.unit, self.stream, self.interval_s = desc, unit, stream, interval_s
        self.clock = clock
        self.t0 = self.last = clock()
        self.wrote = False

    def __call__(self, done: int, total: int, failed: int = 0) -> None:
        now = self.clock()
        k = done + failed
        if total > 0 and k >= total:  # the end: a last line if any was written
            if self.wrote:
                self._write(k, total, failed, now)
            self.wrote = False  # a next step (the demo's stages) starts afresh
            return
        if now - self.last >= self.interval_s:
            self._write(k, total, failed, now)

    def _write(self, k: int, total: int, failed: int, now: float) -> None:
        el = now - self.t0
        eta = f"{el / k * (total - k):.0f} s" if 0 < k <= total else "?"
        extra = f" ({failed} failed)" if failed else ""
        self.stream.write(f"vimsim {self.desc}: {k}/{total} {self.unit}s{extra}, "
                          f"elapsed {el:.0f} s, eta {eta}\n")  # fmt: skip
        self.stream.flush()
        self.wrote, self.last = True, now


@contextlib.contextmanager
def progress_bar(desc: str, *, unit: str = "frame", enabled: bool = True) -> Iterator:
    """A ``progress(done, total, failed=0)`` callback: a tqdm bar on the terminal and/or
    plain lines (:class:`ProgressLines`) where there is no terminal and into ``--log``;
    None if disabled (``--no-progress``) or when nothing would be shown."""
    stream = progress_stream()
    sink = _line_sink()
    if not enabled or (stream is None and sink is None):
        yield None
        return
    lines = ProgressLines(desc, unit, sink) if sink is not None else None
    bar = None

    def cb(done: int, total: int, failed: int = 0) -> None:
        nonlocal bar
        if lines is not None:
            lines(done, total, failed)
        if stream is None:
            return
        from tqdm import tqdm

        if bar is not None and (total != bar.total or done + failed < bar.n):
            bar.close()  # a new step (e.g. the demo's next stage) starts a new bar
            bar = None
        if bar is None:
            bar = tqdm(total=total, initial=done + failed, unit=unit, desc=desc,
                       mininterval=0.5, dynamic_ncols=True, leave=False, file=stream)  # fmt: skip
        else:
            bar.update(done + failed - bar.n)
        if failed:
            bar.set_postfix_str(f"done {done}, failed {failed}", refresh=False)

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
