"""A JSON head log read entry by entry from the file, in blocks, so that a long log (one line of 100 MB) is never held as one string nor as one tree of Python objects.

The log is a top-level object keyed by timestamps (``{"20210510Z-200400_686Z": {...},
...}``) or a list of objects. :func:`json_entries` yields ``(key, value)`` per entry (key
None in a list), each value decoded by the standard library's decoder on its own; a caller
keeps what it needs of each entry (numbers) and drops the rest. Errors name the file and
the line as :func:`json.loads` would; a document nested too deeply is an InputError too.
"""

from __future__ import annotations

import json
import re
from collections.abc import Iterator
from pathlib import Path

from simulator.core.errors import InputError

__all__ = ["BLOCK_CHARS", "json_entries", "starts_as_json"]

#: Characters read at a time (a block grows to hold an entry longer than this).
BLOCK_CHARS = 1 << 20
_WS = re.compile(r"[ \t\n\r]*")
_DECODER = json.JSONDecoder()
_NUMBER_START, _AFTER_NUMBER = frozenset("-0123456789"), frozenset(" \t\n\r,]}")


def starts_as_json(p: Path) -> bool:
    """Whether the file's first non-blank character opens a JSON object or list."""
    with open(p, encoding="utf-8-sig", errors="replace") as fh:
        while True:
            chunk = fh.read(4096)
            if not chunk:
                return False
            s = chunk.lstrip()
            if s:
                return s[0] in "{["


class _Blocks:
    """The unread part of a text file, a block at a time, with the line it starts on."""

    def __init__(self, p: Path, fh):
        self.p, self.fh = p, fh
        self.buf, self.pos, self.eof, self.line = "", 0, False, 1

    def more(self) -> bool:
        """Append a block (at least as long as what is left: linear reads); False at EOF."""
        if self.eof:
            return False
        chunk = self.fh.read(max(BLOCK_CHARS, len(self.buf) - self.pos))
        if not chunk:
            self.eof = True
            return False
        self.line += self.buf.count("\n", 0, self.pos)
        self.buf, self.pos = self.buf[self.pos :] + chunk, 0
        return True

    def fail(self, msg: str, pos: int | None = None):
        at = self.pos if pos is None else pos
        line = self.line + self.buf.count("\n", 0, at)
        raise InputError(f"{self.p}: not valid JSON (line {line}: {msg})")

    def peek(self) -> str:
        """The next non-blank character, not consumed ('' at the end of the file)."""
        while True:
            self.pos = _WS.match(self.buf, self.pos).end()
            if self.pos < len(self.buf) or not self.more():
                return self.buf[self.pos] if self.pos < len(self.buf) else ""

    def expect(self, chars: str, what: str) -> str:
        c = self.peek()
        if not c or c not in chars:
            self.fail(f"Expecting {what}")
        self.pos += 1
        return c

    def value(self):
        """The next JSON value, decoded whole (read on while it runs past the block)."""
        self.peek()
        while True:
            try:
                v, end = _DECODER.raw_decode(self.buf, self.pos)
            except json.JSONDecodeError as e:
                if not self.more():
                    self.fail(e.msg, e.pos)
                continue
            # a number the block cut ("2." of "2.5") is read on until a delimiter follows
            whole = end < len(self.buf) and (
                self.buf[self.pos] not in _NUMBER_START or self.buf[end] in _AFTER_NUMBER
            )
            if whole or not self.more():
                self.pos = end
                return v


def json_entries(p: Path) -> Iterator[tuple[str | None, object]]:
    """``(key, value)`` of each entry of the JSON log ``p`` (key None for a list's items);
    InputError naming the file for invalid JSON or nesting too deep."""
    with open(p, encoding="utf-8-sig", errors="replace") as fh:
        b = _Blocks(p, fh)
        try:
            yield from _entries(b)
        except RecursionError:
            raise InputError(f"{p}: JSON nested too deeply") from None


def _entries(b: _Blocks) -> Iterator[tuple[str | None, object]]:
    keyed = b.expect("{[", "'{' or '['") == "{"
    close = "}" if keyed else "]"
    if b.peek() == close:
        b.pos += 1
    else:
        while True:
            key = None
            if keyed:
                if b.peek() != '"':
                    b.fail("Expecting property name enclosed in double quotes")
                key = b.value()
                b.expect(":", "':' delimiter")
            yield key, b.value()
            if b.expect("," + close, "',' delimiter") == close:
                break
    if b.peek():
        b.fail("Extra data")
