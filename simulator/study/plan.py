"""The plan of a study: grid keys, what the cache holds, which viewings are unchanged, and the dry run's checks.

:func:`plan_study` is what a run does before any work (and all a ``--dry-run`` does): the
cache key of each video's grid (the video's content hash and its preprocessing options),
whether the cache holds it, the key of each viewing (grid, trace bytes, user, options)
and whether an earlier run's record on OUTDIR matches it. :func:`check_plan` adds what
only a dry run reads: every trace parsed (a multi-user file once), its time range
checked against its video's, and each render range against the video's length.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import json
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path

from simulator import __version__
from simulator.core.errors import InputError
from simulator.core.fileio import OutputFolder, atomic_output
from simulator.core.mapcache import cache_dir
from simulator.media.gridfile import VERSION as GRID_VERSION
from simulator.media.gridfile import cells_from_meta, content_hash, load_grid
from simulator.media.source import Source
from simulator.media.video import probe
from simulator.study.manifest import SCRIPTED, Manifest, VideoSpec, ViewingSpec
from simulator.traces.clock import check_span, place, read_trace
from simulator.traces.path import synth
from simulator.traces.readers import TraceFile
from simulator.viewing.spec import VIEW_OPTIONS, ViewSpec

#: The files at the top of OUTDIR (the folder manifest lists them; the rest are in folders).
STUDY_FILES = ("viewings.csv", "study.json")

__all__ = [
    "STUDY_FILES",
    "Plan",
    "base_row",
    "cache_problem",
    "check_outputs",
    "check_plan",
    "check_videos",
    "default_cache_dir",
    "dry_run",
    "plan_study",
    "study_folders",
    "view_cells",
    "viewing_key",
]


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
        "grid": grid.name, "trace": "" if w.trace is None else _file_sha(w.trace, memo),
        "format": w.format, "trace_opts": w.trace_opts,
        "user": w.user, "epof": m.epof, "vimsim": __version__,
        "render": [w.render_opts, m.grf] if w.render else None, "plot": w.plot,
    })  # fmt: skip


def read_state(p: Path) -> dict | None:
    """A viewing's resume record, or None (missing or unreadable: recomputed)."""
    try:
        d = json.loads(p.read_text())
    except (OSError, ValueError, RecursionError):
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
    #: cached grids that cannot serve their video (``{video id: "rebuilt: why"}``): a run
    #: removes and remakes them, a dry run reports them
    stale: dict[str, str] = field(default_factory=dict)

    @property
    def n_tasks(self) -> int:
        """What the run's progress bar counts: a preprocess per grid missing from the cache,
        an EPOF per viewing to compute (chunked when run), a render per rendering one."""
        return sum(not hit for hit in self.hits.values()) + sum(1 + w.render for w in self.todo)


def plan_study(m: Manifest, out: Path, cache: Path, resume: bool) -> Plan:
    """The plan of ``m`` into ``out`` with the grid cache ``cache`` (reads no video frame)."""
    memo: dict = {}
    grids = {v.id: _grid_path(v, cache) for v in m.videos}
    plan = Plan(grids, {k: p.is_file() for k, p in grids.items()}, {}, {}, [])
    for v in m.videos:  # an entry is checked before use (format, video, options)
        mine = grids[v.id] == v.grid_file  # the user's grid: checked already, never removed
        why = cache_problem(grids[v.id], v, remember=True) if plan.hits[v.id] and not mine else None
        if why is not None:
            plan.hits[v.id] = False
            plan.stale[v.id] = f"rebuilt: {why}"
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


def _grid_path(v: VideoSpec, cache: Path) -> Path:
    """The grid of video ``v``: the user's own (``grid_file``) when it can serve it
    (:func:`cache_problem`), else the cache's entry (the user's file is never removed)."""
    # a user's own grid without stored artefacts still serves (its video is read for them)
    if v.grid_file is not None and cache_problem(v.grid_file, v, own=True) is None:
        return v.grid_file
    return cache / "grids" / f"{_grid_key(v)[:32]}.npz"


def _trace_of(w: ViewingSpec, parsed: dict, length_s: float):
    """The head path of a viewing read with its trace options, a multi-user file parsed
    once (``parsed`` memo); a scripted viewer's covers the video (``length_s``), as the
    EPOF task makes it."""
    if w.trace is None and w.format.startswith(SCRIPTED):
        return synth(w.format[len(SCRIPTED) :], length_s, seed=int(w.user or 0))
    if w.user is None:
        return read_trace(w.trace, w.trace_opts)
    key = (str(w.trace), w.format)
    if key not in parsed:
        parsed[key] = TraceFile(w.trace, w.format)
    return place(parsed[key].user(w.user), w.trace_opts)


def _open_as_the_run(v: VideoSpec):
    """The video's MediaInfo, opened as the run opens it (its layout, eye, projection and
    lens; a still refused as preprocessing refuses it): InputError for the same problems."""
    src = Source.open(v.path, layout=v.layout, eye=v.eye, projection=v.projection,
                      lens_fov_deg=v.lens_fov_deg)  # fmt: skip
    if not src.info.is_video or src.info.n_frames < 2:
        raise InputError(
            f"{v.path}: is a still image; preprocess needs a video with at least 2 frames"
        )
    return src.info


def check_plan(m: Manifest, plan: Plan) -> dict[str, list[str]]:
    """What a dry run checks beyond the manifest: each viewing still to compute has a
    readable trace of a span that fits its video and covering it (unless ``hold_last``,
    in ``[epof]``, ``[traces]`` or the viewing), and a render range
    inside the video. Returns ``{viewing: [warning lines]}``; problems (one line each,
    naming the viewing) go to ``plan.problems``."""
    videos = {}
    for v in m.videos:
        if any(w.video == v.id for w in plan.todo):
            try:
                info = _open_as_the_run(v)
                videos[v.id] = ((info.n_frames - 1) / info.fps, info.n_frames / info.fps)
            except InputError as e:
                plan.problems.append(f"video {v.id}: {' '.join(str(e).split())}")
    parsed: dict = {}
    found: dict[str, list[str]] = {}
    for w in plan.todo:
        if w.video not in videos:
            continue
        last_s, length_s = videos[w.video]
        try:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                hp = _trace_of(w, parsed, length_s)  # with this viewing's warnings only
                check_span(hp, length_s, w.trace_opts, video=m.video(w.video).path.name)
            found[w.id] = sorted({" ".join(str(c.message).split()) for c in caught})
            hold = m.epof["hold_last"] or w.trace_opts.hold_last
            hp.check_covers(last_s, hold=hold, video=str(m.video(w.video).path))
            r = w.render_opts or {}
            if r.get("start_s") is not None and r["start_s"] >= length_s:
                raise InputError(f"render start = {r['start_s']:g} s is beyond the video "
                                 f"({length_s:.3f} s)")  # fmt: skip
        except InputError as e:  # the fix in the manifest's terms (hold_last = true)
            plan.problems.append(f"viewing {w.id}: {' '.join(w.trace_opts.fix(str(e)).split())}")
    return found


def check_videos(manifest: Manifest) -> None:
    """InputError (a manifest error, before any work) for a ``[[videos]] path`` that is
    not a video PyAV can read."""
    for v in manifest.videos:
        try:
            probe(v.path)
        except InputError as e:
            raise InputError(f"{manifest.path}: [[videos]] id {v.id!r}: {e}") from None
        except OSError as e:
            raise InputError(
                f"{manifest.path}: [[videos]] id {v.id!r}: {v.path}: not a readable video "
                f"({e.strerror or type(e).__name__})"
            ) from None


def cache_problem(
    path: Path, v: VideoSpec, *, remember: bool = False, own: bool = False
) -> str | None:
    """Why the cached grid ``path`` cannot serve video ``v`` (None: it can). Checked before
    use: the grid file's format (every array and its meta, as :func:`load_grid` checks),
    the content hash of the video it was made from, and its options (method, layout,
    eye, window matrix shape, cell size).

    ``own``: the user's grid (``grid_file``), which serves without stored artefacts.
    ``remember`` (the study's own cache entries, never a user's file): the fields' values
    (a decompression of each) are checked once per entry, a ``.checked`` mark beside it
    holding the file's size, time and inode when they passed."""
    mark = path.with_name(path.name + ".checked")
    try:
        st = path.stat()
        stamp = f"{st.st_size}:{st.st_mtime_ns}:{st.st_ino}"
        known = remember and mark.is_file() and mark.read_text(encoding="ascii") == stamp
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            g = load_grid(path, scan=not known)
    except (InputError, OSError, ValueError, KeyError, EOFError, UnicodeDecodeError) as e:
        return f"not a valid grid file ({' '.join(str(e).split())[:120]})"
    problem = _cache_mismatch(g, v, own)
    if problem is None and remember and not known:
        # a read-only cache: checked again next time
        with contextlib.suppress(OSError), atomic_output(mark) as tmp:
            Path(tmp).write_text(stamp, encoding="ascii")
    return problem


def _cache_mismatch(g, v: VideoSpec, own: bool = False) -> str | None:
    """Why a loaded cached grid was made of another video or with other options."""
    meta = g.meta if isinstance(g.meta, dict) else {}
    video = meta.get("video") if isinstance(meta.get("video"), dict) else {}
    if video.get("content_hash") != content_hash(v.path):
        return "made from another video (content hash differs)"
    want = {"method": v.method, "layout": v.layout, "eye": v.eye}
    for k, x in want.items():
        if meta.get(k, "paper" if k == "method" else None) != x:
            return f"made with {k} = {meta.get(k)!r}, not {x!r}"
    gm = meta.get("grid") if isinstance(meta.get("grid"), dict) else {}
    if gm.get("size") != [v.window_size, v.window_size]:
        return f"made with windows of {gm.get('size')} px, not {v.window_size}"
    if v.method == "sphere" and g.field_dps is not None:
        cell = cells_from_meta(meta).cell_deg
        if abs(float(cell) - float(v.cell_deg)) > 1e-9:
            return f"made with cell_deg = {cell:g}, not {v.cell_deg:g}"
    stored = isinstance(meta.get("artefacts"), dict)
    if v.artefacts and v.method == "sphere" and not stored and not own:
        # made before artefacts were detected by default: made again once with them, not
        # detected by every worker of every run (a decoding pass of the whole video each)
        return "made without artefact detection"
    return None


def check_outputs(m: Manifest, out: Path, cache: Path) -> None:
    """Refuse an OUTDIR or cache that would overwrite an input (or is one), and a file of
    an output name at OUTDIR's top that no earlier study wrote (the one folder rule)."""
    inputs = {p.resolve() for p in m.input_files()}
    for d, what in ((out, "output folder"), (cache, "cache folder")):
        r = d.resolve()
        if r in inputs or (d.exists() and not d.is_dir()):
            raise InputError(f"{d}: {what} is a file (an input?); give a folder")
    OutputFolder(out, STUDY_FILES, "study").check(inputs)
    roots = [out.resolve() / n for n in ("epof", "render", "state", "videos", "analysis")]
    for p in inputs:
        if p.parent == out.resolve() and p.name in ("viewings.csv", "study.json"):
            raise InputError(
                f"{p}: is an input and would be overwritten by the study; choose another -o"
            )
        if any(p.is_relative_to(r) for r in roots):
            raise InputError(
                f"{p}: is an input inside the study's output folders; choose another -o"
            )


def study_folders(manifest: Manifest, outdir, cache_dir) -> tuple[Path, Path]:
    # Absolute: workers (Ray's especially) need not share the driver's working directory.
    out = Path(outdir).absolute()
    cache = (Path(cache_dir) if cache_dir else (manifest.cache or default_cache_dir())).absolute()
    check_outputs(manifest, out, cache)
    return out, cache


def dry_run(manifest: Manifest, outdir, *, cache_dir=None, resume: bool = True) -> dict:
    """What ``run_study`` would do, checked and planned; writes nothing.

    Returns ``videos`` (grid, ``hit``/``miss``, whether it would be preprocessed),
    ``viewings`` (id, video, trace, user, condition, ``compute`` or ``unchanged``,
    render range), ``tasks`` (the count the run's progress bar would show),
    ``problems`` (one line each, naming the viewing or video: the run would fail them)
    and ``warnings`` (``{viewing: [lines]}``, the trace readers' warnings)."""
    t0 = time.perf_counter()
    out, cache = study_folders(manifest, outdir, cache_dir)
    plan = plan_study(manifest, out, cache, resume)
    warns = check_plan(manifest, plan)
    todo = {w.id for w in plan.todo}
    need = {w.video for w in plan.todo}
    videos = {
        v.id: {"grid": str(plan.grids[v.id]), "cache": "hit" if plan.hits[v.id] else plan.stale.get(v.id, "miss"),
               "preprocess": v.id in need and not plan.hits[v.id], "method": v.method}
        for v in manifest.videos
    }  # fmt: skip
    viewings = []
    for w in manifest.viewings:
        r = w.render_opts or {}
        viewings.append({
            **base_row(w), "action": "compute" if w.id in todo else "unchanged",
            "render": w.render, "start_s": r.get("start_s"), "end_s": r.get("end_s"),
            "review": bool(r.get("review")),
        })  # fmt: skip
    return {"videos": videos, "viewings": viewings, "tasks": plan.n_tasks,
            "problems": plan.problems, "warnings": warns, "cache": str(cache),
            "seconds": time.perf_counter() - t0}  # fmt: skip


def base_row(w: ViewingSpec) -> dict:
    """The identifying cells of a viewing's row in ``viewings.csv``."""
    return {
        "viewing": w.id,
        "participant": w.participant,
        "condition": w.condition,
        "video": w.video,
        "trace": "" if w.trace is None else str(w.trace),
        "user": "" if w.user is None else w.user,
        **view_cells(w.own_render),
    }


def view_cells(render_opts: dict | None) -> dict:
    """``mitigation`` and ``opacity_rule`` cells of a viewing's row: what its view draws
    (``none`` when nothing: ``grf = "off"`` or ``mitigation = "none"``) and how the
    opacity is set (the rule's name, with its deg/s for ``absolute``; ``fixed X`` for
    a constant ``opacity``)."""
    if not render_opts or "view" not in render_opts:
        return {"mitigation": "", "opacity_rule": ""}
    return _view_cells(json.dumps(render_opts["view"], sort_keys=True, default=str))


@functools.lru_cache(maxsize=64)
def _view_cells(view_json: str) -> dict:
    opts = json.loads(view_json)
    view = ViewSpec.from_options(opts, video=False)
    m = view.mitigation
    kind = m.kind if view.grains is not None else ("vignette" if m.vignette else "none")
    if isinstance(view.opacity, float):
        rule = f"fixed {view.opacity:g}"
    elif view.opacity != "auto":
        rule = f"from {Path(view.opacity).name}"
    else:
        rule = str(opts.get("opacity_rule") or VIEW_OPTIONS["opacity_rule"])
        if view.rule.is_absolute:
            rule += f" {view.rule.low_dps:g}-{view.rule.high_dps:g} deg/s"
    return {"mitigation": kind, "opacity_rule": rule}
