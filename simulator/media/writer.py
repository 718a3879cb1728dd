"""The H.264 writer of every output video: PyAV's libx264 into a temporary name, renamed when
complete (:class:`simulator.core.fileio.PendingOutput`), with the source's timing and audio.
"""

from __future__ import annotations

import contextlib
import os
from fractions import Fraction
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from simulator.core.errors import InputError
from simulator.core.fileio import PendingOutput
from simulator.media.x264 import x264_params

__all__ = ["VideoWriter"]


def _naming(e: BaseException, target, tmp) -> BaseException:
    """``e`` naming ``target`` where it names no file or the temporary one (an OSError of
    the encoder writing the temporary file: the user knows the output's name)."""
    if isinstance(e, OSError) and (e.filename is None or str(e.filename) == str(tmp)):
        # PyAV's errors have a read-only filename: a plain OSError of the same errno
        return OSError(e.errno, e.strerror or str(e), str(target))
    return e


class VideoWriter:
    """H.264 MP4 writer (PyAV), atomic: the file appears under its name only on success.

    Parameters
    ----------
    path : output file (``.mp4``)
    fps : frame rate, frames/s (a float such as 29.97 is kept as an exact fraction)
    size : (width, height) pixels; even numbers (yuv420p)
    crf : x264 constant rate factor (lower = better quality)
    audio : None, or a :class:`simulator.media.audio.AudioSource` (duck-typed: ``add_to(container)``)
        whose audio (range) is carried into the file
    threads : x264 encoder threads (None: x264's default, about 1.5 per core); a task that
        declares its CPUs (``vimsim study``) passes them
    times_s : None (frame ``i`` at ``i / fps``), or each frame's time in seconds (a
        variable-rate source's timestamps: the output keeps its timing, from its first frame)

    The same frames give the same file in any process: x264's AVX-512 kernels, which
    read memory they never wrote, are left out (:func:`simulator.media.x264.x264_params`).

    Use as a context manager; ``write(frame)`` takes ``(height, width, 3)`` uint8 RGB.
    """

    def __init__(
        self,
        path: str | os.PathLike,
        fps: float,
        size: tuple[int, int],
        *,
        crf: int = 18,
        preset: str = "veryfast",
        audio=None,
        threads: int | None = None,
        times_s=None,
    ):
        import av

        self.path = Path(path)
        w, h = int(size[0]), int(size[1])
        if w <= 0 or h <= 0 or w % 2 or h % 2:
            raise InputError(
                f"{self.path}: H.264 output size must be positive and even; got {w}x{h}"
            )
        if not (fps > 0):
            raise InputError(f"{self.path}: frame rate must be > 0; got {fps}")
        self._out = PendingOutput(self.path)  # the one output-file helper (checks, temp name)
        self._tmp = self._out.tmp
        self.size = (w, h)
        self.n_written = 0
        self._container = av.open(str(self._tmp), mode="w", format="mp4")
        rate = Fraction(fps).limit_denominator(1001)
        self._stream = self._container.add_stream("libx264", rate=rate)
        self._stream.width, self._stream.height = w, h
        self._stream.pix_fmt = "yuv420p"
        params = x264_params()  # reproducible bits: no AVX-512 kernels (media/x264.py)
        self._stream.options = {
            "crf": str(crf),
            "preset": preset,
            **({} if threads is None else {"threads": str(int(threads))}),
            **({} if params is None else {"x264-params": params}),
        }
        self._times = None
        if times_s is not None:  # timestamps in 1/90000 s, from the first frame
            t = np.asarray(times_s, float)
            self._stream.codec_context.time_base = Fraction(1, 90000)
            self._times = np.round((t - t[0]) * 90000).astype(np.int64)
        self._closed = False
        self.n_audio_packets = 0
        if audio is not None:
            try:
                # All audio first: the muxer interleaves it with the video packets by time.
                self.n_audio_packets = audio.add_to(self._container).mux_all()
            except BaseException:
                self.close(ok=False)
                raise

    def write(self, frame: NDArray[np.uint8]) -> None:
        try:
            self._write(frame)
        except OSError as e:  # a full disk: say which output, not its temporary name
            raise _naming(e, self.path, self._tmp) from None

    def encode(self, vf) -> None:
        """Encode and mux one ``av.VideoFrame`` at the next frame's time (the source's
        timestamps, else ``i / fps``); an OSError names the output file."""
        vf.pts = self.frame_pts()
        try:
            for pkt in self._stream.encode(vf):
                self._container.mux(pkt)
        except OSError as e:
            raise _naming(e, self.path, self._tmp) from None

    def _write(self, frame: NDArray[np.uint8]) -> None:
        import av

        if frame.shape != (self.size[1], self.size[0], 3) or frame.dtype != np.uint8:
            raise ValueError(
                f"frame must be ({self.size[1]}, {self.size[0]}, 3) uint8; got {frame.shape} {frame.dtype}"
            )
        self.encode(av.VideoFrame.from_ndarray(np.ascontiguousarray(frame), format="rgb24"))
        self.n_written += 1

    def frame_pts(self) -> int | None:
        """The pts of the next frame (None: the encoder counts frames at ``fps``)."""
        if self._times is None:
            return None
        return int(self._times[min(self.n_written, len(self._times) - 1)])

    def close(self, ok: bool = True) -> None:
        """Flush and close; rename into place if ``ok``, else delete the partial file."""
        if self._closed:
            return
        self._closed = True
        try:
            try:
                if ok:
                    for pkt in self._stream.encode():
                        self._container.mux(pkt)
            finally:
                if ok:
                    self._container.close()
                else:  # already failing: the first error is the one to report
                    with contextlib.suppress(Exception):
                        self._container.close()
        except BaseException as e:  # noqa: BLE001 - re-raised
            self._out.discard()  # a full disk while flushing: no temporary left
            raise _naming(e, self.path, self._tmp) from None
        if ok:
            self._out.commit()
        else:
            self._out.discard()

    def __enter__(self) -> VideoWriter:  # noqa: PYI034
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        self.close(ok=exc_type is None)
