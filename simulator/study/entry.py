"""Typed values of one manifest table, with errors naming the manifest and the entry, and user specs.

A user spec (``user = ...`` and ``render = ...`` of a ``[[viewings]]`` entry) is a number, a
list of numbers and ranges, a range such as ``"1-12"`` (or ``"1-3,7"``) or ``"all"``.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

from simulator.core.errors import InputError
from simulator.sphere.headsets import resolve_fov

__all__ = ["Entry", "render_users", "short_spec", "stem_fields", "user_numbers", "user_spans"]


class Entry:
    """Reads typed values from one table of the manifest; errors name manifest and entry."""

    def __init__(self, manifest: Path, where: str, table: object, allowed: tuple[str, ...]):
        self.m, self.where = manifest, where
        if not isinstance(table, dict):
            self.fail(f"expected a table, got {type(table).__name__}")
        self.t = table
        unknown = [k for k in table if k not in allowed]
        if unknown:
            self.fail(f"unknown key {unknown[0]!r}; expected one of {', '.join(allowed)}")

    def fail(self, msg: str):
        raise InputError(f"{self.m}: {self.where}: {msg}")

    def get(self, key, types, default=None, *, required=False, choices=None):
        if key not in self.t:
            if required:
                self.fail(f"key {key!r} missing")
            return default
        v = self.t[key]
        if isinstance(v, bool) and bool not in types:
            self.fail(f"{key} = {v!r}: expected {'/'.join(t.__name__ for t in types)}")
        if not isinstance(v, types):
            self.fail(f"{key} = {v!r}: expected {'/'.join(t.__name__ for t in types)}")
        if isinstance(v, float) and not math.isfinite(v):
            self.fail(f"{key} = {v!r}: expected a finite number")
        if choices is not None and v not in choices:
            self.fail(f"{key} = {v!r}: expected one of {', '.join(map(str, choices))}")
        return v

    def number(self, key, default=None, *, lo=None, hi=None, integer=False, lo_open=False):
        v = self.get(key, (int,) if integer else (int, float), default)
        if v is None:
            return None
        if (lo is not None and (v < lo or (lo_open and v == lo))) or (hi is not None and v > hi):
            rng = f"{'(' if lo_open else '['}{lo if lo is not None else '-inf'}, {hi if hi is not None else 'inf'}]"
            self.fail(f"{key} = {v!r}: expected a number in {rng}")
        return v if integer else float(v)

    def fov(self, default):
        try:
            return resolve_fov(
                headset=self.get("headset", (str,)),
                fov_deg=self.number("fov"),
                hfov_deg=self.number("hfov"),
                vfov_deg=self.number("vfov"),
                default=default,
            )
        except InputError as e:
            self.fail(str(e))

    def path(self, key, base: Path, *, required=True) -> Path | None:
        v = self.get(key, (str,), required=required)
        if v is None:
            return None
        p = Path(v).expanduser()
        return p if p.is_absolute() else base / p


_USER_PART = re.compile(r"^\s*(\d+)\s*(?:-\s*(\d+)\s*)?$")
_USER_HELP = 'expected a number >= 1, a list, a range such as "1-12" (or "1-3,7") or "all"'


def user_spans(e: Entry, key: str, value) -> list[tuple[int, int]]:
    """The ranges ``(first, last)`` a user spec names, in order, checked but never expanded
    (``"1-99999999999999999999"`` is one pair: bounds are checked before any list is made)."""
    spans: list[tuple[int, int]] = []
    for item in value if isinstance(value, list) else [value]:
        if isinstance(item, bool) or not isinstance(item, (int, str)):
            e.fail(f"{key} = {value!r}: {_USER_HELP}")
        parts = [item] if isinstance(item, int) else item.split(",")
        for part in parts:
            if isinstance(part, int):
                lo = hi = part
            else:
                mt = _USER_PART.match(part)
                if not mt:
                    e.fail(f"{key} = {value!r}: {_USER_HELP}")
                lo = int(mt.group(1))
                hi = int(mt.group(2)) if mt.group(2) else lo
                if hi < lo:
                    e.fail(f"{key} = {value!r}: range {part.strip()!r} is empty")
            if lo < 1:
                e.fail(f"{key} = {value!r}: {_USER_HELP}")
            spans.append((lo, hi))
    if not spans:
        e.fail(f"{key} = {value!r}: names no user; {_USER_HELP}")
    return spans


def user_numbers(e: Entry, key: str, value, *, n_users: int, where: str = "") -> list[int]:
    """The users a spec names, in order, without repeats, each checked against the
    ``n_users`` a file holds before the spec is expanded (a user beyond them: the entry's
    error, naming ``where`` and the file's range, in time independent of the spec's size)."""
    spans = user_spans(e, key, value)
    beyond = [max(lo, n_users + 1) for lo, hi in spans if hi > n_users]
    if beyond:
        held = f"users 1-{n_users}" if n_users > 1 else "one user (1)"
        e.fail(f"{where}no user {min(beyond)} ({key} = {short_spec(value)}); the file holds {held}")
    out: dict[int, None] = {}  # ordered, repeats dropped in linear time
    for lo, hi in spans:
        out.update(dict.fromkeys(range(lo, hi + 1)))
    return list(out)


def short_spec(value) -> str:
    """A spec as the manifest wrote it, cut to one readable line."""
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def stem_fields(trace: Path, user: int | None, n_users: int) -> dict:
    """The ``{stem}`` and ``{user}`` of a viewing's id template: the trace file's stem and
    the user's number, zero-padded to the width of the file's user count."""
    width = len(str(n_users)) if n_users > 1 else 1
    return {"stem": trace.stem, "user": "" if user is None else f"{user:0{width}d}"}


def render_users(e: Entry, render, users: list[int | None]) -> set:
    """Which of a viewing entry's users are rendered: ``render = true | false`` (all or
    none) or a user spec naming some of them."""
    if isinstance(render, bool):
        return set(users) if render else set()
    if users == [None]:
        e.fail(f"render = {render!r}: names users, but the trace holds one; use true or false")
    top = max(users)  # checked against the entry's users before the spec is expanded
    beyond = [max(lo, top + 1) for lo, hi in user_spans(e, "render", render) if hi > top]
    chosen = [] if beyond else user_numbers(e, "render", render, n_users=top)
    taken = set(users)
    missing = beyond or [u for u in chosen if u not in taken]
    if missing:
        e.fail(f"render = {short_spec(render)}: user {missing[0]} is not among this entry's users")
    return set(chosen)
