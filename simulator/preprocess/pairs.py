"""The frame-pair pipeline of paper-mode preprocessing: decoding, window extraction, flow and reduction overlapped across threads (:mod:`simulator.preprocess.paper`)."""

from __future__ import annotations

import collections
import itertools
import math
import os
import queue
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor

import numpy as np
from numpy.typing import NDArray

from simulator.core.errors import InputError
from simulator.core.progress import Counter, Progress
from simulator.flow.base import FlowBackend
from simulator.media.source import Source
from simulator.media.video import prefetch
from simulator.preprocess.common import PreprocessInterrupted
from simulator.sphere.windows import WindowExtractor, WindowGrid

__all__ = ["PairPipeline"]


class PairPipeline:
    """The grid rows of one paper-mode run, appended to ``dps_rows``/``px_rows`` (which may
    already hold the rows of a checkpoint) by :meth:`run`.

    Row r (r >= 1) is the flow from video frame ``start_f + r - 1`` to ``start_f + r``; row 0
    repeats row 1 and is stored when row 1 is known. ``checkpoint()`` saves the rows so far
    to ``ckpt``; it is called every ``checkpoint_every_s`` wall-clock seconds and on Ctrl-C.
    ``reducer`` is the :class:`~simulator.preprocess.paper.WindowFlowReducer` of the grid.
    """

    def __init__(
        self,
        source: Source,
        grid: WindowGrid,
        backend: FlowBackend,
        reducer,
        extractor: WindowExtractor,
        *,
        interp: str,
        span: tuple[int, int],
        rows: tuple[list, list],
        threads: int | None,
        checkpoint: Callable[[], None],
        ckpt,
        checkpoint_every_s: float,
        progress: Progress | None,
        on_frame: Callable[[int], None] | None,
    ):
        self.source, self.backend, self.reducer, self.extractor = source, backend, reducer, extractor
        self.interp = interp
        self.start_f, self.end_f = span
        self.dps_rows, self.px_rows = rows
        self.checkpoint, self.ckpt, self.checkpoint_every_s = checkpoint, ckpt, checkpoint_every_s
        self.progress, self.on_frame = progress, on_frame
        self.P, self.Y = grid.shape
        self.n_win = self.P * self.Y
        self.w, self.h = grid.size
        self.fps = source.info.fps
        self.k_dps = math.degrees(1.0) * float(self.fps)
        self.n_threads = max(1, int(threads or os.cpu_count() or 1))
        self.fused = backend.thread_safe
        n_chunks = self.n_threads * 4 if self.fused and self.n_threads > 1 else 1
        bounds = np.linspace(0, self.n_win, min(n_chunks, self.n_win) + 1).astype(int)
        self.chunks = [(int(a), int(b)) for a, b in itertools.pairwise(bounds) if b > a]
        # Window stacks are written into recycled buffers (no 17 MB allocation per frame at
        # the default grid): the decoding thread takes one from `free` or makes one; a stack
        # goes back once the last flow pair that reads it has finished.
        self.free: queue.SimpleQueue = queue.SimpleQueue()
        # Frame pairs in flight, oldest first: (row, futures or parts, stack to recycle).
        # Two pairs in flight keep both workers busy across frame boundaries (the workers
        # start on pair t+1 while the last chunks of pair t finish).
        self.inflight: collections.deque = collections.deque()
        self.pool: ThreadPoolExecutor | None = None

    def _work(self, prev: NDArray, cur: NDArray, a: int, b: int):
        # Flow and reduction of one window at a time in the same worker: the window's
        # flow (512 KB at 256 px) is reduced while still in this core's cache, and no
        # (N, h, w, 2) batch is allocated and copied. Same values as reducer(backend(...)).
        dps = np.empty(b - a)
        px = np.empty(b - a)
        npx = self.reducer._npx
        for i, k in enumerate(range(a, b)):
            s_ang, s_px = self.reducer._one(self.backend.pair(prev[k], cur[k]))
            dps[i] = s_ang * self.k_dps
            px[i] = s_px / npx
        return dps, px

    def _extract(self, f: NDArray) -> NDArray:
        P, Y, h, w = self.P, self.Y, self.h, self.w
        try:
            buf = self.free.get_nowait().reshape(P, Y, h, w)
        except queue.Empty:
            buf = np.empty((P, Y, h, w), np.uint8)
        return self.extractor(f, interp=self.interp, out=buf).reshape(self.n_win, h, w)

    def _submit(self, prev_win: NDArray, win: NDArray) -> list:
        """Start (fused pool) or compute the flow of one frame pair: futures or parts."""
        pool, backend, reducer, fps = self.pool, self.backend, self.reducer, self.fps
        if pool is not None and self.fused:
            return [pool.submit(self._work, prev_win, win, a, b) for a, b in self.chunks]
        if pool is not None:
            fl = backend(prev_win, win)
            rb = np.linspace(0, self.n_win, min(2 * self.n_threads, self.n_win) + 1).astype(int)
            futs = [pool.submit(reducer, fl[a:b], fps) for a, b in itertools.pairwise(rb) if b > a]
            return [f.result() for f in futs]
        return [reducer(backend(prev_win, win), fps)]

    def _finish(self) -> None:
        """Store the oldest pair in flight as a row (checking it), checkpointing when due."""
        r, pending, old = self.inflight.popleft()
        parts = [f.result() for f in pending] if self.pool is not None and self.fused else pending
        d = np.concatenate([p[0] for p in parts]).astype(np.float32).reshape(self.P, self.Y)
        x = np.concatenate([p[1] for p in parts]).astype(np.float32).reshape(self.P, self.Y)
        if not (np.all(np.isfinite(d)) and np.all(np.isfinite(x))):
            raise InputError(
                f"{self.source.path}: flow backend {self.backend.name} gave non-finite flow "
                f"at frame {self.start_f + r}"
            )
        if r == 1:
            self.dps_rows.append(d)
            self.px_rows.append(x)
            self.bar.update(1)
        self.dps_rows.append(d)
        self.px_rows.append(x)
        self.bar.update(1)
        self.free.put(old)
        if self.on_frame is not None:
            self.on_frame(r)
        now = time.monotonic()
        if now - self.last_ckpt >= self.checkpoint_every_s:
            self.checkpoint()
            self.last_ckpt = now

    def run(self) -> None:
        """Compute the remaining rows; raises PreprocessInterrupted on Ctrl-C (after saving
        a checkpoint when any row is known)."""
        done = len(self.dps_rows)
        total = self.end_f - self.start_f
        first_row = max(done, 1)
        decode_from = self.start_f + first_row - 1
        self.bar = Counter(self.progress, total, done)
        self.last_ckpt = time.monotonic()
        prev_win: NDArray | None = None
        frames = windows = None
        row = first_row - 1
        if len(self.chunks) > 1 or not self.fused:
            self.pool = ThreadPoolExecutor(self.n_threads)
        try:
            frames = self.source.frames(fmt="gray", start=decode_from, end=self.end_f)
            # Decoding and window extraction of frame t+1 overlap the flow of frame t.
            windows = prefetch((self._extract(f) for f in frames), depth=2)
            for win in windows:
                if prev_win is None:
                    prev_win = win
                    continue
                row += 1
                self.inflight.append((row, self._submit(prev_win, win), prev_win))
                prev_win = win
                # The first row is delivered at once (start-up latency), later ones one pair late.
                late = 1 if self.pool is not None and self.fused and row > first_row else 0
                while len(self.inflight) > late:
                    self._finish()
            while self.inflight:
                self._finish()
        except KeyboardInterrupt:
            self._interrupted(total)
        finally:
            self._close(windows, frames)

    def _interrupted(self, total: int) -> None:
        """Ctrl-C: save what is known and raise PreprocessInterrupted."""
        self.bar.close()
        if self.dps_rows:
            self.checkpoint()
            raise PreprocessInterrupted(
                f"interrupted after {len(self.dps_rows)} of {total} frames; checkpoint saved to "
                f"{self.ckpt}; run the same command with --resume to continue"
            ) from None
        raise PreprocessInterrupted(
            "interrupted before the first frame pair; nothing saved"
        ) from None

    def _close(self, windows, frames) -> None:
        """Stop the bar, the decoding thread, the video file and the pool."""
        self.bar.close()
        if windows is not None:
            windows.close()  # stops the decoding thread now, not when garbage-collected
        if frames is not None:
            frames.close()  # closes the video file
        if self.pool is not None:
            self.pool.shutdown(wait=True, cancel_futures=True)
