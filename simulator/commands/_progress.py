"""Progress bars and warnings of the CLI: the talkative side of the quiet library."""

from __future__ import annotations

import contextlib
import sys
import warnings
from collections.abc import Iterator

__all__ = ["progress_bar", "warnings_to_stderr"]


@contextlib.contextmanager
def progress_bar(desc: str, *, unit: str = "frame", enabled: bool = True) -> Iterator:
    """A ``progress(done, total)`` callback drawing a tqdm bar on stderr (None if disabled)."""
    if not enabled:
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
                file=sys.stderr,
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
