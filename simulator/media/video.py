"""Video and image input/output through PyAV (FFmpeg) and Pillow.

Frames are ``(H, W, 3)`` uint8 RGB or ``(H, W)`` uint8 grayscale (the Y plane, read
without an RGB conversion), origin top-left, stored pixels (a non-square sample aspect
ratio is reported in :class:`MediaInfo`, never resampled away: equirect longitude is
linear in the stored column). Stereo layouts (``top-bottom``: left eye on top;
``side-by-side``: left eye on the left) are split by :func:`simulator.sphere.geometry.split_eye`.

Decoding streams: one frame in memory at a time, whatever the video's length.
Writing goes to a temporary file renamed into place when the writer is closed without
error, so an interrupted encode never leaves an MP4 that looks complete.
"""

from __future__ import annotations

import os
import queue
import threading
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal, TypeVar

import numpy as np
from numpy.typing import NDArray

from simulator.core.errors import InputError
from simulator.core.fileio import check_input_file
from simulator.media.writer import VideoWriter  # the one writer, re-exported here
from simulator.sphere.geometry import check_equirect_aspect, split_eye

__all__ = [
    "IMAGE_SUFFIXES",
    "MediaInfo",
    "VideoWriter",
    "iter_frames",
    "prefetch",
    "probe",
    "read_frame",
]

IMAGE_SUFFIXES = (".jpg", ".jpeg", ".png", ".bmp", ".tif", ".tiff", ".webp")
PixelFormat = Literal["rgb24", "gray"]
_T = TypeVar("_T")


@dataclass(frozen=True)
class MediaInfo:
    """What a media file holds.

    width, height : stored size in pixels (both eyes for stereo)
    sar : sample (pixel) aspect ratio, display width = width * sar
    fps : frames per second (1.0 for a still image)
    n_frames : number of frames (1 for a still image)
    is_video : False for a still image
    codec : decoder name (``"image"`` for stills)
    pix_fmt : the decoder's pixel format (e.g. ``yuv420p10le``; None for stills)
    bit_depth : bits per sample of the source (8 for stills; 10 for HEVC Main10 etc.);
        frames are always delivered as 8-bit (FFmpeg's swscale conversion, no tone mapping)
    transfer : the stream's transfer characteristic (``bt709``, ``smpte2084`` = PQ,
        ``arib-std-b67`` = HLG, ...; None when unspecified)
    frame_times : None for a constant-rate stream starting at 0 (frame ``i`` at
        ``i / fps``), else each frame's presentation time in seconds on the player's clock
        (the container's start is 0: a video stream starting later than its audio has its
        first frame after 0), from the stream's timestamps (:meth:`times_s`)
    """

    path: str
    width: int
    height: int
    sar: float
    fps: float
    n_frames: int
    is_video: bool
    codec: str
    pix_fmt: str | None = None
    bit_depth: int = 8
    transfer: str | None = None
    frame_times: NDArray[np.float64] | None = field(default=None, compare=False, repr=False)

    def times_s(self, frames=None) -> NDArray[np.float64]:
        """Presentation time (seconds) of video frames ``frames`` (default: all)."""
        idx = np.arange(self.n_frames) if frames is None else np.asarray(frames)
        if self.frame_times is None:
            return idx / self.fps
        return self.frame_times[np.clip(idx, 0, self.n_frames - 1)]

    def frame_at(self, t_s) -> NDArray[np.int64]:
        """The frame on screen at time ``t_s`` (the last one starting at or before it)."""
        t = np.asarray(t_s, float)
        if self.frame_times is None:
            return np.floor(t * self.fps + 1e-9).astype(np.int64)
        return np.searchsorted(self.frame_times, t + 1e-9, side="right").astype(np.int64) - 1

    @property
    def variable_rate(self) -> bool:
        """True when frame times are not ``i / fps`` (variable rate or a late start)."""
        return self.frame_times is not None

    @property
    def duration_s(self) -> float:
        """Seconds to the end of the last frame (a variable-rate stream's last frame lasts
        its median interval)."""
        if self.frame_times is None:
            return self.n_frames / self.fps
        dt = np.diff(self.frame_times)
        return float(self.frame_times[-1] + (np.median(dt) if dt.size else 1.0 / self.fps))

    def eye_size(self, layout: str = "mono") -> tuple[int, int]:
        """Stored per-eye ``(w, h)``, after checking each eye displays as 2:1."""
        return check_equirect_aspect(self.width, self.height, layout, self.sar, source=self.path)


def _open_container(path: Path):
    import av

    try:
        return av.open(str(path))
    except av.error.FFmpegError as e:  # not a media file FFmpeg can read
        raise InputError(
            f"{path}: not a readable video or image ({e.strerror or type(e).__name__})"
        ) from None


def _is_image_path(path: Path) -> bool:
    return path.suffix.lower() in IMAGE_SUFFIXES


def _check_media_file(path: str | os.PathLike) -> Path:
    """:func:`check_input_file` naming the file an image or a video by its suffix."""
    return check_input_file(path, "image" if _is_image_path(Path(path)) else "video")


def _probe_image(path: Path) -> MediaInfo:
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(path) as im:
            w, h = im.size
    except (UnidentifiedImageError, OSError) as e:
        raise InputError(f"{path}: not a readable image ({e})") from None
    except Image.DecompressionBombError as e:  # a header claiming e.g. 30000x15000 px
        raise InputError(f"{path}: image too large to read ({e})") from None
    return MediaInfo(str(path), w, h, 1.0, 1.0, 1, False, "image")


def probe(path: str | os.PathLike) -> MediaInfo:
    """Size, sample aspect ratio, frame rate and frame count of a video or image.

    ``n_frames`` is the number of frames a decoder delivers, counted from the packets
    (demuxing reads the file but decodes nothing: ~0.1 s per 100 MB): packets that the
    container marks as discarded (an MP4 edit list trimming the end) are not frames. The
    stream header can disagree: three.js ``pano.mp4`` declares 189 frames, but its edit
    list drops the last packet and FFmpeg (``ffmpeg -i pano.mp4 -f null -``) and
    :func:`iter_frames` deliver 188; ``pano.webm`` has no count in its header (189).
    ``fps`` is the stream's nominal rate (``r_frame_rate``), not the average rate.
    Raises InputError for a missing file, a file FFmpeg cannot read, or a container
    without a video stream.
    """
    p = _check_media_file(path)
    if _is_image_path(p):
        return _probe_image(p)
    with _open_container(p) as c:
        if not c.streams.video:
            raise InputError(f"{p}: no video stream")
        s = c.streams.video[0]
        cc = s.codec_context
        w, h = cc.width, cc.height
        sar_f = s.sample_aspect_ratio or cc.sample_aspect_ratio
        sar = float(sar_f) if sar_f else 1.0
        # Nominal rate (r_frame_rate) first: average_rate is skewed by the last frame's duration.
        rate = s.guessed_rate or s.base_rate or s.average_rate
        fps = float(rate) if rate else 0.0
        codec = cc.name
        pix_fmt, depth, transfer = _depth_and_transfer(cc)
        n, times = _count_frames(c, s, p)
    if codec in ("mjpeg", "png", "bmp", "tiff", "webp") and n <= 1:
        return MediaInfo(str(p), w, h, sar, 1.0, 1, False, codec)
    if w <= 0 or h <= 0:
        raise InputError(f"{p}: video stream has no frame size")
    if fps <= 0:
        raise InputError(f"{p}: video stream has no frame rate")
    if times is not None and np.all(np.abs(times - np.arange(n) / fps) <= 0.25 / fps):
        times = None  # constant rate from 0: frame i at i / fps
    return MediaInfo(str(p), w, h, sar, fps, n, True, codec, pix_fmt, depth, transfer, times)


#: ISO/IEC 23091-2 transfer characteristics (FFmpeg's AVColorTransferCharacteristic).
_TRANSFERS = {1: "bt709", 4: "gamma22", 5: "gamma28", 6: "smpte170m", 7: "smpte240m", 8: "linear",
              13: "iec61966-2-1", 14: "bt2020-10", 15: "bt2020-12", 16: "smpte2084",
              18: "arib-std-b67"}  # fmt: skip


def _depth_and_transfer(cc) -> tuple[str | None, int, str | None]:
    """Pixel format, bits per sample and transfer name of a video codec context."""
    fmt = cc.format
    name = getattr(fmt, "name", None)
    try:
        depth = max(int(c.bits) for c in fmt.components) if fmt is not None else 8
    except (AttributeError, ValueError):
        depth = 8
    trc = getattr(cc, "color_trc", None)
    return name, depth, _TRANSFERS.get(int(trc)) if trc is not None else None


def _count_frames(container, stream, p: Path) -> tuple[int, NDArray | None]:
    """Frames a decoder delivers (non-empty packets not marked as discarded) and their
    presentation times on the player's clock (None when packets carry no timestamps).
    InputError naming the frame for timestamps that repeat or go backwards."""
    n = 0
    pts: list[int] = []
    last_dts = None
    try:
        for pk in container.demux(stream):
            if pk.size > 0 and not getattr(pk, "is_discard", False):
                if pk.dts is not None and last_dts is not None and pk.dts <= last_dts:
                    raise InputError(
                        f"{p}: video timestamps go backwards or repeat at frame {n} (decode "
                        "order); vimsim needs strictly increasing frame times"
                    )
                last_dts = pk.dts if pk.dts is not None else last_dts
                pts.append(pk.pts)
                n += 1
    except InputError:
        raise
    except Exception as e:  # noqa: BLE001 - corrupt container
        if n == 0:
            raise InputError(f"{p}: unreadable video stream ({e})") from None
    if n == 0 or any(v is None for v in pts) or stream.time_base is None:
        return n, None
    order = np.sort(np.asarray(pts, np.int64))
    rep = np.flatnonzero(np.diff(order) <= 0)
    if rep.size:
        raise InputError(
            f"{p}: video timestamps repeat at frame {int(rep[0]) + 1}; vimsim needs strictly "
            "increasing frame times"
        )
    # the player's clock: 0 at the container's start (the earliest stream)
    t0 = container.start_time / 1e6 if container.start_time is not None else None
    times = order * float(stream.time_base)
    return n, times - (t0 if t0 is not None else times[0])


def _frame_array(frame, fmt: PixelFormat) -> NDArray[np.uint8]:
    if fmt == "gray":
        # Fast path: the luma plane of planar YUV is the grayscale image (no RGB step).
        if frame.format.name in (
            "yuv420p",
            "yuvj420p",
            "yuv422p",
            "yuvj422p",
            "yuv444p",
            "yuvj444p",
            "gray",
            "nv12",
        ):
            plane = frame.planes[0]
            buf = np.frombuffer(plane, np.uint8).reshape(plane.height, plane.line_size)
            return buf[:, : frame.width]
        return frame.to_ndarray(format="gray")
    return frame.to_ndarray(format="rgb24")


def iter_frames(
    path: str | os.PathLike,
    *,
    fmt: PixelFormat = "rgb24",
    layout: str = "mono",
    eye: str = "left",
    start: int = 0,
    end: int | None = None,
    threads: int | None = None,
) -> Iterator[NDArray[np.uint8]]:
    """Decode frames ``start <= index < end`` of a video (or the one frame of an image).

    Yields one eye's frame, ``(h, w, 3)`` RGB or ``(h, w)`` gray uint8 (stored pixels),
    one at a time (streaming: memory does not grow with the video's length). Frames are
    yielded as views into decoder buffers where possible: copy one to keep it.
    ``threads``: decoder threads (None: FFmpeg's choice, about one per core).
    """
    p = _check_media_file(path)
    if _is_image_path(p):
        if start == 0 and (end is None or end > 0):
            yield split_eye(_read_image(p, fmt), layout, eye, source=str(p))
        return
    import av

    with _open_container(p) as c:
        if not c.streams.video:
            raise InputError(f"{p}: no video stream")
        s = c.streams.video[0]
        s.thread_type = "AUTO"
        if threads is not None:
            s.thread_count = max(1, int(threads))
        i = -1
        try:
            for i, frame in enumerate(c.decode(s)):
                if i < start:
                    continue
                if end is not None and i >= end:
                    break
                yield split_eye(_frame_array(frame, fmt), layout, eye, source=str(p))
        except av.error.FFmpegError as e:
            raise InputError(
                f"{p}: unreadable video stream at frame {i + 1} ({e.strerror or e})"
            ) from None


def prefetch(iterable: Iterable[_T], depth: int = 2) -> Iterator[_T]:
    """Iterate ``iterable`` in a background thread, up to ``depth`` items ahead.

    For decode pipelines: PyAV decoding, ``cv2.remap`` and most numpy work release the
    GIL, so producing item t+1 (e.g. ``(extract(f) for f in iter_frames(...))``) overlaps
    the caller's work on item t. Items arrive in order. An exception raised while
    producing is re-raised here (with its traceback) at the item where it happened.
    Closing the returned generator (``close()``, ``break`` out of a ``for`` loop that
    then drops it, an exception in the caller) stops the thread, closes ``iterable``'s
    iterator if it has ``close`` (a generator: its ``finally``/``with`` blocks run, e.g.
    the video file is closed) and returns only when the thread has ended.

    Parameters
    ----------
    iterable : any iterable; iterated only in the background thread
    depth : int >= 1, items produced ahead of the consumer (memory bound)
    """
    if int(depth) < 1:
        raise ValueError(f"prefetch depth must be >= 1; got {depth}")
    q: queue.Queue = queue.Queue(maxsize=int(depth))
    stop = threading.Event()
    end = object()
    it = iter(iterable)

    def put(item) -> bool:
        while not stop.is_set():
            try:
                q.put(item, timeout=0.05)
                return True
            except queue.Full:
                continue
        return False

    def produce() -> None:
        try:
            try:
                for x in it:
                    if not put((x, None)):
                        return
            finally:
                close = getattr(it, "close", None)
                if close is not None:
                    close()
            put((end, None))
        except BaseException as e:  # noqa: BLE001 - handed to the consumer
            put((None, e))

    th = threading.Thread(target=produce, name="vimsim-prefetch", daemon=True)
    th.start()
    try:
        while True:
            x, err = q.get()
            if err is not None:
                raise err
            if x is end:
                return
            yield x
    finally:
        stop.set()
        th.join()


def _read_image(p: Path, fmt: PixelFormat) -> NDArray[np.uint8]:
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(p) as im:
            im = im.convert("L" if fmt == "gray" else "RGB")
            return np.asarray(im)
    except (UnidentifiedImageError, OSError) as e:
        raise InputError(f"{p}: not a readable image ({e})") from None
    except Image.DecompressionBombError as e:
        raise InputError(f"{p}: image too large to read ({e})") from None


def read_frame(
    path: str | os.PathLike,
    index: int = 0,
    *,
    fmt: PixelFormat = "rgb24",
    layout: str = "mono",
    eye: str = "left",
) -> NDArray[np.uint8]:
    """One eye's frame ``index`` of a video or the image itself (a copy)."""
    if index < 0:
        raise InputError(f"{path}: frame index must be >= 0; got {index}")
    for f in iter_frames(path, fmt=fmt, layout=layout, eye=eye, start=index, end=index + 1):
        return np.array(f)
    raise InputError(f"{path}: has no frame {index}")
