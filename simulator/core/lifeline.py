"""Worker processes that end with the command that started them: a parent-death signal, and a check of the parent before each task and each output.

A pool worker calls :func:`watch_parent` once, in its initializer. On Linux the kernel
then kills it (``SIGKILL``, ``prctl(PR_SET_PDEATHSIG)``) the moment its parent process
dies, even by ``kill -9`` (the fork server of a local pool exits when the command's
process is gone, so its workers follow within a moment). Where there is no such signal
(another platform, ``prctl`` refused), :func:`exit_if_orphaned` -- called before each task
and before each output file is created or renamed into place -- ends a worker whose
parent has changed, so an orphan never writes into the output folder. Outside a worker
(nothing watched) both are no-ops.
"""

from __future__ import annotations

import ctypes
import os
import signal
import sys

__all__ = ["exit_if_orphaned", "orphaned", "watch_parent"]

#: ``[parent pid, command pid]`` this process watches; empty: not a worker.
_WATCHED: list[int] = []
#: ``prctl`` option number of the parent-death signal (linux/prctl.h).
_PR_SET_PDEATHSIG = 1
#: Exit status of a worker that ends because its command is gone.
ORPHAN_STATUS = 1


def _set_parent_death_signal(sig: int) -> bool:
    """Ask the kernel to send ``sig`` when the parent process dies (Linux only)."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        return libc.prctl(_PR_SET_PDEATHSIG, int(sig), 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # exists, another user's: alive
        return True
    return True


def watch_parent(command_pid: int | None = None) -> bool:
    """In a freshly started worker: die with the parent process from now on.

    ``command_pid``: the process of the command that made the pool (the parent itself, or
    its fork server's parent); a worker that starts after it is gone exits at once.
    Returns whether the kernel's parent-death signal is set (else only the checks of
    :func:`exit_if_orphaned` guard)."""
    parent = os.getppid()
    _WATCHED[:] = [parent, command_pid if command_pid is not None else parent]
    armed = _set_parent_death_signal(signal.SIGKILL)
    exit_if_orphaned()  # the parent died before the signal was armed
    return armed


def orphaned() -> bool:
    """Whether this worker's parent or command process is gone (False outside a worker)."""
    if not _WATCHED:
        return False
    parent, command = _WATCHED
    return os.getppid() != parent or not _alive(command)


def exit_if_orphaned(cleanup=None) -> None:
    """End this worker at once, writing nothing more, if its command is gone; ``cleanup()``
    first (e.g. remove the temporary file about to be renamed into place)."""
    if orphaned():
        if cleanup is not None:
            cleanup()
        os._exit(ORPHAN_STATUS)
