"""``vimsim screen``: a study whose viewers are scripted, then the screening report of each video.

Each video is preprocessed in sphere mode through the study's grid cache (or a grid the
user already made of it, when its video's content hash matches), watched by ``n``
scripted viewers (:func:`simulator.traces.path.synth`, seeds ``seed .. seed + n - 1``,
made in the study's EPOF tasks as a manifest's ``viewers = {kind, n, seed}`` are),
with artefacts (:mod:`simulator.preprocess.artefacts`) detected and left out. The study
writes ``viewings.csv``, ``epof/`` and ``videos/``; :mod:`simulator.screen.report` adds
``screen/<video>/`` and ``screen/comparison.csv``.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

from simulator.core.errors import InputError
from simulator.core.fileio import check_input_file
from simulator.discomfort.model import Model, load_model
from simulator.media.gridfile import content_hash, load_grid
from simulator.media.source import Source
from simulator.media.video import probe
from simulator.screen.report import SCREEN_COLUMNS, screen_folders, write_screen_outputs
from simulator.study.manifest import SCRIPTED, VIEWER_KINDS, Manifest, VideoSpec, ViewingSpec
from simulator.study.runner import run_study
from simulator.study.tasks import write_json

__all__ = ["SCREEN_COLUMNS", "VIEWER_KINDS", "check_viewers", "check_work", "screen_videos"]


def check_viewers(n, kind: str) -> None:
    """InputError unless ``n`` >= 1 scripted viewers of a known kind."""
    if isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= 100_000:
        raise InputError(f"--viewers must be an integer in 1..100000; got {n!r}")
    if kind not in VIEWER_KINDS:
        raise InputError(f"unknown viewer kind {kind!r}; expected one of {', '.join(VIEWER_KINDS)}")


#: Scripted viewers per video by default (``--viewers``).
DEFAULT_VIEWERS = 30
#: CPU seconds of one scripted viewing, and of each frame of it (exact EPOF on a small
#: grid, with room for a slower machine), and the estimate above which more viewers than
#: the default need ``force=True`` (``--force``): an hours-long screening is asked for.
VIEWING_CPU_S, FRAME_CPU_S, WORK_LIMIT_CPU_S = 0.02, 0.0003, 1800.0


def check_work(viewers: int, frames: list[int], *, force: bool = False) -> float:
    """The estimated CPU seconds of ``viewers`` scripted viewers of videos of ``frames``
    frames; InputError (before any work) when more viewers than the default would take
    longer than :data:`WORK_LIMIT_CPU_S` unless ``force``."""
    est = viewers * sum(VIEWING_CPU_S + n * FRAME_CPU_S for n in frames)
    if viewers > DEFAULT_VIEWERS and est > WORK_LIMIT_CPU_S and not force:
        raise InputError(
            f"--viewers {viewers}: about {est / 3600:.1f} CPU hours of EPOF ({viewers} viewers x "
            f"{sum(frames)} frames in {len(frames)} video(s)); pass --force to run it, or "
            "choose fewer viewers"
        )
    return est


def _video_id(path: Path, taken: set[str]) -> str:
    base = re.sub(r"[^A-Za-z0-9._-]", "_", path.stem).lstrip("._-") or "video"
    vid, k = base, 2
    while vid in taken:
        vid, k = f"{base}-{k}", k + 1
    taken.add(vid)
    return vid


def _matching_grid(
    video: Path, grids: list[Path], layout: str, projection: str = "equirect"
) -> Path | None:
    """The first of ``grids`` made of ``video`` (the content hash its meta records) with
    ``layout`` and ``projection``. Every grid is validated as ``epof`` does
    (:func:`~simulator.media.gridfile.load_grid`: InputError naming it for pickled or
    object members, a bad header or meta), matching or not."""
    if not grids:
        return None
    want = content_hash(video)
    for g in grids:
        meta = load_grid(g).meta
        if (meta.get("video", {}).get("content_hash") == want and meta.get("layout") == layout
                and (meta.get("projection") or "equirect") == projection):  # fmt: skip
            return g
    return None


def screen_videos(
    videos,
    outdir,
    *,
    viewers: int = 30,
    kind: str = "look-around",
    seed: int = 0,
    epof: dict | None = None,
    artefacts: bool = True,
    grids=(),
    layout: str = "mono",
    projection: str | None = None,
    lens_fov_deg: float | None = None,
    executor: str = "local",
    workers: int | None = None,
    cache_dir=None,
    progress=None,
    model=None,
    force: bool = False,
) -> dict:
    """Screen ``videos`` into ``outdir``; returns the study summary with ``screen`` added.

    ``epof``: the ``[epof]`` options of a study manifest (opacity rule, FOV); ``grids``:
    grid files the user already made (used for the video whose content they match);
    ``layout``: of every video (stereo: the left eye is screened); ``projection``,
    ``lens_fov_deg``: of every video (None: each file's spherical metadata, else equirect).
    ``model``: a discomfort model (:class:`simulator.discomfort.model.Model`, or the path of
    its JSON, checked before any work) whose predictions join the comparison table.
    InputError (nothing written) for no video, a still image, a missing file, bad viewers,
    more viewers than the default whose work estimate exceeds the limit unless ``force``
    (:func:`check_work`).
    """
    check_viewers(viewers, kind)
    if model is not None and not isinstance(model, Model):
        model = load_model(model)
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise InputError(f"--seed must be an integer >= 0; got {seed!r}")
    paths = [check_input_file(v, "video") for v in videos]
    if not paths:
        raise InputError("screen needs at least one video")
    grid_files = [check_input_file(g, "grid") for g in grids]
    sources, frames = {}, []
    for p in paths:
        info = probe(p)
        if not info.is_video or info.n_frames < 2:
            raise InputError(f"{p}: is a still image; screen needs a video")
        frames.append(int(info.n_frames))
        # the layout and projection must fit the frame (InputError naming the file)
        sources[p] = Source.open(p, layout=layout, projection=projection,
                                 lens_fov_deg=lens_fov_deg)  # fmt: skip
    check_work(viewers, frames, force=force)
    out = Path(outdir)
    taken: set[str] = set()
    specs, views, reused = [], [], {}
    for p in paths:
        vid = _video_id(p, taken)
        src = sources[p]
        g = _matching_grid(p, grid_files, src.layout, src.projection)
        if g is not None:
            reused[vid] = str(g)
        specs.append(VideoSpec(id=vid, path=p.resolve(), layout=src.layout, method="sphere",
                               grid_file=g, artefacts=artefacts, projection=src.projection,
                               lens_fov_deg=src.lens_fov_deg))  # fmt: skip
    width = max(3, len(str(viewers)))
    for spec in specs:  # viewer k: the scripted head path of seed + k - 1 (study tasks make it)
        for k in range(1, viewers + 1):
            views.append(ViewingSpec(f"{spec.id}-viewer{k:0{width}d}", spec.id, None,
                                     SCRIPTED + kind, seed + k - 1, f"viewer{k:0{width}d}"))  # fmt: skip
    folders = screen_folders(out, [spec.id for spec in specs])
    for f in folders:  # a user's file under OUTDIR/screen/: refused before any work
        f.check()
    opts = _epof_options(epof or {}, artefacts)
    m = Manifest(path=(out / "screen.toml").resolve(), name="screen", videos=tuple(specs),
                 viewings=tuple(views), epof=opts, render=_RENDER, grf={})  # fmt: skip
    summary = run_study(m, out, executor=executor, workers=workers, cache_dir=cache_dir,
                        progress=progress, video_outputs=False)  # fmt: skip
    summary["screen"] = write_screen_outputs(m, out, summary, artefacts=artefacts, model=model)
    summary["screen"]["reused_grids"] = reused
    summary["screen"]["unused_grids"] = [
        str(g) for g in grid_files if str(g) not in reused.values()
    ]
    summary["screen"]["viewers"] = {"n": viewers, "kind": kind, "seed": seed}
    summary["screen"]["artefacts"] = artefacts
    write_json(out / "screen" / "screen.json", {"format": "vimsim-screen", "version": 1,
               "study": "study.json", **summary["screen"]})  # fmt: skip
    folders[0].complete()
    return summary


#: A screening renders nothing; the study runner still reads these.
_RENDER = {"cpus": 1}


def _epof_options(given: dict, artefacts: bool) -> dict:
    """The study's ``[epof]`` options of a screening: as ``vimsim study`` defaults, the
    last pose held (a scripted path covers the video anyway), ``artefacts`` as asked."""
    d = {
        "hfov_deg": None, "vfov_deg": None, "method": "auto", "top_k": None, "hold_last": True,
        "low_pct": 10.0, "high_pct": 90.0, "opacity_source": "grid", "smooth_s": 0.0,
        "opacity_rule": "comfort", "ease_in_s": None, "ease_out_s": None,
    }  # fmt: skip
    d.update(given)
    d["artefacts"] = bool(artefacts)
    for k in ("low_dps", "high_dps"):
        v = d.get(k)
        if v is not None and not math.isfinite(v):
            raise InputError(f"--{k.replace('_', '-')} must be finite; got {v}")
    return d
