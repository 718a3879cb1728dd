"""A lab's ratings file (``RATINGS.csv``) read and checked: one rated video or viewing a row.

Columns (header row first; lines starting with ``#`` are comments)::

    video,rating[,group][,trace][,participant]

- ``video``: the rated video's path, relative to the CSV's folder (or absolute).
- ``rating``: a finite number (a MOS, a discomfort score, an SSQ total: any scale, the
  model predicts in it).
- ``group`` (optional): the content or scene. Cross-validation holds whole groups out,
  so a model is judged on content it has not seen. Every row needs one when the column
  is there; at least :data:`MIN_GROUPS` groups.
- ``trace`` (optional): the viewer's head path (any format ``vimsim headpath`` reads),
  relative to the CSV; the row's features are then those of that viewing. An empty cell
  = the video's features.
- ``participant`` (optional): who rated, kept to tell rows apart.

At least :data:`MIN_VIDEOS` distinct videos. A duplicate row (the same video, trace and
participant twice) is refused. Every problem is one line naming the file, the row (its
line number in the file) and the problem (:class:`simulator.core.errors.InputError`).
"""

from __future__ import annotations

import csv
import hashlib
import io
import math
import os
from dataclasses import dataclass
from pathlib import Path

from simulator.core.errors import InputError
from simulator.core.fileio import check_input_file

__all__ = ["COLUMNS", "MIN_GROUPS", "MIN_VIDEOS", "Rating", "Ratings", "read_ratings"]

#: The columns a ratings file may have (``video`` and ``rating`` required).
COLUMNS: tuple[str, ...] = ("video", "rating", "group", "trace", "participant")
#: Fewest distinct videos a model is fitted on.
MIN_VIDEOS = 8
#: Fewest groups when the file has a ``group`` column.
MIN_GROUPS = 3


@dataclass(frozen=True)
class Rating:
    """One row: the ``video`` (resolved path), its ``rating``, the ``group`` (or None),
    the viewer's ``trace`` (resolved path, or None), ``participant`` ("" if none) and
    the file's ``line`` number."""

    video: Path
    rating: float
    group: str | None
    trace: Path | None
    participant: str
    line: int


@dataclass(frozen=True)
class Ratings:
    """The rows of a ratings file, its ``path``, whether it is ``grouped`` and the SHA-256
    of its bytes (``csv_hash``)."""

    path: Path
    rows: tuple[Rating, ...]
    grouped: bool
    csv_hash: str

    @property
    def videos(self) -> list[Path]:
        """The distinct videos, in first-seen order."""
        return list(dict.fromkeys(r.video for r in self.rows))


def _lines(p: Path) -> tuple[list[str], list[tuple[int, list[str]]], str]:
    raw = p.read_bytes()
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        raise InputError(f"{p}: ratings file is not UTF-8 text") from None
    body = [(i + 1, ln) for i, ln in enumerate(text.splitlines()) if ln.strip()]
    body = [(i, ln) for i, ln in body if not ln.lstrip().startswith("#")]
    if not body:
        raise InputError(f"{p}: ratings file has no header; expected {','.join(COLUMNS[:2])},...")
    rows = []
    for n, cells in zip(
        (i for i, _ in body), csv.reader(io.StringIO("\n".join(ln for _, ln in body))), strict=True
    ):
        rows.append((n, [c.strip() for c in cells]))
    header = [c.lower() for c in rows[0][1]]
    return header, rows[1:], "sha256:" + hashlib.sha256(raw).hexdigest()


def _check_header(p: Path, header: list[str]) -> None:
    unknown = [c for c in header if c not in COLUMNS]
    if unknown:
        raise InputError(
            f"{p}: row 1: unknown column(s) {', '.join(unknown)}; expected {', '.join(COLUMNS)}"
        )
    missing = [c for c in COLUMNS[:2] if c not in header]
    if missing:
        raise InputError(f"{p}: row 1: column(s) {', '.join(missing)} missing; found {header}")
    if len(set(header)) != len(header):
        raise InputError(f"{p}: row 1: a column is named twice: {header}")


def _file(p: Path, line: int, base: Path, value: str, what: str) -> Path:
    if not value:
        raise InputError(f"{p}: row {line}: {what} is empty")
    f = Path(value) if os.path.isabs(value) else base / value
    try:
        return check_input_file(f, what)
    except InputError as e:
        raise InputError(f"{p}: row {line}: {e}") from None


def _row(p: Path, base: Path, header: list[str], line: int, cells: list[str]) -> Rating:
    if len(cells) != len(header):
        raise InputError(f"{p}: row {line}: {len(cells)} cells; the header has {len(header)}")
    c = dict(zip(header, cells, strict=True))
    try:
        rating = float(c["rating"])
    except ValueError:
        rating = math.nan
    if not math.isfinite(rating):
        raise InputError(f"{p}: row {line}: rating {c['rating']!r} is not a finite number")
    group = c.get("group")
    if group is not None and not group:
        raise InputError(f"{p}: row {line}: group is empty (every row needs one)")
    video = _file(p, line, base, c["video"], "video")
    trace = _file(p, line, base, c["trace"], "trace") if c.get("trace") else None
    return Rating(video, rating, group, trace, c.get("participant", ""), line)


def read_ratings(path: str | os.PathLike) -> Ratings:
    """Read and check a ratings file (module docstring); InputError naming the file, the
    row and the problem."""
    p = check_input_file(path, "ratings")
    header, rows, digest = _lines(p)
    _check_header(p, header)
    base = p.resolve().parent
    out, seen = [], {}
    for line, cells in rows:
        r = _row(p, base, header, line, cells)
        key = (r.video.resolve(), r.trace.resolve() if r.trace else None, r.participant)
        if key in seen:
            raise InputError(f"{p}: row {line}: duplicate of row {seen[key]} (same video, "
                             "trace and participant)")  # fmt: skip
        seen[key] = line
        out.append(r)
    n_videos = len({r.video.resolve() for r in out})
    if n_videos < MIN_VIDEOS:
        raise InputError(
            f"{p}: {n_videos} rated video(s); a model needs at least {MIN_VIDEOS} distinct videos"
        )
    grouped = "group" in header
    if grouped:
        groups = {r.group for r in out}
        if len(groups) < MIN_GROUPS:
            raise InputError(
                f"{p}: {len(groups)} group(s); cross-validation holding groups out needs at "
                f"least {MIN_GROUPS}"
            )
    return Ratings(p, tuple(out), grouped, digest)
