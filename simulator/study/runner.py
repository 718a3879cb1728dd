"""Runs a study: plans the task graph, skips unchanged viewings, schedules the rest, writes outputs.

The graph: one preprocess task per video whose grid is not in the cache (content hash
of the video + preprocessing options; a second study on the same video reuses it), then
per video, once its grid exists, EPOF tasks over chunks of its viewings and one render
task per viewing that asks for it. Videos and viewings run in parallel on the executor.

Resume: after a viewing completes, ``OUTDIR/state/<viewing>.json`` records the hash of
its inputs and options (video content and grid options, the trace file's bytes, its
user and format, the EPOF/render/GRF options, the vimsim version) and its row. A rerun
on the same OUTDIR (``--resume``, the default) skips viewings whose hash and outputs are
unchanged and recomputes the others; an interrupted study thus continues where it
stopped. ``study.json`` is removed at the start and written last: it marks a complete
study.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import time
from dataclasses import asdict
from pathlib import Path

from simulator import __version__
from simulator.core.errors import InputError
from simulator.core.fileio import check_output_dir
from simulator.media.gridfile import VERSION as GRID_VERSION
from simulator.media.gridfile import content_hash
from simulator.study import outputs, tasks
from simulator.study.executors import make_executor
from simulator.study.manifest import Manifest, VideoSpec, ViewingSpec

__all__ = ["VIEWING_COLUMNS", "default_cache_dir", "run_study"]

VIEWING_COLUMNS = (
    "viewing", "participant", "condition", "video", "trace", "user", "frames",
    "epof_mean_dps", "epof_median_dps", "epof_p90_dps", "epof_max_dps", "opacity_mean",
    "share_opacity_ge_0_5", "status",
)  # fmt: skip
_STAT_COLUMNS = VIEWING_COLUMNS[6:13]


def default_cache_dir() -> Path:
    """``$VIMSIM_CACHE``, else ``$XDG_CACHE_HOME/vimsim``, else ``~/.cache/vimsim``."""
    if os.environ.get("VIMSIM_CACHE"):
        return Path(os.environ["VIMSIM_CACHE"])
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "vimsim"


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


def _video_dict(v: VideoSpec) -> dict:
    d = asdict(v)
    d["path"] = str(v.path)
    d["grid_file"] = None if v.grid_file is None else str(v.grid_file)
    return d


def _item(w: ViewingSpec) -> dict:
    return {"id": w.id, "trace": "" if w.trace is None else str(w.trace), "format": w.format,
            "user": w.user}  # fmt: skip


def _check_outputs(m: Manifest, out: Path, cache: Path) -> None:
    """Refuse an OUTDIR or cache that would overwrite an input (or is one)."""
    inputs = {p.resolve() for p in m.input_files()}
    for d, what in ((out, "output folder"), (cache, "cache folder")):
        r = d.resolve()
        if r in inputs or (d.exists() and not d.is_dir()):
            raise InputError(f"{d}: {what} is a file (an input?); give a folder")
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


#: Runs of a task whose worker process died before it is failed (a task's own errors
#: are its result's status, never retried).
TASK_ATTEMPTS = 2


def _chunks(items: list, workers: int) -> list[list]:
    """Split a video's viewings into chunks: a few per worker (balance) but not one per
    viewing (each chunk loads the grid once per worker process anyway)."""
    n = max(1, min(len(items), workers * 3))
    size = math.ceil(len(items) / n)
    return [items[i : i + size] for i in range(0, len(items), size)]


def run_study(
    manifest: Manifest,
    outdir,
    *,
    executor: str = "local",
    workers: int | None = None,
    cache_dir=None,
    resume: bool = True,
    progress=None,
    video_outputs: bool = True,
) -> dict:
    """Run ``manifest`` into ``outdir``; returns the ``study.json`` summary.

    ``video_outputs=False`` skips ``OUTDIR/videos/`` (a caller writing its own, e.g. a
    screening).

    ``progress(done, failed, total)`` is called as tasks finish (units: a preprocess, a
    viewing's EPOF, a render). Failed viewings do not stop the study: their row's
    ``status`` holds the error line. InputError only for problems found before any work
    (output folder, executor, Ray address).
    """

    t_start, c_start = time.perf_counter(), time.process_time()
    # Absolute: workers (Ray's especially) need not share the driver's working directory.
    out = Path(outdir).absolute()
    cache = (Path(cache_dir) if cache_dir else (manifest.cache or default_cache_dir())).absolute()
    _check_outputs(manifest, out, cache)
    ex = make_executor(executor, workers)  # Ray address checked here, before any work
    try:
        return _run(manifest, out, cache, ex, resume, progress, (t_start, c_start), video_outputs)
    except BaseException:
        ex.close(cancel=True)
        raise


def _run(manifest, out, cache, ex, resume, progress, start, video_outputs) -> dict:
    t_start, c_start = start
    timings: dict[str, float] = {}
    cpu_tasks = 0.0
    cpus = manifest.render["cpus"]
    if ex.name == "ray" and any(w.render for w in manifest.viewings) and cpus > ex.max_task_cpus:
        raise InputError(
            f"{manifest.path}: [render] cpus = {cpus}, but the largest node of the Ray "
            f"cluster has {ex.max_task_cpus} CPUs: a render task would never start"
        )
    check_output_dir(out)
    (cache / "grids").mkdir(parents=True, exist_ok=True)
    for sub in ("epof", "state"):
        (out / sub).mkdir(exist_ok=True)
    (out / "study.json").unlink(missing_ok=True)  # the completion marker goes first

    # ---- plan: grid keys, viewing keys, what is unchanged
    t0 = time.perf_counter()
    memo: dict = {}
    grids = {v.id: v.grid_file or cache / "grids" / f"{_grid_key(v)[:32]}.npz"
             for v in manifest.videos}  # fmt: skip
    opts = {"epof": manifest.epof, "render": manifest.render, "grf": manifest.grf}
    rows: dict[str, dict] = {}
    keys: dict[str, str] = {}
    todo: list[ViewingSpec] = []
    for w in manifest.viewings:
        keys[w.id] = _sha({
            "grid": grids[w.video].name, "trace": _file_sha(w.trace, memo) if w.trace else "", "format": w.format,
            "user": w.user, "epof": opts["epof"], "vimsim": __version__,
            "render": [opts["render"], opts["grf"]] if w.render else None,
        })  # fmt: skip
        prev = _read_state(out / "state" / f"{w.id}.json") if resume else None
        if (
            prev is not None
            and prev.get("key") == keys[w.id]
            and prev.get("row", {}).get("status") == "ok"
            and (out / "epof" / f"{w.id}.csv").is_file()
            and (not w.render or (out / "render" / w.id / "summary.json").is_file())
        ):
            rows[w.id] = {**_base_row(w), **{c: prev["row"][c] for c in _STAT_COLUMNS},
                          "status": "ok", "resumed": True}  # fmt: skip
        else:
            todo.append(w)
    timings["plan"] = time.perf_counter() - t0

    # ---- schedule
    total = sum(1 + w.render for w in todo)
    need_grid = {w.video for w in todo}
    video_info: dict[str, dict] = {}
    for v in manifest.videos:
        hit = grids[v.id].is_file()
        video_info[v.id] = {"path": str(v.path), "grid": str(grids[v.id]),
                            "cache": "hit" if hit else "miss", "preprocess_s": 0.0}  # fmt: skip
        if not hit:
            total += 1
    done = failed = 0

    def tick(ok: bool, n: int = 1) -> None:
        nonlocal done, failed
        done += n if ok else 0
        failed += 0 if ok else n
        if progress is not None:
            progress(done, failed, total)

    tick(True, 0)
    pending: dict = {}
    n_pre = sum(not grids[v.id].is_file() for v in manifest.videos)
    threads = max(1, (os.cpu_count() or 1) // max(1, min(ex.workers, n_pre)))
    threads = min(threads, ex.max_task_cpus)  # a task no node can take would never start
    render_opts = dict(manifest.render)

    def submit(what: tuple, call: tuple, cpus: int, attempt: int = 1) -> None:
        """Submit ``call`` = (fn, *args); ``what`` = (kind, video id, payload)."""
        h = ex.submit(*call, num_cpus=cpus, alone=attempt > 1)
        pending[h] = (*what, call, cpus, attempt)

    def launch(v: VideoSpec) -> None:
        mine = [w for w in todo if w.video == v.id]
        for chunk in _chunks([_item(w) for w in mine], ex.workers):
            submit(("epof", v.id, chunk),
                   (tasks.epof_task, str(grids[v.id]), chunk, manifest.epof, str(out / "epof")),
                   1)  # fmt: skip
        for w in mine:
            if w.render:
                submit(("render", v.id, w.id),
                       (tasks.render_task, _video_dict(v), str(grids[v.id]), _item(w),
                        render_opts, manifest.grf, str(out / "render" / w.id)),
                       render_opts["cpus"])  # fmt: skip

    t0 = time.perf_counter()
    for v in manifest.videos:
        if not grids[v.id].is_file():
            submit(("preprocess", v.id, None),
                   (tasks.preprocess_task, _video_dict(v), str(grids[v.id]), threads), threads)  # fmt: skip
        elif v.id in need_grid:
            launch(v)

    results: dict[str, dict] = {}
    renders: dict[str, dict] = {}
    warnings_: list[str] = []
    by_id = {w.id: w for w in manifest.viewings}
    while pending:
        for h in ex.wait(pending.keys()):
            kind, vid, payload, call, cpus, attempt = pending.pop(h)
            try:
                res = ex.result(h)
                cpu_tasks += sum(
                    r.get("cpu_s", 0.0) for r in (res if isinstance(res, list) else [res])
                )
            except Exception as e:  # noqa: BLE001 -- a worker died: its tasks fail, the rest go on
                if ex.lost(e) and attempt < TASK_ATTEMPTS:
                    # Its process died (killed, out of memory, a crash) -- maybe another
                    # task's, which takes the whole local pool down: once more, new workers.
                    submit((kind, vid, payload), call, cpus, attempt + 1)
                    continue
                res = None
                line = f"internal error: worker failed: {ex.describe(e)}"
            if kind == "preprocess":
                if res is not None:
                    line = f"video {vid}: {res['error']}"
                    video_info[vid]["preprocess_s"] = res["seconds"]
                if res is not None and res["ok"]:
                    tick(True)
                    if vid in need_grid:
                        launch(manifest.video(vid))
                else:
                    video_info[vid]["error"] = line
                    tick(False)
                    for w in todo:
                        if w.video == vid:
                            results[w.id] = {"id": w.id, "status": line}
                            if w.render:
                                renders[w.id] = {"status": line}
                            tick(False, 1 + w.render)
            elif kind == "epof":
                recs = (
                    res if res is not None else [{"id": it["id"], "status": line} for it in payload]
                )
                for r in recs:
                    results[r["id"]] = r
                    warnings_ += [f"{r['id']}: {x}" for x in r.get("warnings", [])]
                    tick(r["status"] == "ok")
                    _maybe_finish(out, by_id[r["id"]], keys, results, renders, rows)
            else:
                r = res if res is not None else {"status": line}
                renders[payload] = r
                tick(r["status"] == "ok")
                _maybe_finish(out, by_id[payload], keys, results, renders, rows)
    timings["tasks"] = time.perf_counter() - t0
    ex_info = ex.info()
    ex.close(wait=False)  # Ray's runtime stops while the outputs are written

    # ---- outputs
    t0 = time.perf_counter()
    table = [rows[w.id] for w in manifest.viewings]
    outputs.write_viewings_csv(out / "viewings.csv", table, VIEWING_COLUMNS)
    report = (
        outputs.write_study_outputs(manifest, out, grids, table)
        if video_outputs
        else {"videos": {}}
    )
    timings["outputs"] = time.perf_counter() - t0
    ex.join()
    timings["total"] = time.perf_counter() - t_start
    # CPU seconds: this process, and the tasks as measured in their workers (worker
    # start-up and imports not included).
    timings["cpu_driver"] = time.process_time() - c_start
    timings["cpu_tasks"] = cpu_tasks
    failures = [
        {"viewing": r["viewing"], "status": r["status"]} for r in table if r["status"] != "ok"
    ]
    summary = {
        "format": "vimsim-study",
        "version": 1,
        "name": manifest.name,
        "manifest": str(manifest.path),
        "outdir": str(out),
        "cache": str(cache),
        **ex_info,
        "settings": {**opts, "questionnaires": manifest.questionnaires},
        "videos": video_info,
        "counts": {
            "viewings": len(table),
            "ok": sum(r["status"] == "ok" for r in table),
            "failed": len(failures),
            "resumed": sum(bool(r.get("resumed")) for r in table),
            "renders": sum(w.render for w in manifest.viewings),
        },
        "failures": failures,
        "warnings": warnings_,
        "outputs": report,
        "versions": outputs.versions(ex_info),
        "timings_s": timings,
    }
    tasks.write_json(out / "study.json", summary)  # last: the study is complete
    return summary


def _base_row(w: ViewingSpec) -> dict:
    return {
        "viewing": w.id,
        "participant": w.participant,
        "condition": w.condition,
        "video": w.video,
        "trace": "" if w.trace is None else str(w.trace),
        "user": "" if w.user is None else w.user,
    }


def _read_state(p: Path) -> dict | None:
    try:
        d = json.loads(p.read_text())
    except (OSError, ValueError):
        return None
    return d if isinstance(d, dict) else None


def _maybe_finish(out, w: ViewingSpec, keys, results, renders, rows) -> None:
    """Once a viewing's EPOF (and render, if asked) are in: its row, and its state file."""
    if w.id not in results or (w.render and w.id not in renders):
        return
    r = results[w.id]
    row = {**_base_row(w), **{c: r.get(c, "") for c in _STAT_COLUMNS}}
    status = r["status"]
    if status == "ok" and w.render and renders[w.id]["status"] != "ok":
        status = f"render: {renders[w.id]['status']}"
    row["status"] = status
    rows[w.id] = row
    state = out / "state" / f"{w.id}.json"
    if status == "ok":
        tasks.write_json(state, {"key": keys[w.id], "row": row})
    else:
        state.unlink(missing_ok=True)
