"""The plan of a study: grid keys, what the cache holds, which viewings are unchanged, and the dry run's checks.

:func:`plan_study` is what a run does before any work (and all a ``--dry-run`` does): the
cache key of each video's grid (the video's content hash and its preprocessing options),
whether the cache holds it, the key of each viewing (grid, trace bytes, user, options)
and whether an earlier run's record on OUTDIR matches it. :func:`check_plan` adds what
only a dry run reads: every trace parsed (a multi-user file once), its time range
checked against its video's, and each render range against the video's length.
"""

from __future__ import annotations

import hashlib
import json
import warnings
from dataclasses import dataclass, field
from pathlib import Path

from simulator import __version__
from simulator.core.errors import InputError
from simulator.core.mapcache import cache_dir
from simulator.media.gridfile import VERSION as GRID_VERSION
from simulator.media.gridfile import content_hash
from simulator.media.video import probe
from simulator.study.manifest import Manifest, VideoSpec, ViewingSpec
from simulator.traces.readers import TraceFile, load_headpath

__all__ = ["Plan", "check_plan", "default_cache_dir", "plan_study", "viewing_key"]


def default_cache_dir() -> Path:
    """vimsim's cache folder (:func:`simulator.core.mapcache.cache_dir`: ``$VIMSIM_CACHE_DIR``,
    else the deprecated ``$VIMSIM_CACHE``, else ``$XDG_CACHE_HOME/vimsim`` or
    ``~/.cache/vimsim``)."""
    return cache_dir()


def _sha(obj) -> str:
    return hashlib.sha256(json.dumps(obj, sort_keys=True, default=str).encode()).hexdigest()


def _file_sha(path: Path, memo: dict) -> str:
    key = str(path)
    if key not in memo:
        h = hashlib.sha256()
        with open(path, "rb") as fh:
            for b in iter(lambda: fh.read(1 << 20), b""):
                h.update(b)
        memo[key] = h.hexdigest()
    return memo[key]


def _grid_key(v: VideoSpec) -> str:
    return _sha({"video": content_hash(v.path), "options": v.options(), "grid": GRID_VERSION,
                 "vimsim": __version__})  # fmt: skip


def viewing_key(m: Manifest, w: ViewingSpec, grid: Path, memo: dict) -> str:
    """The hash of everything a viewing's outputs depend on (its resume record's key)."""
    return _sha({
        "grid": grid.name, "trace": _file_sha(w.trace, memo), "format": w.format,
        "user": w.user, "epof": m.epof, "vimsim": __version__,
        "render": [w.render_opts, m.grf] if w.render else None, "plot": w.plot,
    })  # fmt: skip


def read_state(p: Path) -> dict | None:
    """A viewing's resume record, or None (missing or unreadable: recomputed)."""
    try:
        d = json.loads(p.read_text())
    except (OSError, ValueError):
        return None
    return d if isinstance(d, dict) else None


@dataclass
class Plan:
    """What a run would do: grid paths and cache hits, viewing keys, unchanged viewings
    (their recorded rows), the viewings to compute, and the number of tasks."""

    grids: dict[str, Path]
    hits: dict[str, bool]
    keys: dict[str, str]
    unchanged: dict[str, dict]
    todo: list[ViewingSpec]
    problems: list[str] = field(default_factory=list)

    @property
    def n_tasks(self) -> int:
        """Preprocess tasks (grids missing for a video with work), one EPOF per viewing to
        compute (chunked when run), one render per rendering one."""
        need = {w.video for w in self.todo}
        return sum(not self.hits[v] for v in need) + sum(1 + w.render for w in self.todo)


def plan_study(m: Manifest, out: Path, cache: Path, resume: bool) -> Plan:
    """The plan of ``m`` into ``out`` with the grid cache ``cache`` (reads no video frame)."""
    memo: dict = {}
    grids = {v.id: cache / "grids" / f"{_grid_key(v)[:32]}.npz" for v in m.videos}
    plan = Plan(grids, {k: p.is_file() for k, p in grids.items()}, {}, {}, [])
    for w in m.viewings:
        plan.keys[w.id] = viewing_key(m, w, grids[w.video], memo)
        prev = read_state(out / "state" / f"{w.id}.json") if resume else None
        if (
            prev is not None
            and prev.get("key") == plan.keys[w.id]
            and prev.get("row", {}).get("status") == "ok"
            and (out / "epof" / f"{w.id}.csv").is_file()
            and (not w.render or (out / "render" / w.id / "summary.json").is_file())
        ):
            plan.unchanged[w.id] = prev["row"]
        else:
            plan.todo.append(w)
    return plan


def _trace_of(w: ViewingSpec, parsed: dict):
    """The head path of a viewing, a multi-user file parsed once (``parsed`` memo)."""
    if w.user is None:
        return load_headpath(w.trace, w.format)
    key = (str(w.trace), w.format)
    if key not in parsed:
        parsed[key] = TraceFile(w.trace, w.format)
    return parsed[key].user(w.user)


def check_plan(m: Manifest, plan: Plan) -> dict[str, list[str]]:
    """What a dry run checks beyond the manifest: each viewing still to compute has a
    readable trace covering its video (unless ``[epof] hold_last``), and a render range
    inside the video. Returns ``{viewing: [warning lines]}``; problems (one line each,
    naming the viewing) go to ``plan.problems``."""
    videos = {}
    for v in m.videos:
        if any(w.video == v.id for w in plan.todo):
            try:
                info = probe(v.path)
                videos[v.id] = ((info.n_frames - 1) / info.fps, info.n_frames / info.fps)
            except InputError as e:
                plan.problems.append(f"video {v.id}: {e}")
    parsed: dict = {}
    found: dict[str, list[str]] = {}
    for w in plan.todo:
        if w.video not in videos:
            continue
        last_s, length_s = videos[w.video]
        try:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                hp = _trace_of(w, parsed)  # with this viewing's warnings only
            found[w.id] = sorted({" ".join(str(c.message).split()) for c in caught})
            hp.check_covers(last_s, hold=m.epof["hold_last"], video=str(m.video(w.video).path))
            r = w.render_opts or {}
            if r.get("start_s") is not None and r["start_s"] >= length_s:
                raise InputError(f"render start = {r['start_s']:g} s is beyond the video "
                                 f"({length_s:.3f} s)")  # fmt: skip
        except InputError as e:
            plan.problems.append(f"viewing {w.id}: {' '.join(str(e).split())}")
    return found
