"""SIGTERM and SIGINT for every command: both become KeyboardInterrupt, so temporary files are removed on the way out, and the exit status says which (130 / 143)."""

from __future__ import annotations

import contextlib
import signal
from collections.abc import Iterator

__all__ = ["exit_status", "handle_signals", "signal_name"]

_received: list[int] = []


def _handler(signum, frame):
    _received.append(signum)
    raise KeyboardInterrupt


@contextlib.contextmanager
def handle_signals() -> Iterator[None]:
    """Within it SIGTERM and SIGINT raise KeyboardInterrupt (cleanup runs in ``finally``
    and ``except BaseException`` blocks, e.g. :func:`simulator.core.fileio.atomic_output`)."""
    _received.clear()
    old = {}
    for s in (signal.SIGTERM, signal.SIGINT):
        try:
            old[s] = signal.signal(s, _handler)
        except ValueError:  # not the main thread: leave the defaults
            pass
    try:
        yield
    finally:
        for s, h in old.items():
            signal.signal(s, h)


def exit_status() -> int:
    """128 + the signal received (143 for SIGTERM), 130 for Ctrl-C or none recorded."""
    return 128 + (_received[-1] if _received else signal.SIGINT)


def signal_name() -> str:
    """``"terminated (SIGTERM)"`` or ``"interrupted (SIGINT)"``."""
    if _received and _received[-1] == signal.SIGTERM:
        return "terminated (SIGTERM)"
    return "interrupted (SIGINT)"
