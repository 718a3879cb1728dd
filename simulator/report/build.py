"""Build ``OUTDIR/report/``: read a complete study, write the pages, the browser copies of the videos and the web runtime's data.

The folder is self-contained (no request outside it; nothing from a network): ``index.html``
(summary), ``viewings.html`` (table), ``video-<id>.html``, ``viewing-<id>.html`` (timeline and
replay), ``analysis.html``; ``assets/`` (CSS, the pages' scripts, the web runtime
``vimsim.js``, ``vimsim_grains.js`` and ``vimsim_gl.js``), ``data/<video>/`` (:func:`simulator.export.web.export_web`
of the video's grid with the study's opacity rule and grains), ``media/`` (the study's plots
and thumbnails, and ``<video>.mp4``, the browser copy: :func:`browser_copy`). It is built in a
temporary folder beside it and swapped in when complete; a report folder holding a file that
no earlier report listed in its ``.vimsim-report.json`` is refused (nothing written).
"""

from __future__ import annotations

import base64
import contextlib
import csv
import importlib.resources
import json
import os
import shutil
import time
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path

import numpy as np

from simulator.core.errors import InputError
from simulator.core.fileio import atomic_output, csv_uncell, json_text
from simulator.core.progress import Counter
from simulator.epof.viewing import EPOF_COLUMNS, read_epof_csv
from simulator.export.unity import VERSION as DATA_VERSION
from simulator.export.web import JS_FILES, MANIFEST_VERSION, export_web, js_source
from simulator.media.source import Source
from simulator.media.video import VideoWriter, probe
from simulator.mitigation.cao2021 import cao_grf_config
from simulator.mitigation.grf import GrfConfig
from simulator.report import pages
from simulator.study.tasks import _rule as study_rule

__all__ = [
    "BROWSER_WIDTH",
    "MANIFEST",
    "MAX_WEB_SIDE",
    "ReportResult",
    "browser_copy",
    "build_report",
    "check_browser_width",
    "check_report_folder",
    "check_study",
]

MANIFEST = ".vimsim-report.json"
ASSETS = ("report.css", "report.js", "replay.js")
#: Largest side (pixels) a browser copy may have: WebGL2 guarantees 2048, every current
#: desktop browser 4096 or more.
MAX_WEB_SIDE = 4096
#: Default width (pixels) of a browser copy (``--browser-width``): the replay shows a
#: ~100 deg view of it in a window of at most ~1280 px, i.e. ~3.5 source px per view px at
#: 2048 wide (sharper than the screen); a wider or non-H.264 source is scaled to fit.
BROWSER_WIDTH = 2048
#: x264 preset of a re-encoded browser copy: the fastest that keeps the replay sharp at the
#: report's view size (bench/report_4k.py prints the view PSNR of each preset).
BROWSER_PRESET = "superfast"
BROWSER_CRF = 20


@dataclass(frozen=True)
class ReportResult:
    """What :func:`build_report` wrote: the folder, its index page, file count, seconds."""

    folder: Path
    index: Path
    files: int
    seconds: float
    copies: dict


def check_study(outdir: str | os.PathLike) -> tuple[Path, dict]:
    """``(OUTDIR, study.json)`` of a complete study; InputError naming what is missing."""
    out = Path(outdir)
    if not out.is_dir():
        raise InputError(f"{out}: no such study folder (run vimsim study -o {out} first)")
    sj = out / "study.json"
    try:
        s = json.loads(sj.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputError(
            f"{out}: not a complete vimsim study (no study.json: the study did not finish)"
        ) from None
    except (OSError, ValueError, RecursionError) as e:
        raise InputError(f"{sj}: unreadable study summary ({e.__class__.__name__})") from None
    if not isinstance(s, dict) or s.get("format") != "vimsim-study":
        raise InputError(f"{sj}: not a vimsim study summary")
    for need in ("viewings.csv", "epof"):
        if not (out / need).exists():
            raise InputError(f"{out}: not a complete vimsim study ({need} is missing)")
    return out, s


def check_report_folder(folder: Path) -> set[str]:
    """Files an earlier report wrote into ``folder``; InputError for any other file."""
    if not folder.exists():
        return set()
    if not folder.is_dir():
        raise InputError(f"{folder}: exists and is not a folder; refusing to replace it")
    try:
        listed = set(json.loads((folder / MANIFEST).read_text(encoding="utf-8"))["files"])
    except (OSError, ValueError, KeyError, TypeError, RecursionError):
        listed = set()
    for p in sorted(folder.rglob("*")):
        rel = p.relative_to(folder).as_posix()
        if p.is_dir() and not p.is_symlink() or rel == MANIFEST:
            continue
        if rel not in listed:
            raise InputError(
                f"{p}: was not written by vimsim report; refusing to replace the report "
                "folder (move the file away)"
            )
    return listed


def _viewings(out: Path) -> list[dict]:
    """viewings.csv rows (columns read by name; extra columns kept)."""
    with open(out / "viewings.csv", newline="", encoding="utf-8") as f:
        rows = [{k: csv_uncell(v) if isinstance(v, str) else v for k, v in r.items()}
                for r in csv.DictReader(f)]  # fmt: skip -- the text as written, unguarded
    for need in ("viewing", "video", "status"):
        if rows and need not in rows[0]:
            raise InputError(f"{out / 'viewings.csv'}: no {need!r} column")
    return rows


def _source_key(path: Path) -> str:
    st = path.stat()
    return f"{st.st_size}:{st.st_mtime_ns}"


def check_browser_width(width) -> int:
    """``--browser-width`` as an int: InputError unless a positive even number of pixels
    no larger than :data:`MAX_WEB_SIDE`."""
    try:
        w = int(width)
    except (TypeError, ValueError):
        w = -1
    if str(width).strip() != str(w) or w <= 0 or w % 2 or w > MAX_WEB_SIDE:
        raise InputError(
            f"--browser-width must be a positive even number of pixels <= {MAX_WEB_SIDE} "
            f"(e.g. 2048); got {width!r}"
        )
    return w


def browser_copy(
    src: str | os.PathLike, dst: Path, layout: str = "mono", eye: str = "left",
    projection: str = "equirect", lens_fov_deg: float | None = None, *,
    width: int = BROWSER_WIDTH, explicit: bool = False, progress=None,
) -> dict:  # fmt: skip
    """The study's browser copy of a video: H.264 yuv420p MP4 (no audio), the source's
    (left-eye) equirect at most ``width`` pixels wide (:data:`BROWSER_WIDTH`):
    the source itself or a stream copy when it already is H.264 yuv420p mono equirect
    that wide or less, else scaled and encoded (x264 :data:`BROWSER_PRESET`). Another
    ``projection`` (the replay draws an equirect texture) is converted to its equirect
    working frame (:class:`simulator.media.source.Source`; uncovered directions black),
    as every vimsim command sees it. ``explicit``: the width was asked for
    (``--browser-width``): InputError when it is wider than the source's equirect.
    ``progress(done, total)`` is told of the frames encoded.

    Returns ``{"how", "width", "height", "start_s"}``: ``start_s`` is what to add to the
    copy's media time to get the source's clock (the clock of the EPOF rows and head
    paths): 0 for a copy or stream copy (they keep the source's timestamps), the source's
    first frame time for a re-encoding (which starts at 0; a video stream starting after
    its container's start, e.g. 1 s after its audio, would otherwise replay that much
    early)."""
    import av

    info = probe(src)
    with av.open(str(src)) as c:
        s = c.streams.video[0]
        codec, pix = s.codec_context.name, s.codec_context.pix_fmt
        mp4 = "mp4" in c.format.name.split(",") and len(c.streams.video) == 1
    w, h = info.width, info.height
    plain = layout == "mono" and projection == "equirect"
    if explicit and plain and width > w:
        raise InputError(f"{src}: --browser-width {width} is wider than the video ({w} px); "
                         f"give at most {w - w % 2}")  # fmt: skip
    playable = plain and codec == "h264" and pix == "yuv420p" and w <= width and h <= MAX_WEB_SIDE
    if playable and mp4:
        with atomic_output(dst) as tmp:
            shutil.copyfile(src, tmp)
        return {"how": "copy of the source (H.264 MP4)", "width": w, "height": h, "start_s": 0.0}
    if playable:
        _stream_copy(src, dst)
        return {"how": "stream copy into MP4", "width": w, "height": h, "start_s": 0.0}
    # a variable-rate source keeps its frame times (from its first frame), as the replay seeks them
    times = info.times_s() if info.variable_rate else None
    start_s = float(info.times_s([0])[0])
    if plain:
        size = _fit(w, h, width)
        _scaled_copy(src, dst, info, size, times, progress, w)
    else:
        size = _converted_copy(src, dst, info, (layout, projection, eye, lens_fov_deg), width,
                               times, explicit, progress)  # fmt: skip
    how = f"re-encoded (H.264 {BROWSER_PRESET} crf {BROWSER_CRF}, {size[0]}x{size[1]})"
    return {"how": how, "width": size[0], "height": size[1], "start_s": start_s}


def _fit(w: int, h: int, width: int) -> tuple[int, int]:
    """Even ``(width, height)`` of a ``w x h`` frame scaled down to at most ``width`` wide
    and :data:`MAX_WEB_SIDE` high (never up)."""
    k = min(1.0, width / w, MAX_WEB_SIDE / h)
    return max(2, round(w * k / 2) * 2), max(2, round(h * k / 2) * 2)


def _stream_copy(src, dst: Path) -> None:
    """The video stream of ``src`` into an MP4 at ``dst`` as it is (no decoding)."""
    import av

    with atomic_output(dst) as tmp, av.open(str(src)) as ic:
        oc = av.open(str(tmp), "w", format="mp4", options={"movflags": "+faststart"})
        try:
            st = oc.add_stream_from_template(ic.streams.video[0])
            for pkt in ic.demux(ic.streams.video[0]):
                if pkt.size == 0:  # the demuxer's end-of-stream flush packet
                    continue
                pkt.stream = st
                oc.mux(pkt)
        finally:
            oc.close()


def _scaled_copy(src, dst: Path, info, size, times, progress, w: int) -> None:
    """A mono equirect source decoded on FFmpeg's threads, scaled by swscale (area) to
    ``size`` in yuv420p and encoded, frame for frame: no RGB round trip; a copy at half the
    source's width or less skips the decoder's deblocking."""
    import av

    counter = Counter(progress, info.n_frames)
    # each frame at its own time (constant rate too): pts in the writer's 1/90000 s
    times = info.times_s() if times is None else times
    with av.open(str(src)) as ic, VideoWriter(dst, info.fps, size, crf=BROWSER_CRF,
                                              preset=BROWSER_PRESET, times_s=times) as vw:  # fmt: skip
        st = ic.streams.video[0]
        st.thread_type = "AUTO"
        # The copy is scaled down: the decoder's in-loop deblocking (H.264/HEVC) is skipped,
        # ~1.7x faster for 4K HEVC; what it changes is under the area scaling (47-53 dB
        # at 2048 px, against ~31 dB of the x264 encoding itself: bench/report_4k.py).
        if size[0] * 2 <= w:
            st.codec_context.options = {"skip_loop_filter": "all"}
        for f in ic.decode(st):
            nf = f.reformat(width=size[0], height=size[1], format="yuv420p", interpolation="AREA")
            nf.time_base = Fraction(1, 90000)
            vw.encode(nf)
            vw.n_written += 1
            counter.update()


def _converted_copy(src, dst: Path, info, how, width, times, explicit, progress):
    """Another layout or projection: the eye's equirect working frame (RGB) scaled to fit
    ``width`` and encoded; returns the copy's size."""
    import cv2

    layout, projection, eye, lens_fov_deg = how
    source = Source.open(src, layout=layout, projection=projection, eye=eye,
                         lens_fov_deg=lens_fov_deg, orientation=False)  # fmt: skip
    frames = source.frames(fmt="rgb24")  # the eye, converted to equirect
    first = next(frames)
    fh, fw = first.shape[:2]
    if explicit and width > fw:
        raise InputError(f"{src}: --browser-width {width} is wider than the video's equirect "
                         f"frame ({fw} px); give at most {fw - fw % 2}")  # fmt: skip
    size = _fit(fw, fh, width)
    counter = Counter(progress, info.n_frames)
    with VideoWriter(dst, info.fps, size, crf=BROWSER_CRF, preset=BROWSER_PRESET,
                     times_s=times) as vw:  # fmt: skip
        for f in _chain(first, frames):
            vw.write(f if (f.shape[1], f.shape[0]) == size else
                     cv2.resize(f, size, interpolation=cv2.INTER_AREA))  # fmt: skip
            counter.update()
    return size


def _layout(grid: Path) -> dict:
    """How the grid's source was read: ``browser_copy``'s ``layout``, ``eye``,
    ``projection`` and ``lens_fov_deg`` (mono equirect, left, when unknown)."""
    try:
        with np.load(grid, allow_pickle=False) as z:
            meta = json.loads(str(z["meta"]))
    except (OSError, ValueError, KeyError):
        meta = {}
    src = meta.get("source") if isinstance(meta.get("source"), dict) else {}
    lens = src.get("lens_fov_deg")
    return {"layout": str(meta.get("layout") or "mono"), "eye": str(meta.get("eye") or "left"),
            "projection": str(meta.get("projection") or "equirect"),
            "lens_fov_deg": None if lens is None else float(lens)}  # fmt: skip


def _chain(first, rest):
    yield first
    yield from rest


def _asset(name: str) -> bytes:
    return importlib.resources.files("simulator.report").joinpath("assets", name).read_bytes()


def _grf(settings: dict) -> GrfConfig:
    """The replay's grains: the study's ``[grf]``, or the authors' with ``preset = "cao2021-code"``."""
    g = settings.get("grf") or {}
    if (settings.get("epof") or {}).get("preset") == "cao2021-code":
        return cao_grf_config(seed=int(g.get("seed", 0)))
    return GrfConfig(**{k: g[k] for k in ("grain_deg", "density", "inner_deg", "outer_deg",
                                          "seed") if k in g})  # fmt: skip


def _video_data(
    out: Path, tmp: Path, s: dict, vid: str, vinfo: dict, old: Path, copies: dict, copy_opts: dict
) -> dict:
    """data/<vid>/ (the web export), media/<vid>.mp4 (the browser copy, reused from the old
    report when the source is unchanged), media/<vid>/ (the study's plots, thumbnails)."""
    epof = s["settings"]["epof"]
    grid = Path(vinfo.get("grid", ""))
    res = {"id": vid, "export": None, "copy": None, "plots": [], "moments": []}
    made = ((s.get("outputs") or {}).get("videos") or {}).get(vid) or {}
    res["artefacts_left_out"] = int(made.get("artefact_frames_left_out") or 0)
    res["artefact_kinds"] = dict(made.get("artefact_kinds") or {})
    if grid.is_file():
        # The export's formats are in the key: a report made before a format change is
        # exported again, not copied.
        key = json.dumps([_source_key(grid), epof, s["settings"].get("grf"), DATA_VERSION,
                          MANIFEST_VERSION], sort_keys=True)  # fmt: skip
        prev = (copies.get(vid) or {}).get("export")
        if prev and prev.get("key") == key and (old / "data" / vid).is_dir():
            shutil.copytree(old / "data" / vid, tmp / "data" / vid, copy_function=os.link)
            res["export"] = prev
        else:
            e = export_web(grid, tmp / "data" / vid, method=epof.get("method", "auto"),
                           hfov_deg=epof.get("hfov_deg"), vfov_deg=epof.get("vfov_deg"),
                           rule=study_rule(epof), grf=_grf(s["settings"]), example=False)  # fmt: skip
            res["export"] = {"mode": e.mode, "fps": e.header["fps"], "key": key,
                             "viewport": e.header["viewport"]}  # fmt: skip
    src = Path(vinfo.get("path", ""))
    (tmp / "media" / vid).mkdir(parents=True, exist_ok=True)
    if src.is_file():
        key = f"{_source_key(src)}:{copy_opts['width']}"
        prev = (copies.get(vid) or {}).get("copy")
        target = tmp / "media" / f"{vid}.mp4"
        # (a copy from before "start_s" was recorded is made again)
        reuse = prev and prev.get("key") == key and "start_s" in prev
        if reuse and (old / "media" / f"{vid}.mp4").is_file():
            os.link(old / "media" / f"{vid}.mp4", target)
            res["copy"] = prev
        else:
            res["copy"] = {**browser_copy(src, target, **_layout(grid), **copy_opts), "key": key}
    vdir = out / "videos" / vid
    for name in ("epof_viewers.png", "provocative.png"):
        if (vdir / name).is_file():
            shutil.copyfile(vdir / name, tmp / "media" / vid / name)
            res["plots"].append(name)
    if (vdir / "moments.csv").is_file():
        with open(vdir / "moments.csv", newline="", encoding="utf-8") as f:
            for m in csv.DictReader(f):
                th = m.get("thumbnail", "")
                if th and (vdir / th).is_file():
                    shutil.copyfile(vdir / th, tmp / "media" / vid / th)
                res["moments"].append(m)
    return res


def _viewing_data(out: Path, row: dict, s: dict) -> dict | None:
    """Timeline and replay data of one viewing (its EPOF CSV), or None when it has none."""
    p = out / "epof" / f"{row['viewing']}.csv"
    if row.get("status") != "ok" or not p.is_file():
        return None
    cols = {c: base64.b64encode(np.ascontiguousarray(v, "<f4").tobytes()).decode()
            for c, v in _epof_columns(p).items()}  # fmt: skip
    rs = s["settings"].get("render") or {}
    return {"viewing": row["viewing"], "video": row["video"], "columns": cols,
            "render": rs, "grf": s["settings"].get("grf"),
            "rendered": (out / "render" / row["viewing"] / "summary.json").is_file()}  # fmt: skip


def _epof_columns(path: Path) -> dict:
    """The EPOF CSV's columns (:data:`EPOF_COLUMNS`), float64: a fast read of the file the
    study wrote; anything unusual goes through :func:`read_epof_csv` (the checked reader)."""
    try:
        lines = [ln for ln in path.read_text(encoding="utf-8").splitlines() if ln and ln[0] != "#"]
        head = lines[0].split(",")
        idx = [head.index(c) for c in EPOF_COLUMNS]
        a = np.array(",".join(lines[1:]).split(","), np.float64).reshape(len(lines) - 1, len(head))
        return {c: a[:, i] for c, i in zip(EPOF_COLUMNS, idx)}
    except (ValueError, IndexError):
        r = read_epof_csv(path)
        return {c: np.asarray(getattr(r, c), np.float64) for c in EPOF_COLUMNS}


def _write(folder: Path, rel: str, data: bytes | str, written: list[str]) -> None:
    p = folder / rel
    p.parent.mkdir(parents=True, exist_ok=True)
    p.write_bytes(data.encode("utf-8") if isinstance(data, str) else data)
    written.append(rel)


def _as_output_error(e: OSError, tmp: Path, folder: Path) -> OSError:
    """``e`` naming the file of ``folder`` that a failed write under ``tmp`` was for."""
    name = folder
    if e.filename is not None:
        with contextlib.suppress(ValueError):
            name = folder / Path(os.fsdecode(e.filename)).relative_to(tmp)
    return OSError(e.errno, e.strerror or str(e), str(name))


def build_report(
    outdir: str | os.PathLike, *, browser_width: int | None = None, progress=None
) -> ReportResult:
    """Write ``OUTDIR/report/`` for a complete study (see the module docstring).

    ``browser_width``: the browser copies' width (``--browser-width``; default
    :data:`BROWSER_WIDTH`, InputError if wider than a video); ``progress(done, total)``
    is told of the frames of each copy being encoded."""
    t0 = time.perf_counter()
    explicit = browser_width is not None
    copy_opts = {"width": check_browser_width(browser_width) if explicit else BROWSER_WIDTH,
                 "explicit": explicit, "progress": progress}  # fmt: skip
    out, s = check_study(outdir)
    folder = out / "report"
    listed = check_report_folder(folder)
    rows = _viewings(out)
    old_copies = {}
    with contextlib.suppress(OSError, ValueError, KeyError, TypeError, RecursionError):
        old_copies = json.loads((folder / MANIFEST).read_text(encoding="utf-8"))["copies"]
    _remove_stale(out)
    tmp = out / f".report-tmp-{os.getpid()}"
    shutil.rmtree(tmp, ignore_errors=True)
    try:
        tmp.mkdir()
        written: list[str] = []
        for n in ASSETS:
            _write(tmp, f"assets/{n}", _asset(n), written)
        for n in JS_FILES:
            _write(tmp, f"assets/{n}", js_source(n), written)
        videos = {}
        for vid, vinfo in (s.get("videos") or {}).items():
            videos[vid] = _video_data(out, tmp, s, vid, vinfo, folder, old_copies, copy_opts)
        site = pages.Site(s, rows, videos)
        for rel, html in site.static_pages():
            _write(tmp, rel, html, written)
        for row in rows:
            data = _viewing_data(out, row, s)
            _write(tmp, pages.viewing_href(row["viewing"]), site.viewing_page(row, data), written)
        _write(tmp, "analysis.html", site.analysis_page(out / "analysis"), written)
        if (out / "analysis" / "boxplots.png").is_file():
            _write(
                tmp,
                "media/analysis/boxplots.png",
                (out / "analysis" / "boxplots.png").read_bytes(),
                written,
            )
        for p in sorted(tmp.rglob("*")):
            rel = p.relative_to(tmp).as_posix()
            if p.is_file() and rel not in written:
                written.append(rel)
        copies = {v: {"copy": d["copy"], "export": d["export"]} for v, d in videos.items()}
        (tmp / MANIFEST).write_text(
            json_text({"command": "report", "files": sorted(written), "copies": copies}) + "\n"
        )
        _swap(folder, tmp, listed)
    except OSError as e:  # a full disk: named as the report's file, not the temporary one
        raise _as_output_error(e, tmp, folder) from None
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return ReportResult(folder, folder / "index.html", len(written), time.perf_counter() - t0,
                        copies)  # fmt: skip


def _remove_stale(out: Path) -> None:
    """Temporary folders of builds that were killed (their process is gone)."""
    for p in [*out.glob(".report-tmp-*"), *out.glob(".report-old-*")]:
        try:
            pid = int(p.name.rsplit("-", 1)[1])
            os.kill(pid, 0)
        except ProcessLookupError:
            shutil.rmtree(p, ignore_errors=True)
        except (ValueError, PermissionError, OSError):
            continue


def _swap(folder: Path, tmp: Path, listed: set[str]) -> None:
    """Replace the old report (only files it listed) by the new one."""
    if folder.exists():
        old = folder.with_name(f".report-old-{os.getpid()}")
        folder.rename(old)
        try:
            tmp.rename(folder)
        except OSError:
            old.rename(folder)
            raise
        shutil.rmtree(old, ignore_errors=True)
    else:
        tmp.rename(folder)
