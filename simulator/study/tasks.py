"""The study's task functions: what a worker runs (preprocess a video, EPOF of viewings, render one).

Each is a top-level function taking plain values (paths as strings, option dicts), so
the local process pool and Ray ship them the same way; inputs are passed by path (a
shared filesystem on a cluster) and outputs are written by the worker, each to a
temporary name renamed when complete (:func:`simulator.core.fileio.atomic_output`). A task
never raises for a bad input: the viewing's result carries the one-line error as its
``status``. Per worker process, loaded grids, parsed multi-user trace files and the GL
context are kept for the next task (the context is created in the worker, on its first
render).
"""

from __future__ import annotations

import dataclasses
import math
import os
import time
import warnings
from pathlib import Path

import numpy as np

from simulator.core.errors import InputError
from simulator.core.fileio import atomic_output, json_text
from simulator.core.traceopts import TraceOptions, translate
from simulator.epof.exact import shared_query
from simulator.epof.nearest import FLOW_PX_COLUMN, nearest_epof
from simulator.epof.overlaps import viewport_fov
from simulator.epof.parts import keep_parts_in
from simulator.epof.viewing import compute_epof, plot_epof, write_epof_csv
from simulator.media.gridfile import GridFile, cells_from_meta, check_field_values, load_grid
from simulator.media.lazyfield import LazyField, spool, spool_name
from simulator.media.source import Source
from simulator.mitigation.grf import OpacityRule, rule_from_options
from simulator.preprocess.artefacts import Artefacts, artefacts_for_grid
from simulator.preprocess.paper import preprocess_video
from simulator.preprocess.sphere import SphereConfig, preprocess_sphere
from simulator.render.gl import create_context
from simulator.sphere.cells import Frustum
from simulator.sphere.windows import grid_preset
from simulator.study.viewers import SCRIPTED
from simulator.traces.clock import check_span, place, read_trace
from simulator.traces.path import HeadPath, synth
from simulator.traces.readers import TraceFile
from simulator.viewing.job import render_viewing
from simulator.viewing.spec import ViewSpec

__all__ = ["PART_MEAN_COLUMNS", "epof_task", "preprocess_task", "render_task", "viewing_stats"]

# Per worker process: kept between tasks (a pool or Ray worker runs many tasks).
_GRIDS: dict[tuple, GridFile] = {}
_TRACES: dict[tuple, TraceFile] = {}
_GL: list = []
_ARTEFACTS: dict[tuple, Artefacts] = {}

#: Exact-EPOF weight cache of a study worker (it serves every viewing of a video). Bounded:
#: a longer video visits more orientation bins, so a large cache fills with length (192 MiB
#: made a worker 2x larger for 10x the frames); 64 MiB keeps screen's worker within 1.15x
#: (bench/screen_memory.py) and the viewers' shared bins (16 MiB: 1.6x the EPOF time of 48
#: viewers of one video, 64 and 192 MiB the same).
WEIGHT_CACHE_BYTES = 64 << 20
#: A grid's sphere fields (float32, with the translational part) held whole by a worker
#: up to this size; beyond it they are read lazily per viewing.
FIELD_IN_MEMORY_BYTES = 16 << 20


def _field_bytes(g: GridFile) -> int:
    """Bytes of the grid's fields as float32 arrays."""
    return sum(4 * math.prod(f.shape) for f in (g.field_dps, g.field_trans_dps) if f is not None)


def _source(video: dict) -> Source:
    """The manifest video's checked :class:`simulator.media.source.Source`."""
    return Source.open(
        video["path"],
        layout=video["layout"],
        eye=video["eye"],
        projection=video.get("projection"),
        lens_fov_deg=video.get("lens_fov_deg"),
    )


def _error_line(e: BaseException) -> str:
    """One line for a failed step: the InputError's message (a trace option named by its
    manifest key), an OSError's file and reason (a full disk), or the internal error's type."""
    text = translate(" ".join(str(e).split()), "manifest")  # a study's fix: its manifest keys
    if isinstance(e, OSError) and e.strerror:  # an environment error: a full disk, permissions
        return f"{e.filename}: {e.strerror}" if e.filename else e.strerror
    return text if isinstance(e, InputError) else f"internal error: {type(e).__name__}: {text}"


def _file_key(path: str) -> tuple:
    st = os.stat(path)
    return (str(Path(path).resolve()), st.st_size, st.st_mtime_ns)


def _spooled(g: GridFile, folder: Path) -> GridFile:
    """A long video's fields as raw float32 spools in ``folder`` (the study's cache:
    decompressed once per grid file, not at each viewing; still read chunk by chunk) and
    their rotational part kept beside them (:func:`simulator.epof.parts.keep_parts_in`);
    the grid as it is when the folder cannot be written."""
    try:
        new = {}
        for name in ("field_dps", "field_trans_dps"):
            f = getattr(g, name)
            n = spool_name(f, name) if isinstance(f, LazyField) else None
            if n is not None:
                new[name] = spool(f, folder / n)
        keep_parts_in(folder)
        return dataclasses.replace(g, **new)
    except OSError:
        keep_parts_in(None)
        return g


def _grid(path: str, spool_dir: str | None = None) -> GridFile:
    key = _file_key(path)
    if key not in _GRIDS:
        _GRIDS.clear()  # one video's grid at a time per worker: bounded memory
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            g = load_grid(path, scan=False)  # the values checked once, below
        if _field_bytes(g) <= FIELD_IN_MEMORY_BYTES:
            # A short video's fields read once per worker as float32, not once per viewing;
            # a longer one's stay lazy (read chunk by chunk per viewing, as the single
            # commands do): a worker's memory does not grow with the video's length.
            if g.field_dps is not None:
                g = dataclasses.replace(g, field_dps=np.asarray(g.field_dps, dtype=np.float32))
            if g.field_trans_dps is not None:
                g = dataclasses.replace(g, field_trans_dps=np.asarray(g.field_trans_dps, np.float32))
        elif spool_dir is not None:
            g = _spooled(g, Path(spool_dir))
        check_field_values(g)  # in memory, or chunk by chunk
        _GRIDS[key] = g
    return _GRIDS[key]


def _artefacts(path: str, grid: GridFile) -> Artefacts:
    """The artefacts of a grid's video, detected once per worker and grid."""
    key = _file_key(path)
    if key not in _ARTEFACTS:
        _ARTEFACTS.clear()
        _ARTEFACTS[key] = artefacts_for_grid(grid)
    return _ARTEFACTS[key]


def _trace(item: dict, grid: GridFile | None = None) -> HeadPath:
    """The head path of one viewing (``item``: ``trace``, ``format``, ``user``,
    ``trace_opts``), read with its trace options and its own warnings (the file's and its
    user's sampling): a multi-user file is parsed once per worker. A scripted viewer
    (``format`` ``synth:<kind>``, ``user`` its seed) covers the grid's video."""
    path, fmt, user = item["trace"], item["format"], item["user"]
    if fmt.startswith(SCRIPTED):
        end = (int(grid.meta.get("start_frame", 0)) + grid.n_frames + 1) / grid.fps
        return synth(fmt[len(SCRIPTED) :], end, seed=int(user or 0))
    opts = _trace_opts(item)
    if user is None:
        return read_trace(path, opts)
    key = (*_file_key(path), fmt)
    if key not in _TRACES:
        if len(_TRACES) > 8:
            _TRACES.clear()
        _TRACES[key] = TraceFile(path, fmt)
    return place(_TRACES[key].user(user), opts)


def _check_span(item: dict, hp: HeadPath, grid: GridFile) -> None:
    """A viewing's trace span checked against its grid's whole video (a scripted viewer's
    covers it): :func:`simulator.traces.clock.check_span`, in the manifest's terms."""
    if not item["format"].startswith(SCRIPTED):
        vid = grid.meta.get("video") if isinstance(grid.meta.get("video"), dict) else {}
        n_video = int(vid.get("n_frames") or grid.n_frames)
        name = Path(str(vid.get("path", ""))).name
        check_span(hp, n_video / grid.fps, _trace_opts(item), video=name)


def _trace_opts(item: dict) -> TraceOptions:
    """A viewing's trace options (the manifest's: errors name its keys)."""
    given = {k: v for k, v in (item.get("trace_opts") or {}).items() if k != "origin"}
    return TraceOptions(**given, origin="manifest")


def preprocess_task(video: dict, output: str, threads: int) -> dict:
    """Make the grid file ``output`` of ``video`` (a :class:`VideoSpec` as a dict; paths as
    strings). Paper mode resumes its own checkpoint beside ``output`` after an
    interruption. Returns ``{"ok": bool, "error": str, "seconds": float, "cpu_s": float}``."""
    t0, c0 = time.perf_counter(), time.process_time()
    try:
        grid = grid_preset(
            video["grid"],
            hfov_deg=video["hfov_deg"],
            vfov_deg=video["vfov_deg"],
            size=(video["window_size"], video["window_size"]),
        )
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            if video["method"] == "sphere":
                preprocess_sphere(
                    _source(video),
                    output,
                    grid=grid,
                    config=SphereConfig(cell_deg=video["cell_deg"]),
                    flow=video["flow"],
                    progress=False,
                    artefacts=bool(video.get("artefacts")),
                )
            else:
                preprocess_video(
                    _source(video),
                    output,
                    grid=grid,
                    flow=video["flow"],
                    resume=True,
                    threads=threads,
                    progress=False,
                )
    except Exception as e:  # noqa: BLE001 -- one line per failed video, the study goes on
        line = _error_line(e)
        return {"ok": False, "error": line, "seconds": time.perf_counter() - t0,
                "cpu_s": time.process_time() - c0}  # fmt: skip
    return {"ok": True, "error": "", "seconds": time.perf_counter() - t0,
            "cpu_s": time.process_time() - c0}  # fmt: skip


#: The means of the EPOF's parts (:mod:`simulator.epof.parts`) in a viewing's row; empty
#: for a viewing whose grid has no per-frame camera rotation.
PART_MEAN_COLUMNS = ("epof_rot_mean_dps", "epof_trans_mean_dps")


def viewing_stats(epof_dps, opacity, parts=None) -> dict:
    """The numbers of a viewing's row in ``viewings.csv`` (deg/s; opacity 0..1); with
    ``parts = (epof_rot_dps, epof_trans_dps)`` (or None: empty) their means too."""
    e = np.asarray(epof_dps, np.float64)
    o = np.asarray(opacity, np.float64)
    means = ("", "") if parts is None or any(x is None for x in parts) else (
        float(np.mean(parts[0])), float(np.mean(parts[1])))  # fmt: skip
    return {
        **dict(zip(PART_MEAN_COLUMNS, means)),
        "frames": int(e.size),
        "epof_mean_dps": float(np.mean(e)),
        "epof_median_dps": float(np.median(e)),
        "epof_p90_dps": float(np.percentile(e, 90)),
        "epof_max_dps": float(np.max(e)),
        "opacity_mean": float(np.mean(o)),
        "share_opacity_ge_0_5": float(np.mean(o >= 0.5)),
    }


def _rule(opts: dict) -> OpacityRule:
    """The opacity rule of the ``[epof]`` table, by ``vimsim epof``'s one builder
    (:func:`simulator.mitigation.grf.rule_from_options`: by default ``"absolute"``, eased
    between ``low_dps`` and ``high_dps`` deg/s; ``opacity_rule = "paper"``: the paper's
    unsmoothed rule; ``"comfort"``: eased percentiles)."""
    names = {"smooth": "smooth_s", "ease_in": "ease_in_s", "ease_out": "ease_out_s"}

    def get(k):
        if k == "opacity_rule" and opts.get("preset") == "paper":
            return "paper"  # --preset paper: the paper's rule
        v = opts.get(names.get(k, k))
        return None if k == "smooth" and not v else v  # the table's default 0: not given

    return rule_from_options(get, lambda k: f"[epof] {k}")


def _viewing_epof(grid, hp, opts: dict, frustum, rule, art, topts):
    """One viewing's EPOF as ``vimsim epof`` computes it with the ``[epof]`` options (the
    authors' nearest-window rule with ``preset = "cao2021-code"``)."""
    hold = opts["hold_last"] or topts.hold_last
    if opts.get("preset") == "cao2021-code":
        return nearest_epof(grid, hp, hold=hold)  # the grid's imported scale, if any
    method = "paper" if opts.get("preset") == "paper" else opts["method"]
    return compute_epof(
        grid,
        hp,
        hfov_deg=None if frustum else opts["hfov_deg"],
        vfov_deg=None if frustum else opts["vfov_deg"],
        frustum=frustum,
        top_k=opts["top_k"],
        rule=rule,
        hold=hold,
        method=method,
        artefacts=art,
    )


def epof_task(
    grid_path: str, items: list[dict], opts: dict, epof_dir: str, spool_dir: str | None = None
) -> list[dict]:
    """EPOF and opacity of each viewing in ``items`` (``id``, ``trace``, ``format``,
    ``user``) on the grid ``grid_path``; writes ``epof_dir/<id>.csv``. Returns one dict per
    item: ``id``, ``status`` (``"ok"`` or the one-line error), the stats of
    :func:`viewing_stats`, ``warnings`` (lines), ``seconds`` and ``cpu_s`` (this process's
    CPU time; the first item's includes loading the grid). ``spool_dir``: where a long
    video's fields are kept decompressed (:func:`_spooled`; None: read lazily each time)."""
    out = []
    c_setup = time.process_time()
    try:
        grid = _grid(grid_path, spool_dir)
        rule = _rule(opts)
        # As vimsim epof: a headset's exact per-eye frustum, else the FOVs (the grid's)
        frustum = Frustum.from_headset(opts["headset"]) if opts.get("headset") else None
        art = _artefacts(grid_path, grid) if opts.get("artefacts") else None
        if grid.field_dps is not None and opts["method"] != "paper":
            # One worker serves every viewing of this video: let exact EPOF keep the
            # weights of more orientation bins (bounded, not growing with the video).
            fr = frustum or Frustum.symmetric(
                *viewport_fov(grid, opts["hfov_deg"], opts["vfov_deg"])
            )
            shared_query(cells_from_meta(grid.meta).cell_deg, fr).set_cache_bytes(
                WEIGHT_CACHE_BYTES
            )
    except Exception as e:  # noqa: BLE001
        line = _error_line(e)
        return [{"id": it["id"], "status": line, "warnings": [], "seconds": 0.0} for it in items]
    c_setup = time.process_time() - c_setup
    for it in items:
        t0, c0 = time.perf_counter(), time.process_time()
        rec: dict = {"id": it["id"], "warnings": []}
        try:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                try:
                    hp, topts = _trace(it, grid), _trace_opts(it)
                    _check_span(it, hp, grid)
                    res = _viewing_epof(grid, hp, opts, frustum, rule, art, topts)
                finally:  # a failed viewing keeps the warnings of its input too
                    rec["warnings"] = sorted({" ".join(str(w.message).split()) for w in caught})
            px = res.meta.get("flow_px")  # --preset cao2021-code: the px/frame of its opacity
            extra = None if px is None else {FLOW_PX_COLUMN: px}
            write_epof_csv(Path(epof_dir) / f"{it['id']}.csv", res, extra=extra)
            if it.get("plot"):
                plot_epof(Path(epof_dir) / f"{it['id']}.png", res, title=it["id"])
            parts = (res.epof_rot_dps, res.epof_trans_dps)
            rec.update(viewing_stats(res.epof_dps, res.opacity, parts), status="ok")
        except Exception as e:  # noqa: BLE001
            rec["status"] = _error_line(e)
        rec["seconds"] = time.perf_counter() - t0
        rec["cpu_s"] = time.process_time() - c0 + (c_setup if not out else 0.0)
        out.append(rec)
    return out


def _context():
    """This worker's GL context, created on its first render (never in the driver)."""
    if not _GL:
        _GL.append(create_context())
    return _GL[0]


def render_task(video: dict, grid_path: str, item: dict, opts: dict, outdir: str) -> dict:
    """Render one viewing into ``outdir`` (:func:`simulator.viewing.job.render_viewing`:
    ``left.mp4``, ``right.mp4``, ``epof.csv``, ``summary.json`` last) with the view of
    ``opts["view"]`` (the manifest's view options, built by
    :meth:`simulator.viewing.spec.ViewSpec.from_options` as ``vimsim render`` builds its
    own); ``start_s``/``end_s``, ``review``, ``eyes``, ``audio`` as ``vimsim render``'s
    options. ``opts["cpus"]`` llvmpipe threads unless ``LP_NUM_THREADS`` is set. Returns
    ``id``, ``status``, ``seconds``, ``frames_per_s``."""
    t0, c0 = time.perf_counter(), time.process_time()
    rec = {"id": item["id"], "status": "ok", "frames_per_s": None}
    try:
        # Before Mesa loads (the first context of this process): one thread per declared CPU.
        os.environ.setdefault("LP_NUM_THREADS", str(int(opts.get("cpus", 1))))
        view = ViewSpec.from_options(opts["view"])
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            grid = _grid(grid_path)
            hp = _trace(item, grid)
            _check_span(item, hp, grid)  # as the EPOF task: an implausible span is refused
        s = render_viewing(
            dataclasses.replace(_source(video), eye="left"),
            hp,
            outdir,
            grid=grid,
            view=view,
            x264_preset=opts["x264_preset"],
            crf=opts["crf"],
            threads=int(opts.get("cpus", 1)),  # the CPUs the task declares
            progress=False,
            ctx=_context(),
            start_s=opts.get("start_s"),
            end_s=opts.get("end_s"),
            review=bool(opts.get("review")),
            eyes=opts.get("eyes"),
            audio=opts.get("audio", True),
        )
        rec["frames_per_s"] = s.get("frames_per_s")
        vis = (s.get("visible_flow") or {}).get("visible_flow_dps_mean")
        rec["visible_flow_mean_dps"] = "" if vis is None else float(vis)
    except Exception as e:  # noqa: BLE001
        rec["status"] = _error_line(e)
    rec["seconds"] = time.perf_counter() - t0
    rec["cpu_s"] = time.process_time() - c0  # all threads: llvmpipe and the encoders too
    return rec


def write_json(path, obj) -> None:
    """``obj`` as standard JSON into ``path``, atomically."""
    with atomic_output(path) as tmp:
        Path(tmp).write_text(json_text(obj) + "\n")
