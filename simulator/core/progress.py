"""Progress reporting of long library calls: a ``progress(done, total)`` callback and a counter that feeds it.

The library never draws a bar itself (it is quiet); the CLI passes a callback that does
(:func:`simulator.commands._progress.progress_bar`), tests and benches pass ``None``.
"""

from __future__ import annotations

from collections.abc import Callable

__all__ = ["Counter", "Progress"]

#: ``progress(done, total)``: called with the units (frames, tasks) done so far and the total.
Progress = Callable[[int, int], None]


class Counter:
    """Counts units of work and reports each change to an optional :data:`Progress` callback."""

    def __init__(self, progress: Progress | None, total: int, done: int = 0):
        self.progress = progress or None
        self.total = int(total)
        self.done = int(done)
        if self.progress is not None:
            self.progress(self.done, self.total)

    def update(self, n: int = 1) -> None:
        self.done += int(n)
        if self.progress is not None:
            self.progress(self.done, self.total)

    def close(self) -> None:
        """Nothing to release; kept so callers can treat it like a bar."""
