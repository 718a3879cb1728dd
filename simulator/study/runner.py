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

import math
import os
import time
from dataclasses import asdict
from pathlib import Path

from simulator.core.errors import InputError
from simulator.core.fileio import OutputFolder
from simulator.discomfort.model import load_model
from simulator.discomfort.predict import MODEL_COLUMNS, model_note, model_summary
from simulator.study import outputs, tasks
from simulator.study.executors import make_executor
from simulator.study.manifest import Manifest, VideoSpec, ViewingSpec
from simulator.study.plan import (
    STUDY_FILES,
    Plan,
    base_row,
    check_videos,
    default_cache_dir,
    dry_run,
    plan_study,
    study_folders,
)

__all__ = ["VIEWING_COLUMNS", "default_cache_dir", "dry_run", "run_study"]

VIEWING_COLUMNS = (
    "viewing", "participant", "condition", "video", "trace", "user", "frames",
    "epof_mean_dps", "epof_median_dps", "epof_p90_dps", "epof_max_dps", "opacity_mean",
    "share_opacity_ge_0_5", "status", "warnings",
)  # fmt: skip
_STAT_COLUMNS = VIEWING_COLUMNS[6:13]
#: Warnings of one viewing in its ``warnings`` cell are joined by this.
WARNING_SEP = " | "


def _video_dict(v: VideoSpec) -> dict:
    d = asdict(v)
    d["path"] = str(v.path)
    d["grid_file"] = None if v.grid_file is None else str(v.grid_file)
    return d


def _item(w: ViewingSpec) -> dict:
    return {"id": w.id, "trace": "" if w.trace is None else str(w.trace), "format": w.format,
            "user": w.user, "plot": w.plot, "trace_opts": asdict(w.trace_opts)}  # fmt: skip


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
    ``status`` holds the error line. Each viewing's warnings (its trace's reader
    warnings) are in its row's ``warnings`` cell and in the summary's ``warnings``
    (``{"viewing", "warning"}``). InputError only for problems found before any work
    (output folder, executor, Ray address).
    """
    t_start, c_start = time.perf_counter(), time.process_time()
    out, cache = study_folders(manifest, outdir, cache_dir)
    check_videos(manifest)  # a [[videos]] path that is not a video: a manifest error
    ex = make_executor(executor, workers)  # Ray address checked here, before any work
    try:
        return _run(manifest, out, cache, ex, resume, progress, (t_start, c_start), video_outputs)
    except BaseException:
        ex.close(cancel=True)
        raise


def _prepare(manifest: Manifest, out: Path, cache: Path, ex) -> OutputFolder:
    """Checks that need the executor, then the folders; the folder manifest of OUTDIR's
    top files (:data:`STUDY_FILES`), whose completion marker ``study.json`` goes first."""
    cpus = manifest.render["cpus"]
    if ex.name == "ray" and any(w.render for w in manifest.viewings) and cpus > ex.max_task_cpus:
        raise InputError(
            f"{manifest.path}: [render] cpus = {cpus}, but the largest node of the Ray "
            f"cluster has {ex.max_task_cpus} CPUs: a render task would never start"
        )
    folder = OutputFolder(out, STUDY_FILES, "study")
    folder.prepare()  # the completion marker (study.json) and viewings.csv go first
    (cache / "grids").mkdir(parents=True, exist_ok=True)
    for sub in ("epof", "state"):
        (out / sub).mkdir(exist_ok=True)
    return folder


def _run(manifest, out, cache, ex, resume, progress, start, video_outputs=True) -> dict:
    t_start, c_start = start
    timings: dict[str, float] = {}
    folder = _prepare(manifest, out, cache, ex)
    t0 = time.perf_counter()
    plan = plan_study(manifest, out, cache, resume)
    for vid in plan.stale:  # a corrupt or foreign cache entry: ours, made again
        plan.grids[vid].unlink(missing_ok=True)
    rows: dict[str, dict] = {}
    for w in manifest.viewings:
        if w.id in plan.unchanged:
            prev = plan.unchanged[w.id]
            rows[w.id] = {**base_row(w), **{c: prev.get(c, "") for c in _STAT_COLUMNS},
                          **{c: prev[c] for c in tasks.PART_MEAN_COLUMNS if c in prev},
                          "status": "ok", "warnings": prev.get("warnings", ""),
                          "resumed": True}  # fmt: skip
    timings["plan"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    sched = _Scheduler(manifest, out, ex, plan, rows, progress)
    sched.spool_dir = str(cache / "fields")  # long videos' fields, decompressed once
    sched.run()
    timings["tasks"] = time.perf_counter() - t0
    ex_info = ex.info()
    ex.close(wait=False)  # Ray's runtime stops while the outputs are written

    t0 = time.perf_counter()
    table = [rows[w.id] for w in manifest.viewings]
    cols = VIEWING_COLUMNS
    if manifest.model is not None:  # [model]: each viewing's predicted discomfort
        cols = (*cols, *MODEL_COLUMNS)
        failed = outputs.add_predictions(manifest.model, out, plan.grids, table)
        for r in table:
            if r["viewing"] in failed:
                notes = (r.get("warnings"), failed[r["viewing"]])
                r["warnings"] = WARNING_SEP.join(x for x in notes if x)
    outputs.write_viewings_csv(out / "viewings.csv", table, cols)
    report = (
        outputs.write_study_outputs(manifest, out, plan.grids, table)
        if video_outputs
        else {"videos": {}}
    )
    timings["outputs"] = time.perf_counter() - t0
    ex.join()
    timings["total"] = time.perf_counter() - t_start
    # CPU seconds: this process, and the tasks as measured in their workers (worker
    # start-up and imports not included).
    timings["cpu_driver"] = time.process_time() - c_start
    timings["cpu_tasks"] = sched.cpu_tasks
    summary = _summary(manifest, out, cache, ex_info, sched.video_info, table, report)
    if manifest.model is not None:
        m = load_model(manifest.model)
        summary["model"] = {**model_summary(m), "note": model_note(m)}
    summary["timings_s"] = timings
    folder.complete()
    tasks.write_json(out / "study.json", summary)  # last: the study is complete
    return summary


def _summary(manifest, out, cache, ex_info, video_info, table, report) -> dict:
    failures = [
        {"viewing": r["viewing"], "status": r["status"]} for r in table if r["status"] != "ok"
    ]
    warns = [
        {"viewing": r["viewing"], "warning": x}
        for r in table
        for x in (r.get("warnings") or "").split(WARNING_SEP)
        if x
    ]
    ok = [r for r in table if r["status"] == "ok"]
    return {
        "format": "vimsim-study",
        "version": 1,
        "name": manifest.name,
        "manifest": str(manifest.path),
        "outdir": str(out),
        "cache": str(cache),
        **ex_info,
        "settings": {
            "epof": manifest.epof,
            "render": manifest.render,
            "grf": manifest.grf,
            "questionnaires": manifest.questionnaires,
        },
        "videos": video_info,
        "counts": {
            "viewings": len(table),
            "ok": len(ok),
            "with_warnings": sum(bool(r.get("warnings")) for r in ok),
            "failed": len(failures),
            "resumed": sum(bool(r.get("resumed")) for r in table),
            "renders": sum(w.render for w in manifest.viewings),
        },
        "failures": failures,
        "warnings": warns,
        "outputs": report,
        "versions": outputs.versions(ex_info),
    }


class _Scheduler:
    """Submits the plan's tasks to the executor as their inputs exist, collects results
    into rows (and resume records), counts progress."""

    def __init__(self, manifest: Manifest, out: Path, ex, plan: Plan, rows: dict, progress):
        self.m, self.out, self.ex, self.plan, self.rows = manifest, out, ex, plan, rows
        self.progress = progress
        self.pending: dict = {}
        self.results: dict[str, dict] = {}
        self.renders: dict[str, dict] = {}
        self.by_id = {w.id: w for w in manifest.viewings}
        self.need_grid = {w.video for w in plan.todo}
        self.total = sum(1 + w.render for w in plan.todo)
        self.done = self.failed = 0
        self.cpu_tasks = 0.0
        self.video_info: dict[str, dict] = {}
        for v in manifest.videos:
            hit = plan.hits[v.id]
            self.video_info[v.id] = {"path": str(v.path), "grid": str(plan.grids[v.id]),
                                     "cache": "hit" if hit else plan.stale.get(v.id, "miss"),
                                     "preprocess_s": 0.0}  # fmt: skip
            self.total += 0 if hit else 1

    def tick(self, ok: bool, n: int = 1) -> None:
        self.done += n if ok else 0
        self.failed += 0 if ok else n
        if self.progress is not None:
            self.progress(self.done, self.failed, self.total)

    def submit(self, what: tuple, call: tuple, cpus: int, attempt: int = 1) -> None:
        """Submit ``call`` = (fn, *args); ``what`` = (kind, video id, payload)."""
        h = self.ex.submit(*call, num_cpus=cpus, alone=attempt > 1)
        self.pending[h] = (*what, call, cpus, attempt)

    def launch(self, v: VideoSpec) -> None:
        grid = str(self.plan.grids[v.id])
        mine = [w for w in self.plan.todo if w.video == v.id]
        for chunk in _chunks([_item(w) for w in mine], self.ex.workers):
            self.submit(("epof", v.id, chunk),
                        (tasks.epof_task, grid, chunk, self.m.epof, str(self.out / "epof"),
                         self.spool_dir), 1)  # fmt: skip
        for w in mine:
            if w.render:
                self.submit(("render", v.id, w.id),
                            (tasks.render_task, _video_dict(v), grid, _item(w), w.render_opts,
                             str(self.out / "render" / w.id)),
                            self.m.render["cpus"])  # fmt: skip

    def run(self) -> None:
        n_pre = sum(not hit for hit in self.plan.hits.values())
        threads = max(1, (os.cpu_count() or 1) // max(1, min(self.ex.workers, n_pre)))
        threads = min(threads, self.ex.max_task_cpus)  # a task no node can take never starts
        self.tick(True, 0)
        for v in self.m.videos:
            if not self.plan.hits[v.id]:
                self.submit(("preprocess", v.id, None),
                            (tasks.preprocess_task, _video_dict(v), str(self.plan.grids[v.id]),
                             threads), threads)  # fmt: skip
            elif v.id in self.need_grid:
                self.launch(v)
        while self.pending:
            for h in self.ex.wait(self.pending.keys()):
                self.collect(h)

    def collect(self, h) -> None:
        kind, vid, payload, call, cpus, attempt = self.pending.pop(h)
        line = ""
        try:
            res = self.ex.result(h)
            self.cpu_tasks += sum(
                r.get("cpu_s", 0.0) for r in (res if isinstance(res, list) else [res])
            )
        except Exception as e:  # noqa: BLE001 -- a worker died: its tasks fail, the rest go on
            if self.ex.lost(e) and attempt < TASK_ATTEMPTS:
                # Its process died (killed, out of memory, a crash) -- maybe another
                # task's, which takes the whole local pool down: once more, new workers.
                self.submit((kind, vid, payload), call, cpus, attempt + 1)
                return
            res = None
            line = f"internal error: worker failed: {self.ex.describe(e)}"
        if kind == "preprocess":
            self.preprocessed(vid, res, line)
        elif kind == "epof":
            recs = res if res is not None else [{"id": it["id"], "status": line} for it in payload]
            for r in recs:
                self.results[r["id"]] = r
                self.tick(r["status"] == "ok")
                self.finish(self.by_id[r["id"]])
        else:
            r = res if res is not None else {"status": line}
            self.renders[payload] = r
            self.tick(r["status"] == "ok")
            self.finish(self.by_id[payload])

    def preprocessed(self, vid: str, res: dict | None, line: str) -> None:
        if res is not None:
            line = f"video {vid}: {res['error']}"
            self.video_info[vid]["preprocess_s"] = res["seconds"]
        if res is not None and res["ok"]:
            self.tick(True)
            if vid in self.need_grid:
                self.launch(self.m.video(vid))
            return
        self.video_info[vid]["error"] = line
        self.tick(False)
        for w in self.plan.todo:
            if w.video == vid:
                self.results[w.id] = {"id": w.id, "status": line}
                if w.render:
                    self.renders[w.id] = {"status": line}
                self.tick(False, 1 + w.render)
                self.finish(w)

    def finish(self, w: ViewingSpec) -> None:
        """Once a viewing's EPOF (and render, if asked) are in: its row and state file."""
        if w.id not in self.results or (w.render and w.id not in self.renders):
            return
        r = self.results[w.id]
        row = {**base_row(w), **{c: r.get(c, "") for c in _STAT_COLUMNS},
               **{c: r[c] for c in tasks.PART_MEAN_COLUMNS if c in r}}  # fmt: skip
        status = r["status"]
        if status == "ok" and w.render and self.renders[w.id]["status"] != "ok":
            status = f"render: {self.renders[w.id]['status']}"
        row["status"] = status
        row["warnings"] = WARNING_SEP.join(r.get("warnings") or [])
        self.rows[w.id] = row
        state = self.out / "state" / f"{w.id}.json"
        if status == "ok":
            tasks.write_json(state, {"key": self.plan.keys[w.id], "row": row})
        else:
            state.unlink(missing_ok=True)
