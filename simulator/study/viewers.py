"""The viewers of a study manifest's ``[[viewings]]`` entry: trace files (a glob) or scripted viewers (``viewers = {kind, n, seed}``)."""

from __future__ import annotations

import glob
import re
from pathlib import Path

from simulator.study.entry import Entry

__all__ = ["SCRIPTED", "VIEWER_KINDS", "expand_traces", "scripted_viewers"]

_GLOB_CHARS = re.compile(r"[*?\[]")

_VIEWERS_KEYS = ("kind", "n", "seed")
#: Scripted viewers' head paths (``viewers = {kind = ...}``; keyframes needs a file).
VIEWER_KINDS: tuple[str, ...] = ("look-around", "sine", "sweep", "static")
#: ``ViewingSpec.format`` of a scripted viewer: ``synth:<kind>``, its seed in ``user``.
SCRIPTED = "synth:"


def scripted_viewers(
    e: Entry, vid: str, seen: dict, where: str, id_re: re.Pattern
) -> list[tuple[str, str, int, str]]:
    """``(id, participant, seed, kind)`` of each viewer of ``viewers = {kind = "look-around",
    n = 30, seed = 0}`` in the viewing entry ``e``: viewer k with seed ``seed + k - 1``, ids
    ``<video>-viewer<k>`` (or the ``id`` template with ``{video}``, ``{participant}``,
    ``{user}`` = k, ``{condition}``); each id is recorded in ``seen``."""
    for k in ("trace", "format", "user"):
        if k in e.t:
            e.fail(f"{k} and viewers are exclusive: scripted viewers have no trace file")
    v = Entry(e.m, f"{where}: viewers", e.t["viewers"], _VIEWERS_KEYS)
    kind = v.get("kind", (str,), "look-around")
    if kind not in VIEWER_KINDS:
        v.fail(f"unknown viewer kind {kind!r}; expected one of {', '.join(VIEWER_KINDS)}")
    n = v.number("n", 30, lo=1, hi=100_000, integer=True)
    seed = v.number("seed", 0, lo=0, integer=True)
    id_t, cond = e.get("id", (str,)), e.get("condition", (str,), "")
    out = []
    width = max(3, len(str(n)))
    for k in range(1, n + 1):
        f = {"video": vid, "participant": f"viewer{k:0{width}d}", "user": f"{k:0{width}d}",
             "stem": f"viewer{k:0{width}d}", "condition": cond}  # fmt: skip
        try:
            vw_id = id_t.format(**f) if id_t else f"{vid}-{f['participant']}"
        except (KeyError, IndexError, ValueError) as err:
            e.fail(f"bad template in id ({err}); fields: video, participant, user, condition")
        if not id_re.match(vw_id) or vw_id in seen:
            e.fail(f"viewing id {vw_id!r}: not a file name or used twice; give an id template")
        seen[vw_id] = where
        out.append((vw_id, f["participant"], int(seed) + k - 1, kind))
    return out


def expand_traces(e: Entry, pattern: str, base: Path) -> list[Path]:
    """The trace files of ``trace = PATTERN`` (a glob matching no file: a manifest error)."""
    pat = str(Path(pattern).expanduser())
    pat = pat if Path(pat).is_absolute() else str(base / pat)
    if not _GLOB_CHARS.search(pattern):
        return [Path(pat)]
    traces = [Path(p) for p in sorted(glob.glob(pat)) if Path(p).is_file()]
    if not traces:
        e.fail(f"trace glob {pattern!r} matches no file (relative to {base})")
    return traces
