"""The video source of a viewing: file, stereo layout, projection, right-eye file and eye, checked once and decoded through one funnel.

A :class:`Source` is what every stage takes instead of a loose path plus ``layout=``,
``right=`` and ``eye=``: ``Source.open`` checks the file(s) once (readable, each eye 2:1
equirect for ``equirect``, a right-eye file matching the left), and its methods decode
one eye's frames (:meth:`Source.frames`), both eyes in step (:meth:`Source.eye_frames`)
or one frame (:meth:`Source.read`), always as equirect frames of :meth:`Source.eye_size`.
Library functions accept a Source or a plain path (:func:`as_source`: mono equirect).
"""

from __future__ import annotations

import math
import os
import re
from collections.abc import Iterator
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from simulator.core.choices import (
    EYES,
    LAYOUTS,
    MAX_CLIP_FPS,
    MAX_CLIP_FRAMES,
    PROJECTIONS,
    STILL_FPS,
    STILL_SECONDS,
)
from simulator.core.errors import InputError
from simulator.media.guard import aspect_refusal, check_not_dual_fisheye
from simulator.media.spherical import read_spherical, view_angles_deg
from simulator.media.video import MediaInfo, PixelFormat, iter_frames, probe, read_frame
from simulator.sphere.geometry import split_eye
from simulator.sphere.projections import DEFAULT_LENS_FOV_DEG, EquirectConverter, converter

__all__ = ["Source", "as_source", "check_local_path"]

_URL = re.compile(r"^[A-Za-z][A-Za-z0-9+.-]*://")


def check_local_path(path, what: str = "video") -> str:
    """``path`` as text; InputError (one line) for a URL: vimsim reads local files only."""
    text = os.fspath(path) if isinstance(path, os.PathLike) else str(path)
    if _URL.match(text) or text.lower().startswith(("data:", "blob:")):
        raise InputError(f"{text}: a URL; vimsim reads local {what} files only: download it first")
    return text


@dataclass(frozen=True)
class Source:
    """A checked video (or image) source; make one with :meth:`Source.open`.

    path : the file (the left eye's with ``right``)
    layout : ``mono``, ``top-bottom`` (left eye on top) or ``side-by-side`` (left eye left)
    projection : the input projection (:data:`PROJECTION_NAMES`)
    right : the right eye's own file (two per-eye files; layout ``mono``), or None
    eye : the eye a single-eye consumer (preprocess, viewport) takes from a stereo source
    lens_fov_deg : a dual fisheye's lens FOV (degrees, in (180, 360)); None for the others
    still : an image made a clip (``Source.open(still=(seconds, fps))``): ``info`` then says
        ``n_frames = round(seconds * fps)`` frames at ``fps``, every one the image
    info : the file's :class:`simulator.media.video.MediaInfo` (of ``path``)
    metadata : its spherical metadata (:func:`simulator.media.spherical.read_spherical`)
    notes : one line each for the user (an option overriding the metadata)
    orientation_deg : the initial orientation applied (yaw, pitch, roll degrees, from the
        spherical metadata; None when it has none, it is zero, or ``orientation=False``):
        every view of a head pose is turned by it (:meth:`view_angles_deg`)
    """

    path: str
    layout: str = "mono"
    projection: str = "equirect"
    right: str | None = None
    eye: str = "left"
    lens_fov_deg: float | None = None
    still: bool = False
    info: MediaInfo | None = field(default=None, compare=False, repr=False)
    metadata: dict | None = field(default=None, compare=False, repr=False)
    notes: tuple[str, ...] = field(default=(), compare=False, repr=False)
    orientation_deg: tuple[float, float, float] | None = None
    #: The file's stereo metadata stores the right eye first (top, or left half): each eye
    #: is read from its own half (:meth:`eye_view`).
    right_first: bool = False

    @classmethod
    def open(
        cls,
        path,
        *,
        layout: str | None = None,
        projection: str | None = None,
        right=None,
        eye: str = "left",
        lens_fov_deg: float | None = None,
        still: tuple[float | None, float | None] | None = None,
        layout_default: str = "mono",
        orientation: bool = True,
    ) -> Source:
        """Check and probe a source (InputError naming the file or option on bad input).

        ``layout`` / ``projection`` None: the file's spherical metadata
        (:func:`simulator.media.spherical.read_spherical`), else ``layout_default`` /
        ``equirect``; given ones win over the metadata, with a note (:attr:`notes`) when
        they disagree. ``still = (seconds, fps)``: an image is accepted as a clip of
        ``seconds`` at ``fps`` (None: :data:`STILL_SECONDS`, :data:`STILL_FPS`).
        ``orientation=False`` ignores the metadata's initial orientation (else applied:
        :attr:`orientation_deg`).
        """
        path = check_local_path(path)
        info = probe(path)
        md = read_spherical(path) if info.is_video else {}
        notes: list[str] = []
        given = projection
        projection = _resolve(path, "projection", projection, md.get("projection"), notes)
        layout = _resolve(path, "layout", layout, md.get("layout"), notes) or layout_default
        projection = projection or "equirect"
        pose = _pose(path, md.get("orientation_deg"), orientation, notes)
        if layout not in LAYOUTS:
            raise InputError(
                f"{path}: unknown stereo layout {layout!r}; expected one of {', '.join(LAYOUTS)}"
            )
        if eye not in EYES:
            raise InputError(f"{path}: unknown eye {eye!r}; expected left or right")
        if projection not in PROJECTIONS:
            raise InputError(
                f"--projection {projection!r}: unknown; expected one of {', '.join(PROJECTIONS)}"
            )
        lens_fov_deg = _check_lens_fov(projection, lens_fov_deg)
        is_still = still is not None and not info.is_video
        if is_still:
            info = _still_info(info, *still)
        # the stored eye order applies to the layout the metadata describes
        right_first = (md.get("eye_order") == "right-first" and layout == md.get("layout")
                       and layout != "mono")  # fmt: skip
        if right_first:
            half = "top" if layout == "top-bottom" else "left"
            notes.append(f"{path}: its stereo metadata stores the right eye first (the {half} "
                         "half): each eye is read from its own half")  # fmt: skip
        src = cls(path, layout, projection, None, eye, lens_fov_deg, is_still, info,
                  orientation_deg=pose, right_first=right_first)  # fmt: skip
        object.__setattr__(src, "metadata", md or None)
        object.__setattr__(src, "notes", tuple(notes))
        try:
            src.eye_size  # noqa: B018 - checks the eye's size fits the projection (InputError)
        except InputError as e:
            raise InputError(aspect_refusal(path, e, src.stored_eye_size, info.sar)) from None
        if given is None and projection == "equirect":  # a dual fisheye read as equirect?
            key = (path, info.width, info.height, info.n_frames, layout, eye, os.stat(path).st_mtime_ns)
            check_not_dual_fisheye(path, lambda i: src.read(i, fmt="gray"), info.n_frames, key)
        if right is not None:
            right = check_local_path(right)
            _check_right_eye(info, right, layout, projection)
            src = replace(src, right=right)
        return src

    # -- what it is --------------------------------------------------------------------
    @property
    def stereo(self) -> bool:
        """True for a stereo source (a stereo layout or two per-eye files)."""
        return self.layout != "mono" or self.right is not None

    @property
    def eye_size(self) -> tuple[int, int]:
        """``(w, h)`` of the equirect frames the funnel yields for one eye."""
        if self.projection == "equirect":
            return self._info.eye_size(self.layout)
        return self.converter.equirect_size

    @property
    def stored_eye_size(self) -> tuple[int, int]:
        """``(w, h)`` of one eye as stored (in the source's projection)."""
        w, h = self._info.width, self._info.height
        if self.right is None and self.layout == "top-bottom":
            return w, h // 2
        if self.right is None and self.layout == "side-by-side":
            return w // 2, h
        return w, h

    @property
    def converter(self) -> EquirectConverter | None:
        """The conversion to the equirect working frame (None for ``equirect``);
        InputError when the frame size does not fit the projection's layout."""
        if self.projection == "equirect":
            return None
        return converter(self.projection, self.stored_eye_size, self.lens_fov_deg)

    @property
    def covered(self):
        """``(H, W)`` bool mask of the equirect working frame's covered directions, or
        None when the projection covers the whole sphere."""
        c = self.converter
        return None if c is None or c.covered.all() else c.covered

    @property
    def _info(self) -> MediaInfo:
        if self.info is None:  # a Source built by hand: probe once, here
            object.__setattr__(self, "info", probe(self.path))
        return self.info  # type: ignore[return-value]

    @property
    def files(self) -> list[str]:
        """The input files (to refuse writing over them)."""
        return [self.path] + ([self.right] if self.right is not None else [])

    def for_eye(self, eye: str) -> Source:
        """The same source, read for ``eye``."""
        if eye not in EYES:
            raise InputError(f"{self.path}: unknown eye {eye!r}; expected left or right")
        return replace(self, eye=eye)

    def settings(self) -> dict:
        """What outputs record about the source (grid meta, ``summary.json``)."""
        return {
            "layout": self.layout,
            "projection": self.projection,
            "lens_fov_deg": self.lens_fov_deg,
            "still": self.still,
            "bit_depth": self._info.bit_depth,
            "transfer": self._info.transfer,
            "pix_fmt": self._info.pix_fmt,
            "spherical_metadata": self.metadata,
            # the initial orientation applied to every view (None: none, or ignored)
            "orientation_deg": None if self.orientation_deg is None else list(self.orientation_deg),
            "orientation_ignored": self.orientation_deg is None
            and any((self.metadata or {}).get("orientation_deg") or ()),
            "eye": self.eye,
            "right": self.right,
            "eye_order": None if self.layout == "mono" or self.right is not None
            else ("right-first" if self.right_first else "left-first"),
        }

    def view_angles_deg(self, yaw_deg, pitch_deg, roll_deg):
        """``(yaw, pitch, roll)`` in the frame of a head pose: turned by the initial
        orientation (:func:`simulator.media.spherical.view_angles_deg`), else as given."""
        return view_angles_deg(self.orientation_deg, yaw_deg, pitch_deg, roll_deg)

    # -- the decode funnel -------------------------------------------------------------
    def file_of(self, eye: str) -> str:
        """The file holding ``eye``'s frames."""
        return self.right if self.right is not None and eye == "right" else self.path

    def eye_view(self, frame: NDArray, eye: str | None = None, *, convert: bool = True) -> NDArray:
        """``eye``'s equirect frame from a decoded frame of :meth:`file_of` ``(eye)``: the
        stereo half (a view for ``top-bottom``) converted from the source's projection
        (``convert=False``: as stored, for :meth:`EquirectConverter.sample`)."""
        eye = self.eye if eye is None else eye
        if self.right is None and self.layout != "mono":
            stored = ("right" if eye == "left" else "left") if self.right_first else eye
            frame = split_eye(frame, self.layout, stored, source=self.path)
        c = self.converter
        return frame if c is None or not convert else c(frame)

    def frames(
        self,
        *,
        fmt: PixelFormat = "rgb24",
        eye: str | None = None,
        start: int = 0,
        end: int | None = None,
        threads: int | None = None,
        convert: bool = True,
    ) -> Iterator[NDArray[np.uint8]]:
        """One eye's equirect frames ``start <= i < end`` (``eye``: default ``self.eye``),
        one at a time; views into decoder buffers where possible (copy one to keep it);
        ``convert=False``: in the source's projection, as stored."""
        eye = self.eye if eye is None else eye
        it = self._decode(self.file_of(eye), fmt, start, end, threads)
        try:
            for f in it:
                yield self.eye_view(f, eye, convert=convert)
        finally:
            it.close()

    def eye_frames(
        self,
        *,
        fmt: PixelFormat = "rgb24",
        start: int = 0,
        end: int | None = None,
        threads: int | None = None,
        convert: bool = True,
    ) -> Iterator[tuple[NDArray[np.uint8], ...]]:
        """Frames ``start <= i < end`` as contiguous per-eye copies: ``(left, right)`` for a
        stereo source (two files decoded in step), ``(frame,)`` for a mono one. Every
        file is closed on every exit. ``convert=False``: in the source's projection, as
        stored (for a renderer sampling it). A still's clip yields one read-only tuple,
        the same at every frame (its frames are the same: made once, not copied per frame)."""
        kw = {"fmt": fmt, "threads": threads, "convert": convert}
        if not self.still:
            yield from self._eye_frames(start=start, end=end, **kw)
            return
        n = self._info.n_frames
        count = len(range(max(0, start), n if end is None else min(int(end), n)))
        if count == 0:
            return
        it = self._eye_frames(start=0, end=1, **kw)
        try:
            made = next(it)
        finally:
            it.close()
        for a in made:
            a.setflags(write=False)
        for _ in range(count):
            yield made

    def _eye_frames(self, *, fmt, start, end, threads, convert):
        """:meth:`eye_frames`, a fresh copy per frame."""
        if self.right is None:
            eyes = EYES if self.stereo else (self.eye,)
            it = self._decode(self.path, fmt, start, end, threads)
            try:
                for f in it:
                    yield tuple(
                        np.array(self.eye_view(f, e, convert=convert), order="C") for e in eyes
                    )
            finally:
                it.close()
            return
        kw = {"fmt": fmt, "start": start, "end": end, "threads": threads, "convert": convert}
        left, right = self.frames(eye="left", **kw), self.frames(eye="right", **kw)
        try:
            for fl in left:
                fr = next(right, None)
                if fr is None:
                    raise InputError(
                        f"{self.right}: right eye ends before the left eye ({self.path})"
                    )
                yield np.array(fl), np.array(fr)
        finally:
            left.close()
            right.close()

    def _decode(self, path: str, fmt: PixelFormat, start: int, end: int | None, threads):
        """Stored frames of ``path``: the video's, or a still's image repeated."""
        if not self.still:
            yield from iter_frames(path, fmt=fmt, start=start, end=end, threads=threads)
            return
        img = read_frame(path, 0, fmt=fmt)
        n = self._info.n_frames
        for _ in range(max(0, start), n if end is None else min(int(end), n)):
            yield img

    def read_stored(self, eye: str | None = None) -> NDArray[np.uint8]:
        """A still's stored image holding ``eye`` (RGB; InputError for a video)."""
        if not self.still:
            raise InputError(f"{self.path}: read_stored is for a still image")
        return read_frame(self.file_of(self.eye if eye is None else eye), 0)

    def read(
        self,
        index: int = 0,
        *,
        fmt: PixelFormat = "rgb24",
        eye: str | None = None,
        convert: bool = True,
    ):
        """One eye's equirect frame ``index`` (a copy; ``convert=False``: as stored)."""
        if index < 0:
            raise InputError(f"{self.path}: frame index must be >= 0; got {index}")
        eye = self.eye if eye is None else eye
        it = self._decode(self.file_of(eye), fmt, index, index + 1, None)
        try:
            for f in it:
                return np.array(self.eye_view(f, eye, convert=convert))
        finally:
            it.close()
        raise InputError(f"{self.path}: has no frame {index}")

    def frames_at(self, frames, *, eye: str | None = None) -> Iterator[tuple[int, NDArray[np.uint8]]]:
        """``(index, the eye's equirect frame RGB)`` for the sorted frame indices ``frames``
        of a video, without decoding from the start (a long video has its moments anywhere):
        decoding forward to a frame within 2 s, else a seek to the keyframe before it. A
        frame is found by its time (:meth:`MediaInfo.times_s`, the player's clock: a
        variable-rate video's frame ``i`` is not at ``i / fps``). Indices past the end are
        skipped; a still yields its image for each."""
        eye = self.eye if eye is None else eye
        frames = sorted({int(f) for f in frames})
        if self.still:
            img = self.read(0, eye=eye)
            yield from ((f, img) for f in frames if 0 <= f < self._info.n_frames)
            return
        import av

        info = self._info
        times = info.times_s(np.clip(frames, 0, max(info.n_frames - 1, 0)))
        tol = 0.25 / info.fps
        with av.open(str(self.file_of(eye))) as c:
            s = c.streams.video[0]
            s.thread_type = "AUTO"
            tb = float(s.time_base)
            # the player's clock, as probe's frame times: 0 at the container's start
            c0 = c.start_time / 1e6 if c.start_time is not None else (
                float(s.start_time * s.time_base) if s.start_time is not None else 0.0)  # fmt: skip
            it, pos = None, -math.inf
            for f, tf in zip(frames, times):
                if f < 0 or f >= info.n_frames:
                    continue
                if it is None or tf - pos > 2.0:
                    c.seek(int((tf + c0) / tb), stream=s, backward=True, any_frame=False)
                    it = c.decode(s)
                for fr in it:
                    pos = fr.pts * tb - c0 if fr.pts is not None else tf
                    if pos >= tf - tol:
                        yield f, np.array(self.eye_view(fr.to_ndarray(format="rgb24"), eye))
                        break


def as_source(video) -> Source:
    """``video`` if it is a :class:`Source`, else ``Source.open(video)`` (mono equirect)."""
    return video if isinstance(video, Source) else Source.open(video)


_IMAGE_CODECS = ("image", "mjpeg", "png", "bmp", "tiff", "webp")


def _resolve(path: str, what: str, given, from_file, notes: list[str]):
    """An option against the file's metadata: the option wins (a note if they differ)."""
    if given is None:
        return from_file
    if from_file is not None and from_file != given:
        notes.append(
            f"{path}: its spherical metadata says {what} {from_file}; --{what} {given} wins"
        )
    return given


def _pose(path: str, md_pose, apply: bool, notes: list[str]):
    """The initial orientation to apply (a non-zero one of the metadata, unless ``apply``
    is False), with a note saying what is done with it."""
    if not md_pose or not any(md_pose):
        return None
    text = "/".join(f"{v:g}" for v in md_pose)
    if not apply:
        notes.append(f"{path}: its spherical metadata's initial orientation (yaw/pitch/roll "
                     f"{text} deg) is ignored (--ignore-orientation)")  # fmt: skip
        return None
    notes.append(f"{path}: its spherical metadata gives an initial orientation (yaw/pitch/roll "
                 f"{text} deg): head yaw/pitch/roll 0 looks there (--ignore-orientation: not)")  # fmt: skip
    return tuple(float(v) for v in md_pose)


def _still_info(info: MediaInfo, seconds: float | None, fps: float | None) -> MediaInfo:
    """The MediaInfo of an image made a clip of ``seconds`` at ``fps``."""
    seconds = STILL_SECONDS if seconds is None else float(seconds)
    fps = STILL_FPS if fps is None else float(fps)
    if not (seconds > 0 and math.isfinite(seconds)):
        raise InputError(
            f"{info.path}: --seconds must be > 0 to make a clip of a still image; got {seconds:g}"
        )
    if not (fps > 0 and math.isfinite(fps)):
        raise InputError(f"{info.path}: --fps must be > 0; got {fps:g}")
    if fps > MAX_CLIP_FPS:
        raise InputError(f"{info.path}: --fps must be at most {MAX_CLIP_FPS:g}; got {fps:g}")
    if seconds * fps > MAX_CLIP_FRAMES + 0.5:
        raise InputError(
            f"{info.path}: a still as a clip of {seconds:g} s at {fps:g} fps has "
            f"{seconds * fps:.4g} frames; at most {MAX_CLIP_FRAMES:,} (lower --seconds or --fps)"
        )
    n = max(1, round(seconds * fps))
    return replace(info, fps=fps, n_frames=n, is_video=True)


def _check_lens_fov(projection: str, lens_fov_deg) -> float | None:
    """The lens FOV of a dual fisheye (default :data:`DEFAULT_LENS_FOV_DEG`); InputError for
    one outside (180, 360) or given for another projection."""
    if lens_fov_deg is None:
        return DEFAULT_LENS_FOV_DEG if projection == "dfisheye" else None
    f = float(lens_fov_deg)
    if projection != "dfisheye":
        raise InputError(f"--lens-fov is for --projection dfisheye; got --projection {projection}")
    if not (180.0 < f < 360.0):
        raise InputError(f"--lens-fov must be in (180, 360) degrees, e.g. 190; got {lens_fov_deg}")
    return f


def _check_right_eye(info: MediaInfo, right: str, layout: str, projection: str) -> None:
    """InputError unless ``right`` is a video matching ``info`` (the left eye's file):
    same stored size, frame rate and frame count, both one eye each (layout mono)."""
    if layout != "mono":
        raise InputError(
            f"{right}: --right takes the right eye's own equirect file; --layout {layout} "
            "is for one file holding both eyes (drop one of them)"
        )
    r = probe(right)
    other = read_spherical(right).get("projection") if r.is_video else None
    if other is not None and other != projection:
        raise InputError(
            f"{right}: a right-eye file of another projection ({other}, from its metadata); "
            f"the left eye ({info.path}) is {projection}"
        )
    if r.is_video != (info.codec not in _IMAGE_CODECS):
        what = "a video" if r.is_video else "a still image"
        raise InputError(
            f"{right}: {what}; the left eye ({info.path}) is not: --right takes the same kind"
        )
    if projection == "equirect":
        r.eye_size("mono")  # 2:1, else InputError naming the file
    if (r.width, r.height) != (info.width, info.height):
        raise InputError(
            f"{right}: right eye is {r.width}x{r.height}; the left eye ({info.path}) is "
            f"{info.width}x{info.height}: the two eye files must have the same size"
        )
    if not r.is_video:
        return  # two stills: the clip's rate and length are the options'
    if abs(r.fps - info.fps) > 1e-6 * info.fps:
        raise InputError(
            f"{right}: right eye is {r.fps:g} fps; the left eye ({info.path}) is {info.fps:g} fps"
        )
    if r.n_frames != info.n_frames:
        raise InputError(
            f"{right}: right eye has {r.n_frames} frames; the left eye ({info.path}) has "
            f"{info.n_frames}: the two eye files must have the same frames"
        )
