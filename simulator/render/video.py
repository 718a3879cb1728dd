"""Rendering whole videos: decode, render each eye, encode per-eye H.264 files.

Frames are decoded once (:func:`simulator.media.video.prefetch`), rendered per eye
(:class:`simulator.render.eye.EyeRenderer`) and leave the GPU as yuv420p planes for the
encoder. Output files are written to temporary names and renamed when complete.
"""

from __future__ import annotations

import contextlib
import functools
import queue
import shutil
import threading
import time
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from simulator.core.errors import InputError
from simulator.core.fileio import atomic_output
from simulator.core.progress import Counter, Progress
from simulator.media.video import VideoWriter, iter_frames, prefetch, probe
from simulator.render.eye import EyeRenderer, RenderConfig
from simulator.sphere.geometry import head_rotation, split_eye

__all__ = ["VideoRenderResult", "render_video"]


@dataclass(frozen=True)
class VideoRenderResult:
    """What :func:`render_video` did: frames written per eye and wall-clock seconds."""

    n_frames: int
    eye_size: tuple[int, int]
    fps: float
    timings_s: dict[str, float]

    @property
    def frames_per_s(self) -> float:
        t = self.timings_s.get("total", 0.0)
        return self.n_frames / t if t > 0 else float("nan")


def _write_yuv420p(writer, frame: NDArray[np.uint8]) -> None:
    """Encode one frame already in yuv420p (``(h * 3 // 2, w)`` uint8, the layout of
    :meth:`EyeRenderer.render` ``pix_fmt="yuv420p"``) with a ``simulator.media.video.VideoWriter``,
    skipping its rgb24 -> yuv420p conversion (the stream is yuv420p: x264 takes it as is)."""
    import av

    w, h = writer.size
    if frame.shape != (h * 3 // 2, w) or frame.dtype != np.uint8:
        raise ValueError(
            f"frame must be ({h * 3 // 2}, {w}) uint8 yuv420p; got {frame.shape} {frame.dtype}"
        )
    writer.encode(av.VideoFrame.from_ndarray(frame, format="yuv420p"))
    writer.n_written += 1


class _Worker:
    """A thread draining a bounded queue into ``fn``; errors resurface in :meth:`join`.

    ``inline=True``: no thread, :meth:`put` calls ``fn`` itself (a one-CPU render)."""

    def __init__(self, fn, maxsize: int = 3, name: str = "worker", inline: bool = False):
        self.q: queue.Queue = queue.Queue(maxsize=maxsize)
        self.fn = fn
        self.error: BaseException | None = None
        self.busy_s = 0.0
        self.t = None
        if not inline:
            self.t = threading.Thread(target=self._run, name=name, daemon=True)
            self.t.start()

    def _run(self) -> None:
        while True:
            item = self.q.get()
            if item is None:
                return
            if self.error is not None:
                continue  # drain after a failure
            t0 = time.perf_counter()
            try:
                self.fn(item)
            except BaseException as e:  # noqa: BLE001 - re-raised in join()
                self.error = e
            self.busy_s += time.perf_counter() - t0

    def put(self, item) -> None:
        if self.error is not None:
            raise self.error
        if self.t is None:
            t0 = time.perf_counter()
            self.fn(item)
            self.busy_s += time.perf_counter() - t0
            return
        self.q.put(item)

    def join(self) -> None:
        if self.t is not None:
            self.q.put(None)
            self.t.join()
        if self.error is not None:
            raise self.error


def _decode(video_path: str, right_path: str | None, start: int, end: int, threads=None):
    """Decoded frames ``start <= i < end`` (copies): of ``video_path``, or ``(left, right)``
    pairs of two per-eye files; both files are closed on every exit."""
    left = iter_frames(video_path, layout="mono", start=start, end=end, threads=threads)
    if right_path is None:
        try:
            for f in left:
                yield np.array(f)
        finally:
            left.close()
        return
    right = iter_frames(right_path, layout="mono", start=start, end=end, threads=threads)
    try:
        for fl in left:
            fr = next(right, None)
            if fr is None:
                raise InputError(f"{right_path}: right eye ends before the left eye ({video_path})")
            yield np.array(fl), np.array(fr)
    finally:
        left.close()
        right.close()


def render_video(
    ctx,
    video_path: str,
    out_paths: tuple[str | None, str | None],
    angles_deg: NDArray[np.float64],
    *,
    opacity: NDArray[np.float64] | None = None,
    cell_opacity: NDArray[np.float32] | None = None,
    config: RenderConfig = RenderConfig(),
    layout: str = "mono",
    fps: float | None = None,
    n_frames: int | None = None,
    preset: str = "veryfast",
    crf: int = 18,
    threads: int | None = None,
    progress: Progress | None = None,
    start_frame: int = 0,
    on_frame=None,
    audio=None,
    right_path: str | None = None,
    review_eye: str = "left",
) -> VideoRenderResult:
    """Render per-eye H.264 videos of a (mono or stereo) equirect video along a head path.

    Parameters
    ----------
    ctx : moderngl.Context from :func:`create_context`
    video_path : equirect video (or image: one frame)
    out_paths : (left.mp4, right.mp4); each appears only when complete (atomic rename);
        None for an eye not wanted (at least one path)
    angles_deg : ndarray, shape (N, 3), float64
        (yaw, pitch, roll) in degrees for video frame ``i`` (time ``i / fps``); frames
        beyond N hold the last pose
    opacity : ndarray, shape (N,), GRF / vignette opacity 0..1 per frame
    cell_opacity : ndarray, shape (N, n_lat, n_lon), local-grf's per-cell grain opacity
        per frame (:func:`simulator.mitigation.kinds.cell_opacity`); frames beyond N hold the last
    layout : ``mono`` (both eyes see the frame), ``top-bottom`` (left eye top) or
        ``side-by-side`` (left eye left)
    fps, n_frames : the video's rate and frame count (from :func:`simulator.media.video.probe`)
    start_frame : render video frames ``start_frame <= i < start_frame + n_frames`` only
        (a time range); row ``j`` of ``angles_deg`` and ``opacity`` is video frame
        ``start_frame + j``. Frames before it are decoded (not converted) and skipped.
    on_frame : None, or ``on_frame(equirect, eye_yuv420p)`` called for every rendered frame,
        in order, on a worker thread (overlapping rendering): the decoded equirect frame
        (left eye's for stereo, RGB) and the left eye's image (yuv420p planes, as encoded);
        its errors are raised here (e.g. :class:`simulator.viewing.review.ReviewWriter`).
    preset, crf : x264 speed preset and quality
    threads : the render's CPU budget. None: no bound (decoding and each eye's encoder
        overlap the drawing in threads of their own; FFmpeg and x264 pick their thread
        counts). ``n``: the decoder and each x264 encoder use ``n`` threads, and with
        ``n == 1`` decoding, drawing and encoding take turns on the calling thread, so
        the render keeps one core busy, not more (a study's task declaring one CPU:
        tasks side by side then scale with the cores). llvmpipe's threads are the
        process's ``LP_NUM_THREADS``, read when Mesa loads.
    audio : None, or a :class:`simulator.media.audio.AudioSource` (the source's audio, the
        range's part) carried into every eye file
    right_path : the right eye's equirect file: ``video_path`` is then the left eye's (two
        per-eye files, both decoded in step; same size and frame count, checked by the caller)
    review_eye : the eye whose image ``on_frame`` gets when both are rendered

    A mono video with grains at infinity gives the same image to both eyes: it is
    rendered and encoded once and ``right.mp4`` is a copy of ``left.mp4``. Frames are
    converted to yuv420p on the GL side (:meth:`EyeRenderer.render` ``pix_fmt``) and
    handed to x264 as they are.

    Returns
    -------
    VideoRenderResult with timings (seconds): ``decode_wait``, ``upload``, ``render``
    (draw, yuv420p conversion and readback of both eyes), ``encode_wait`` (blocked on the encoders),
    ``encode_busy`` (encoder threads' busy time, both eyes), ``total``.
    """
    info = probe(video_path)
    fps = float(fps or info.fps)
    start_frame = int(start_frame)
    if not (0 <= start_frame < info.n_frames):
        raise InputError(
            f"{video_path}: start frame {start_frame} outside the video's {info.n_frames} frames"
        )
    total = int(n_frames or info.n_frames - start_frame)
    ang = np.asarray(angles_deg, float).reshape(-1, 3)
    if ang.shape[0] < 1:
        raise InputError(f"{video_path}: no head orientations to render")
    op = None if opacity is None else np.clip(np.asarray(opacity, float).reshape(-1), 0.0, 1.0)
    rots = head_rotation(ang[:, 0], ang[:, 1], ang[:, 2]).as_matrix()
    stereo = layout != "mono" or right_path is not None
    # Mono video with grains at infinity: both eyes see exactly the same image, so it is
    # rendered and encoded once and the file copied (halves the work; same output).
    same = not stereo and (config.grains is None or config.grains.distance_m is None)
    if config.mitigation.local and config.grains is not None and cell_opacity is None:
        raise InputError("local-grf needs the per-cell opacity of a sphere-mode field")
    wanted = [e for e, p in zip(("left", "right"), out_paths) if p]
    if not wanted:
        raise ValueError("render_video needs at least one output path")
    paths = [p for p in out_paths if p]
    eyes = (wanted[0],) if same else tuple(wanted)
    renderer = EyeRenderer(ctx, config)
    w, h = config.eye_size
    timings = dict.fromkeys(("decode_wait", "upload", "render", "encode_wait"), 0.0)
    t_start = time.perf_counter()
    n = 0
    try:
        with contextlib.ExitStack() as stack:
            writers = [
                stack.enter_context(
                    VideoWriter(
                        p, fps, (w, h), crf=crf, preset=preset, audio=audio, threads=threads
                    )
                )
                for p in paths[: len(eyes)]
            ]
            serial = threads is not None and int(threads) <= 1
            workers = [
                _Worker(functools.partial(_write_yuv420p, wr), name=f"encode-{i}", inline=serial)
                for i, wr in enumerate(writers)
            ]
            if on_frame is not None:
                workers.append(
                    _Worker(lambda item: on_frame(*item), name="on-frame", inline=serial)
                )
            try:
                # Decoding overlaps rendering; decoder buffers are reused, so copy there.
                decoded = _decode(video_path, right_path, start_frame, start_frame + total, threads)
                frames = stack.enter_context(
                    contextlib.closing(decoded if serial else prefetch(decoded, depth=3))
                )
                bar = Counter(progress, total)
                t0 = time.perf_counter()
                for frame in frames:
                    t1 = time.perf_counter()
                    timings["decode_wait"] += t1 - t0
                    i = min(n, len(rots) - 1)
                    if right_path is not None:
                        renderer.upload(frame[0], "left")
                        renderer.upload(frame[1], "right")
                    elif stereo:
                        renderer.upload(split_eye(frame, layout, "left", source=video_path), "left")
                        renderer.upload(
                            split_eye(frame, layout, "right", source=video_path), "right"
                        )
                    else:
                        renderer.upload(frame, "left")
                    t2 = time.perf_counter()
                    o = 0.0 if op is None else float(op[min(n, len(op) - 1)])
                    co = None
                    if cell_opacity is not None and config.mitigation.local:
                        co = cell_opacity[min(n, len(cell_opacity) - 1)]
                    outs = []
                    for eye in eyes:
                        img = renderer.render(
                            rots[i],
                            eye,
                            source=eye if stereo else "left",
                            opacity=o,
                            eye_offset=renderer.eye_offset(rots[i], eye),
                            pix_fmt="yuv420p",
                            cell_opacity=co,
                        )
                        outs.append(img.copy())  # the buffer is reused
                    t3 = time.perf_counter()
                    for wk, img in zip(workers, outs):
                        wk.put(img)
                    if on_frame is not None:
                        k = eyes.index(review_eye) if review_eye in eyes else 0
                        if right_path is not None:
                            src = frame[0 if eyes[k] == "left" else 1]
                        elif stereo:
                            src = split_eye(frame, layout, eyes[k], source=video_path)
                        else:
                            src = frame
                        workers[-1].put((src, outs[k]))
                    t0 = time.perf_counter()
                    timings["upload"] += t2 - t1
                    timings["render"] += t3 - t2
                    timings["encode_wait"] += t0 - t3
                    n += 1
                    bar.update(1)
                bar.close()
            finally:
                errors = []
                for wk in workers:
                    try:
                        wk.join()
                    except BaseException as e:  # noqa: BLE001
                        errors.append(e)
                timings["encode_busy"] = sum(wk.busy_s for wk in workers[: len(writers)])
                if on_frame is not None:
                    timings["on_frame_busy"] = workers[-1].busy_s
            if errors:
                raise errors[0]
            if n == 0:
                raise InputError(f"{video_path}: no frames decoded")
        if same and len(paths) == 2:
            with atomic_output(paths[1]) as tmp:
                shutil.copyfile(paths[0], tmp)
    finally:
        renderer.release()
    timings["total"] = time.perf_counter() - t_start
    return VideoRenderResult(n, (w, h), fps, timings)
