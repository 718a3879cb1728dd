"""Rendering whole videos: decode, render each eye, encode per-eye H.264 files.

Frames are decoded once (:func:`simulator.media.video.prefetch`), rendered per eye
(:class:`simulator.render.eye.EyeRenderer`; a non-equirect source's frames as stored, its
projection sampled in the eye shader: no CPU conversion, :mod:`simulator.render.sampling`)
and leave the GPU as yuv420p planes for the
encoder as they are (:meth:`simulator.render.eye.EyeRenderer.render` ``pix_fmt``). Output
files are written to temporary names and renamed when complete. A mono video with grains
at infinity gives the same image to both eyes: it is rendered and encoded once and
``right.mp4`` is a copy of ``left.mp4``.

The CPU budget (``threads`` of :func:`render_video`): None, no bound (decoding and each
eye's encoder overlap the drawing in threads of their own; FFmpeg and x264 pick their
thread counts); ``n``, the decoder and each x264 encoder use ``n`` threads, and with
``n == 1`` decoding, drawing and encoding take turns on the calling thread, so the render
keeps one core busy, not more (a study's task declaring one CPU: tasks side by side then
scale with the cores). llvmpipe's threads are the process's ``LP_NUM_THREADS``, read when
Mesa loads.
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

from simulator.core.choices import EYES
from simulator.core.errors import InputError
from simulator.core.fileio import atomic_output
from simulator.core.progress import Counter, Progress
from simulator.media.source import as_source
from simulator.media.video import VideoWriter, prefetch
from simulator.render.eye import EyeRenderer, RenderConfig
from simulator.render.sampling import sampled_projection
from simulator.sphere.geometry import head_rotation

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


def render_video(
    ctx,
    source,
    out_paths: tuple[str | None, str | None],
    angles_deg: NDArray[np.float64],
    *,
    opacity: NDArray[np.float64] | None = None,
    cell_opacity: NDArray[np.float32] | None = None,
    config: RenderConfig = RenderConfig(),
    fps: float | None = None,
    n_frames: int | None = None,
    preset: str = "veryfast",
    crf: int = 18,
    threads: int | None = None,
    progress: Progress | None = None,
    start_frame: int = 0,
    on_frame=None,
    audio=None,
    review_eye: str = "left",
) -> VideoRenderResult:
    """Render per-eye H.264 videos of a (mono or stereo) equirect video along a head path.

    Parameters
    ----------
    ctx : moderngl.Context from :func:`create_context`
    source : the video: a :class:`simulator.media.source.Source` (mono or stereo layout, or
        two per-eye files, both decoded in step) or a path (mono equirect; an image: one frame)
    out_paths : (left.mp4, right.mp4); each appears only when complete (atomic rename);
        None for an eye not wanted (at least one path)
    angles_deg, opacity, cell_opacity : per rendered frame (rows beyond N hold the last):
        (yaw, pitch, roll) degrees ``(N, 3)``; GRF / vignette opacity 0..1 ``(N,)``;
        local-grf's per-cell grain opacity ``(N, n_lat, n_lon)``
    fps, n_frames : the video's rate and frame count (from :func:`simulator.media.video.probe`)
    start_frame : render video frames ``start_frame <= i < start_frame + n_frames`` only
        (a time range); row ``j`` of ``angles_deg`` and ``opacity`` is video frame
        ``start_frame + j``. Frames before it are decoded (not converted) and skipped.
    on_frame : None, or ``on_frame(equirect, eye_yuv420p)`` called for every rendered frame,
        in order, on a worker thread (overlapping rendering): the decoded equirect frame
        (left eye's for stereo, RGB) and the left eye's image (yuv420p planes, as encoded);
        its errors are raised here (e.g. :class:`simulator.viewing.review.ReviewWriter`).
    preset, crf : x264 speed preset and quality
    threads : the render's CPU budget (module docstring): None no bound, ``n`` threads
        for the decoder and each encoder, 1: one core
    audio : None, or a :class:`simulator.media.audio.AudioSource` (the source's audio, the
        range's part) carried into every eye file
    review_eye : the eye whose image ``on_frame`` gets when both are rendered

    Returns a VideoRenderResult with timings (seconds): ``decode_wait``, ``upload``,
    ``render`` (draw, yuv420p conversion, readback), ``encode_wait`` (blocked on the
    encoders), ``encode_busy`` (encoder threads' busy time, both eyes), ``total``.
    """
    source = as_source(source)
    fps = float(fps or source.info.fps)
    start_frame, total = _frame_span(source, start_frame, n_frames)
    rots, op = _poses(source, angles_deg, opacity)
    stereo = source.stereo
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
    renderer, proj, on_frame = _renderer(ctx, source, config, on_frame)
    w, h = config.eye_size
    timings = dict.fromkeys(("decode_wait", "upload", "render", "encode_wait"), 0.0)
    t_start = time.perf_counter()
    serial = threads is not None and int(threads) <= 1
    try:
        with contextlib.ExitStack() as stack:
            writers, workers = _workers(stack, paths[: len(eyes)], fps, (w, h), serial,
                                        on_frame, crf=crf, preset=preset, audio=audio, threads=threads,
                                        times_s=_out_times(source.info, start_frame, total))  # fmt: skip
            loop = _FrameLoop(renderer, rots, op, cell_opacity, eyes, stereo, workers,
                              on_frame is not None, review_eye, timings)  # fmt: skip
            try:
                # Decoding overlaps rendering; decoder buffers are reused, so copy there.
                decoded = source.eye_frames(start=start_frame, end=start_frame + total,
                                             threads=threads, convert=proj == "equirect")  # fmt: skip
                frames = stack.enter_context(
                    contextlib.closing(decoded if serial else prefetch(decoded, depth=3))
                )
                n = loop.run(frames, Counter(progress, total))
            finally:
                errors = loop.join(len(writers))
            if errors:
                raise errors[0]
            if n == 0:
                raise InputError(f"{source.path}: no frames decoded")
        if same and len(paths) == 2:
            with atomic_output(paths[1]) as tmp:
                shutil.copyfile(paths[0], tmp)
    finally:
        renderer.release()
    timings["total"] = time.perf_counter() - t_start
    return VideoRenderResult(n, (w, h), fps, timings)


def _renderer(ctx, source, config, on_frame):
    """``(eye renderer, the projection it samples, on_frame)``: a non-equirect source's
    frames are sampled as stored (:func:`simulator.render.sampling.sampled_projection`);
    ``on_frame`` then gets them converted to equirect, on its worker thread."""
    proj = sampled_projection(ctx, source)
    if on_frame is not None and proj != "equirect":  # the review draws the equirect frame
        on_frame = functools.partial(_on_equirect, on_frame, source.converter)
    renderer = EyeRenderer(ctx, config, projection=proj, lens_fov_deg=source.lens_fov_deg)
    return renderer, proj, on_frame


def _on_equirect(on_frame, convert, frame, yuv) -> None:
    """``on_frame`` given the equirect frame of a frame as stored (on its worker thread)."""
    on_frame(convert(frame), yuv)


def _out_times(info, start_frame: int, total: int):
    """The frames' times in seconds for a variable-rate source (the outputs keep its
    timing), else None (constant rate: ``i / fps``)."""
    if not info.variable_rate:
        return None
    return info.times_s(np.arange(start_frame, start_frame + total))


def _workers(stack, paths, fps, size, serial: bool, on_frame, **encode):
    """``(writers, workers)``: one H.264 writer per path (entered on ``stack``) fed by an
    encoder worker each, and ``on_frame``'s worker last (if any)."""
    writers = [stack.enter_context(VideoWriter(p, fps, size, **encode)) for p in paths]
    workers = [
        _Worker(functools.partial(_write_yuv420p, wr), name=f"encode-{i}", inline=serial)
        for i, wr in enumerate(writers)
    ]
    if on_frame is not None:
        workers.append(_Worker(lambda item: on_frame(*item), name="on-frame", inline=serial))
    return writers, workers


def _frame_span(source, start_frame: int, n_frames: int | None) -> tuple[int, int]:
    """``(start_frame, frame count)`` of the render, checked against the video."""
    info, start_frame = source.info, int(start_frame)
    if not (0 <= start_frame < info.n_frames):
        raise InputError(
            f"{source.path}: start frame {start_frame} outside the video's {info.n_frames} frames"
        )
    return start_frame, int(n_frames or info.n_frames - start_frame)


def _poses(source, angles_deg, opacity):
    """``(head->world matrices (N, 3, 3), opacity (N,) clipped to 0..1 or None)``."""
    ang = np.asarray(angles_deg, float).reshape(-1, 3)
    if ang.shape[0] < 1:
        raise InputError(f"{source.path}: no head orientations to render")
    op = None if opacity is None else np.clip(np.asarray(opacity, float).reshape(-1), 0.0, 1.0)
    return head_rotation(ang[:, 0], ang[:, 1], ang[:, 2]).as_matrix(), op


class _FrameLoop:
    """The per-frame work of :func:`render_video`: upload each decoded frame, render the
    eyes as yuv420p, hand them to the encoder workers (and ``on_frame``'s worker, last),
    timing each step; poses and opacities beyond their last row hold the last."""

    def __init__(self, renderer, rots, op, cell_opacity, eyes, stereo, workers, review,
                 review_eye, timings):  # fmt: skip
        self.renderer, self.rots, self.op, self.cell_op = renderer, rots, op, cell_opacity
        self.eyes, self.stereo, self.workers, self.timings = eyes, stereo, workers, timings
        self.review = review
        self.k = eyes.index(review_eye) if review_eye in eyes else 0  # the review's eye

    def _draw(self, frame, n: int) -> list:
        """Render frame ``n``'s eyes (copies: the renderer's buffer is reused)."""
        r, i = self.renderer, min(n, len(self.rots) - 1)
        o = 0.0 if self.op is None else float(self.op[min(n, len(self.op) - 1)])
        co = None
        if self.cell_op is not None and r.config.mitigation.local:
            co = self.cell_op[min(n, len(self.cell_op) - 1)]
        outs = []
        for eye in self.eyes:
            img = r.render(
                self.rots[i],
                eye,
                source=eye if self.stereo else "left",
                opacity=o,
                eye_offset=r.eye_offset(self.rots[i], eye),
                pix_fmt="yuv420p",
                cell_opacity=co,
            )
            outs.append(img.copy())
        return outs

    def run(self, frames, bar) -> int:
        """Draw every frame of ``frames``; the number drawn."""
        timings, n, shown = self.timings, 0, None
        t0 = time.perf_counter()
        for frame in frames:
            t1 = time.perf_counter()
            timings["decode_wait"] += t1 - t0
            if frame is not shown:  # a still's clip repeats one read-only frame: uploaded once
                for e, f in zip(EYES, frame):  # (left, right) or (mono,)
                    self.renderer.upload(f, e)
                shown = frame
            t2 = time.perf_counter()
            outs = self._draw(frame, n)
            t3 = time.perf_counter()
            for wk, img in zip(self.workers, outs):
                wk.put(img)
            if self.review:
                src = frame[EYES.index(self.eyes[self.k]) if self.stereo else 0]
                self.workers[-1].put((src, outs[self.k]))
            t0 = time.perf_counter()
            timings["upload"] += t2 - t1
            timings["render"] += t3 - t2
            timings["encode_wait"] += t0 - t3
            n += 1
            bar.update(1)
        bar.close()
        return n

    def join(self, n_writers: int) -> list[BaseException]:
        """Finish every worker; their errors (first first) and their busy times."""
        errors = []
        for wk in self.workers:
            try:
                wk.join()
            except BaseException as e:  # noqa: BLE001
                errors.append(e)
        self.timings["encode_busy"] = sum(wk.busy_s for wk in self.workers[:n_writers])
        if self.review:
            self.timings["on_frame_busy"] = self.workers[-1].busy_s
        return errors
