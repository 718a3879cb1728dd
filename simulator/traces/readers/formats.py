"""How a head-trace reader declares its formats: a name, how to recognise a file, how to read it.

Each reader module lists its :class:`TraceFormat` entries in ``TRACE_FORMATS``; the package
(``simulator/traces/readers/__init__.py``) gathers them in one registry, and
:func:`~simulator.traces.readers.detect_format` asks each format's ``sniff`` in ``rank``
order. A new head-trace format is thus one new reader module plus one entry in that
registry (and its name in :data:`simulator.core.choices.HEADPATH_FORMATS`, which the CLI
offers without importing the readers).
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from simulator.traces.path import HeadPath

__all__ = ["Sniff", "TraceFormat"]


class Sniff:
    """What detection looks at: the first non-empty line, its lower-cased tokens, and (read
    lazily, once) the first 64 KiB of the text."""

    def __init__(self, path: Path, head: str):
        self.path, self.head = path, head
        low = head.lower()
        for ch in ',"\';':
            low = low.replace(ch, " ")
        self.tokens = frozenset(low.split())

    @functools.cached_property
    def text(self) -> str:
        with open(self.path, encoding="utf-8-sig", errors="replace") as fh:
            return fh.read(1 << 16)

    @property
    def is_json(self) -> bool:
        return self.head.startswith(("{", "["))

    def has(self, *tokens: str) -> bool:
        """Whether the first line holds every one of ``tokens`` (lower case)."""
        return set(tokens) <= self.tokens


@dataclass(frozen=True)
class TraceFormat:
    """One head-trace format.

    ``read(path, video=None, user=None)`` gives the :class:`HeadPath` (``video``/``user``
    select a trace of files holding several); ``sniff(Sniff)`` says whether a file is of
    this format; ``rank`` orders detection (lower first: a more specific format before a
    more general one). ``read_all(path)`` (files of many users) gives ``{user: HeadPath}``
    and ``count_users(path)`` counts them without parsing; both None for one-trace formats.
    """

    name: str
    read: Callable[..., HeadPath]
    sniff: Callable[[Sniff], bool]
    rank: int = 50
    read_all: Callable[[Path], dict[int, HeadPath]] | None = None
    count_users: Callable[[Path], int] | None = None
