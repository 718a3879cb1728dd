"""Eye views at chosen moments of a viewing, rendered as ``vimsim render`` would, to lossless PNGs plus ``frames.json``.

For visual regression tests (:mod:`simulator.testing.compare`, :mod:`simulator.testing.goldens`): the
same inputs give byte-identical PNGs on the same machine. The frame shown at video time
``t`` (seconds) is frame ``floor(t * fps)`` (the one on screen during
``[i / fps, (i + 1) / fps)``); it is rendered with the head pose and GRF opacity that
``vimsim render`` uses for that frame (:func:`simulator.viewing.plan.plan_viewing`), by the
same GL eye renderer, read back as RGB (``render`` converts the same pass to yuv420p
for x264). Only the needed frames are decoded: the decoder seeks to the key frame
before each one.
"""

from __future__ import annotations

import bisect
import concurrent.futures
import importlib.metadata
import math
import os
import platform
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from simulator.core.choices import EYES
from simulator.core.errors import InputError
from simulator.core.fileio import OutputFolder, atomic_output, json_text
from simulator.core.progress import Counter, Progress
from simulator.media.source import as_source
from simulator.media.video import iter_frames, probe
from simulator.mitigation.kinds import KINDS
from simulator.render.eye import EyeRenderer
from simulator.render.gl import create_context
from simulator.render.sampling import sampled_projection
from simulator.sphere.geometry import head_rotation
from simulator.viewing.plan import grf_settings, plan_viewing
from simulator.viewing.spec import ViewSpec

__all__ = ["FRAMES_JSON", "decode_frames", "frame_name", "moments", "render_frames"]

#: The index file of a frames folder, written last (the folder is complete when it exists).
FRAMES_JSON = "frames.json"
#: The most moments one ``frames`` run renders (``--every``, ``--at``): each is a PNG per eye.
MAX_MOMENTS = 10_000


def frame_name(time_s: float, eye: str) -> str:
    """PNG name of the view at ``time_s`` (ms precision) for ``eye`` (left/right/both):
    ``t0012.500_left.png``; names sort by time."""
    return f"t{time_s:08.3f}_{eye}.png"


def moments(
    n_frames: int, fps: float, *, at=None, every: float | None = None, source: str = "video"
) -> list[float]:
    """The requested video times (seconds, rounded to 1 ms, sorted, duplicates dropped).

    ``at``: a list of times or a comma-separated string (``"1,2.5,10"``); ``every``: a
    step in seconds (>= 1 ms) from 0 to the end. Exactly one; at most :data:`MAX_MOMENTS`
    times (checked before any list is made). Every time must lie in the video,
    ``0 <= t < n_frames / fps``; else InputError.
    """
    end = n_frames / fps
    if (at is None) == (every is None):
        raise InputError("give the moments as --at T1,T2,... or --every S (one of them)")
    if every is not None:
        every = float(every)
        if not (every >= 0.001 and math.isfinite(every)):  # times are kept to 1 ms
            raise InputError(f"--every must be at least 0.001 seconds, e.g. 2; got {every:g}")
        if end / every > MAX_MOMENTS:  # checked before a list is made (memory)
            raise InputError(
                f"--every {every:g} s gives {math.ceil(end / every):,} moments in {end:g} s of "
                f"video; at most {MAX_MOMENTS:,} (a larger step, or --at)"
            )
        times = list(np.arange(0.0, end, every))
    else:
        if isinstance(at, str):
            parts = [p.strip() for p in at.split(",")]
            if not at.strip() or any(not p for p in parts):
                raise InputError(f"--at must list times in seconds, e.g. 1,2.5,10; got {at!r}")
            try:
                times = [float(p) for p in parts]
            except ValueError:
                raise InputError(
                    f"--at must list times in seconds, e.g. 1,2.5,10; got {at!r}"
                ) from None
        else:
            times = [float(t) for t in at]
        if not times:
            raise InputError("--at is empty; give times in seconds, e.g. 1,2.5,10")
        if len(times) > MAX_MOMENTS:
            raise InputError(f"--at lists {len(times):,} times; at most {MAX_MOMENTS:,}")
    out = sorted({round(t, 3) for t in times})
    bad = [t for t in out if not (math.isfinite(t) and 0.0 <= t < end)]
    if bad:
        raise InputError(
            f"{source}: time {bad[0]:g} s is outside the video (0 to {end:g} s exclusive, "
            f"{n_frames} frames at {fps:g} fps)"
        )
    return out


def frame_index(time_s: float, fps: float) -> int:
    """The frame on screen at ``time_s``: ``floor(t * fps)`` (1e-6 frame of slack for
    times written in decimal, e.g. 0.1 s at 30 fps is frame 3)."""
    return math.floor(time_s * fps + 1e-6)


def decode_frames(path, indices) -> dict[int, NDArray[np.uint8]]:
    """Decode only the frames ``indices`` of a video (full stored frames, RGB uint8).

    Frame numbers are decode order, as :func:`simulator.media.video.iter_frames` counts them,
    found from presentation times (constant frame rate): for each wanted frame the
    decoder seeks to the key frame before it and decodes forward. A stream without
    timestamps, or a seek that lands past the frame, falls back to decoding from the
    start.
    """
    import av

    want = sorted({int(i) for i in indices})
    info = probe(path)
    if info.variable_rate:  # frame numbers are not pts x fps: decode in order
        return _decode_sequential(iter_frames(path), want)
    out: dict[int, NDArray[np.uint8]] = {}
    with av.open(str(path)) as c:
        s = c.streams.video[0]
        s.thread_type = "AUTO"
        tb = s.time_base
        first = next(c.decode(s), None)
        if first is None or first.pts is None or tb is None:
            return _decode_sequential(iter_frames(path), want)
        pts0 = first.pts

        def index(pts) -> int:
            return round(float((pts - pts0) * tb) * info.fps)

        # Key frames from the packets (demuxing decodes nothing): seek only when the key
        # frame before the wanted frame lies beyond what the decoder has reached.
        c.seek(pts0, stream=s, backward=True, any_frame=False)
        keys = sorted(index(pk.pts) for pk in c.demux(s) if pk.is_keyframe and pk.pts is not None)
        gen, pos = None, -1  # live decoder and its last frame
        for target in want:
            if target in out:
                continue
            k = bisect.bisect_right(keys, target) - 1
            key = keys[k] if k >= 0 else 0
            if gen is None or key > pos or target <= pos:
                c.seek(pts0 + math.floor(key / info.fps / tb), stream=s, backward=True)
                gen = c.decode(s)
            for f in gen:
                if f.pts is None:
                    gen = None
                    break
                pos = idx = index(f.pts)
                if idx in want and idx not in out and idx <= target:
                    out[idx] = f.to_ndarray(format="rgb24")
                if idx >= target:
                    break
            else:
                gen = None
            if target not in out:  # the seek landed past it, or no timestamps
                out.update(_decode_sequential(iter_frames(path), [target]))
                gen = None
    missing = [i for i in want if i not in out]
    if missing:
        raise InputError(f"{path}: has no frame {missing[0]}")
    return out


def _decode_sequential(frames, want) -> dict[int, NDArray[np.uint8]]:
    out = {}
    last = max(want)
    for i, f in enumerate(frames):
        if i in want:
            out[i] = np.array(f)
        if i >= last:
            break
    return out


def _versions(ctx) -> dict:
    import av
    import moderngl
    import PIL

    return {
        "vimsim": importlib.metadata.version("vimsim"),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "moderngl": moderngl.__version__,
        "av": av.__version__,
        "pillow": PIL.__version__,
        "gl_renderer": ctx.info.get("GL_RENDERER"),
        "gl_version": ctx.info.get("GL_VERSION"),
        "gl_vendor": ctx.info.get("GL_VENDOR"),
    }


def _write_png(path: Path, img: NDArray[np.uint8]) -> None:
    """Write ``img`` as a PNG atomically. zlib level 1: lossless like every level; for a
    480x480 petra view 6.5x faster to write than Pillow's default 6, 402 kB vs 411 kB."""
    from PIL import Image

    with atomic_output(path) as tmp:
        Image.fromarray(img).save(tmp, format="PNG", compress_level=1)


def _draw_frames(ctx, source, plan, config, out: Path, times, eyes, progress) -> list[dict]:
    """Render the eye views at ``times`` into ``out`` as PNGs (written by two threads while
    the next view renders); the rows of ``frames.json``. A failure removes this run's PNGs."""
    info, stereo = plan.info, source.stereo
    if info.variable_rate:  # the frame on screen by the stream's timestamps
        idx = [max(0, int(info.frame_at(t))) for t in times]
    else:
        idx = [frame_index(t, info.fps) for t in times]
    if source.still:  # an image made a clip: every frame is the image
        decoded = dict.fromkeys(idx, source.read_stored("left"))
        decoded_right = dict.fromkeys(idx, source.read_stored("right")) if source.right else None
    else:
        decoded = decode_frames(source.path, idx)
        decoded_right = decode_frames(source.right, idx) if source.right is not None else None
    proj = sampled_projection(ctx, source)  # frames as stored where the shader can sample them
    renderer = EyeRenderer(ctx, config, projection=proj, lens_fov_deg=source.lens_fov_deg)
    rows = []
    bar = Counter(progress, len(times))
    pool = concurrent.futures.ThreadPoolExecutor(max_workers=2, thread_name_prefix="vimsim-png")
    writes: list[concurrent.futures.Future] = []
    try:
        for t, i in zip(times, idx):
            for e in EYES if stereo else ("left",):
                held = decoded_right if e == "right" and decoded_right is not None else decoded
                view = source.eye_view(held[i], e, convert=proj == "equirect")
                renderer.upload(np.ascontiguousarray(view), e)
            yaw, pitch, roll = (float(v) for v in plan.angles_deg[i])
            R = head_rotation(yaw, pitch, roll).as_matrix()
            op = float(plan.opacity[i])
            for e in eyes:
                eye = "left" if e == "both" else e
                img = renderer.render(
                    R,
                    eye,
                    source=eye if stereo else "left",
                    opacity=op,
                    eye_offset=renderer.eye_offset(R, eye),
                )
                name = frame_name(t, e)
                # PNG encoding (zlib releases the GIL) overlaps the next render; the
                # renderer's buffer is reused, so the image is copied.
                writes.append(pool.submit(_write_png, out / name, np.array(img)))
                rows.append(
                    {
                        "file": name,
                        "eye": e,
                        "time_s": t,
                        "frame": i,
                        "frame_time_s": float(plan.times_s[i]),
                        **_head_angles(plan, i, (yaw, pitch, roll)),
                        "epof_dps": float(plan.epof_dps[i]),
                        "opacity": op,
                    }
                )
            bar.update(1)
        for f in writes:
            f.result()  # a failed write raises here
        bar.close()
    except BaseException:
        pool.shutdown(wait=True, cancel_futures=True)
        for r in rows:  # no frames.json: this run's PNGs would look like a finished run's
            (out / r["file"]).unlink(missing_ok=True)
        raise
    finally:
        pool.shutdown(wait=True, cancel_futures=True)
        renderer.release()
    return rows


def _index(source, plan, view: ViewSpec, headpath, rows: list[dict], ctx) -> dict:
    """The content of ``frames.json``: the inputs, the renderer's settings, versions, rows."""
    config, info = view.config, plan.info
    w, h = config.eye_size
    index = {
        "video": str(source.path),
        "video_size": [info.width, info.height],
        "fps": info.fps,
        "frames_video": info.n_frames,
        "headpath": str(headpath) if isinstance(headpath, (str, os.PathLike)) else None,
        "grid": None if plan.grid is None else (plan.grid.path or None),
        "layout": source.layout,
        "right": source.right,
        "projection": source.projection,
        "source": source.settings(),
        "hold": view.hold,
        "renderer": {
            "eye_size": [w, h],
            "hfov_deg": config.hfov_deg,
            "vfov_deg": config.vfov_deg,
            "grf": grf_settings(config.grains),
            "mitigation": config.mitigation.kind,
            "opacity": "off" if config.grf is None else view.opacity,
            "opacity_thresholds_dps": list(plan.thresholds_dps),
            "opacity_rule": None if plan.grid is None else (
                view.rule if plan.px_rule is None else plan.px_rule).describe(),
            "epof_method": plan.epof_method,
            "preset": view.preset,
        },
        "versions": _versions(ctx),
        "frames": rows,
    }
    return index


def render_frames(
    source,
    headpath,
    outdir,
    *,
    at=None,
    every: float | None = None,
    grid=None,
    view: ViewSpec | None = None,
    ctx=None,
    progress: Progress | None = None,
    **view_fields,
) -> dict:
    """Render the eye views at chosen video times into ``outdir`` as PNGs + ``frames.json``.

    Parameters
    ----------
    source, headpath, grid : as :func:`simulator.viewing.job.render_viewing`
        (``vimsim render``)
    view : :class:`simulator.viewing.spec.ViewSpec` (what the eye sees), or its fields as
        keywords (``config=``, ``opacity=``, ``rule=``, ``method=``, ``hold=``)
    at : times in seconds (list, or ``"1,2.5"``); or ``every``: a step in seconds
    ctx : moderngl.Context, or None to create one

    Eyes: ``left`` and ``right`` for a stereo layout or grains at a finite distance
    (parallax), else one view named ``both`` (both eyes see the same image). Inputs are
    checked before ``outdir`` is touched (a file of an output name that no earlier
    ``frames`` run wrote is refused: :class:`~simulator.core.fileio.OutputFolder`); then
    the files of the previous run listed in the folder's manifest are removed, each PNG
    appears only when complete, and ``frames.json`` is written last.

    Returns
    -------
    dict, the content of ``frames.json``: per frame (file, eye, requested time, frame
    number and its time, pose in degrees, EPOF deg/s, opacity), renderer settings and
    versions. Nothing time-varying, so that two runs give the same file.
    """
    view = ViewSpec.given(view, **view_fields)
    config = view.config
    if config.mitigation.local and config.grains is not None:
        raise InputError(
            f"frames: --mitigation {config.mitigation.kind} (per-cell opacity) is rendered by "
            f"`vimsim render` only; frames takes {', '.join(k for k, e in KINDS.items() if not e.local)}"
        )
    source = as_source(source)
    video = source.path
    plan = plan_viewing(
        source,
        headpath,
        grid=grid,
        view=view,
    )
    info = plan.info
    rate = info.n_frames / info.duration_s  # = fps unless the rate varies
    times = moments(info.n_frames, rate, at=at, every=every, source=str(video))
    stereo = source.stereo
    parallax = config.grf is not None and config.grf.distance_m is not None
    eyes = ("left", "right") if stereo or parallax else ("both",)
    out = Path(outdir)
    grid_path = plan.grid.path if plan.grid is not None else None
    inputs = {Path(p).resolve() for p in (*source.files, grid_path) if p}
    if not isinstance(headpath, (str, os.PathLike)):
        headpath = plan.headpath.source or headpath
    if isinstance(headpath, (str, os.PathLike)):
        inputs.add(Path(headpath).resolve())
    names = [frame_name(t, e) for t in times for e in eyes] + [FRAMES_JSON]
    for n in names:
        if (out / n).resolve() in inputs:
            raise InputError(f"{out / n}: output would overwrite an input; choose another -o")
    # The one folder rule: a PNG of an output name that no earlier `frames` run wrote
    # (no manifest lists it: a user's file, goldens copied here) is refused, never replaced.
    folder = OutputFolder(out, names, "frames")
    folder.check(inputs)
    if ctx is None:
        ctx = create_context()
    out = folder.prepare(inputs)

    rows = _draw_frames(ctx, source, plan, config, out, times, eyes, progress)
    index = _index(source, plan, view, headpath, rows, ctx)
    with atomic_output(out / FRAMES_JSON) as tmp:
        Path(tmp).write_text(json_text(index) + "\n")
    folder.complete()
    return index


def _head_angles(plan, i: int, view) -> dict:
    """The head's own angles at plan row ``i`` (``view``: the view's in the frame, the
    same without an initial orientation) as frames.json records them."""
    a = view if plan.head_angles_deg is None else plan.head_angles_deg[i]
    return dict(zip(("yaw_deg", "pitch_deg", "roll_deg"), (float(v) for v in a)))
