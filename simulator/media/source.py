"""The video source of a viewing: file, stereo layout, projection, right-eye file and eye, checked once and decoded through one funnel.

A :class:`Source` is what every stage takes instead of a loose path plus ``layout=``,
``right=`` and ``eye=``: ``Source.open`` checks the file(s) once (readable, each eye 2:1
equirect for ``equirect``, a right-eye file matching the left), and its methods decode
one eye's frames (:meth:`Source.frames`), both eyes in step (:meth:`Source.eye_frames`)
or one frame (:meth:`Source.read`), always as equirect frames of :meth:`Source.eye_size`.
Library functions accept a Source or a plain path (:func:`as_source`: mono equirect).
"""

from __future__ import annotations

import os
import re
from collections.abc import Iterator
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from simulator.core.choices import EYES, LAYOUTS
from simulator.core.errors import InputError
from simulator.media.video import MediaInfo, PixelFormat, iter_frames, probe
from simulator.sphere.geometry import split_eye

__all__ = ["PROJECTION_NAMES", "Source", "as_source", "check_local_path"]

#: Input projections (ffmpeg ``v360``'s names).
PROJECTION_NAMES: tuple[str, ...] = ("equirect",)

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
    info : the file's :class:`simulator.media.video.MediaInfo` (of ``path``)
    """

    path: str
    layout: str = "mono"
    projection: str = "equirect"
    right: str | None = None
    eye: str = "left"
    info: MediaInfo | None = field(default=None, compare=False, repr=False)

    @classmethod
    def open(
        cls,
        path,
        *,
        layout: str = "mono",
        projection: str = "equirect",
        right=None,
        eye: str = "left",
    ) -> Source:
        """Check and probe a source (InputError naming the file or option on bad input)."""
        path = check_local_path(path)
        if layout not in LAYOUTS:
            raise InputError(
                f"{path}: unknown stereo layout {layout!r}; expected one of {', '.join(LAYOUTS)}"
            )
        if eye not in EYES:
            raise InputError(f"{path}: unknown eye {eye!r}; expected left or right")
        if projection not in PROJECTION_NAMES:
            raise InputError(
                f"--projection {projection!r}: unknown; expected one of "
                f"{', '.join(PROJECTION_NAMES)}"
            )
        info = probe(path)
        src = cls(path, layout, projection, None, eye, info)
        src.eye_size  # noqa: B018 - checks each eye is 2:1 (InputError otherwise)
        if right is not None:
            right = check_local_path(right)
            _check_right_eye(info, right, layout)
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
        return self._info.eye_size(self.layout)

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
            "eye": self.eye,
            "right": self.right,
        }

    # -- the decode funnel -------------------------------------------------------------
    def file_of(self, eye: str) -> str:
        """The file holding ``eye``'s frames."""
        return self.right if self.right is not None and eye == "right" else self.path

    def eye_view(self, frame: NDArray, eye: str | None = None) -> NDArray:
        """``eye``'s equirect frame from a decoded frame of :meth:`file_of` ``(eye)``: the
        stereo half (a view for ``top-bottom``) in the source's projection, converted."""
        eye = self.eye if eye is None else eye
        if self.right is None and self.layout != "mono":
            frame = split_eye(frame, self.layout, eye, source=self.path)
        return frame

    def frames(
        self,
        *,
        fmt: PixelFormat = "rgb24",
        eye: str | None = None,
        start: int = 0,
        end: int | None = None,
        threads: int | None = None,
    ) -> Iterator[NDArray[np.uint8]]:
        """One eye's equirect frames ``start <= i < end`` (``eye``: default ``self.eye``),
        one at a time; views into decoder buffers where possible (copy one to keep it)."""
        eye = self.eye if eye is None else eye
        it = iter_frames(self.file_of(eye), fmt=fmt, start=start, end=end, threads=threads)
        try:
            for f in it:
                yield self.eye_view(f, eye)
        finally:
            it.close()

    def eye_frames(
        self,
        *,
        fmt: PixelFormat = "rgb24",
        start: int = 0,
        end: int | None = None,
        threads: int | None = None,
    ) -> Iterator[tuple[NDArray[np.uint8], ...]]:
        """Frames ``start <= i < end`` as contiguous per-eye copies: ``(left, right)`` for a
        stereo source (two files decoded in step), ``(frame,)`` for a mono one. Every
        file is closed on every exit."""
        if self.right is None:
            eyes = EYES if self.stereo else (self.eye,)
            it = iter_frames(self.path, fmt=fmt, start=start, end=end, threads=threads)
            try:
                for f in it:
                    yield tuple(np.array(self.eye_view(f, e), order="C") for e in eyes)
            finally:
                it.close()
            return
        left = self.frames(fmt=fmt, eye="left", start=start, end=end, threads=threads)
        right = self.frames(fmt=fmt, eye="right", start=start, end=end, threads=threads)
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

    def read(self, index: int = 0, *, fmt: PixelFormat = "rgb24", eye: str | None = None):
        """One eye's equirect frame ``index`` (a copy)."""
        if index < 0:
            raise InputError(f"{self.path}: frame index must be >= 0; got {index}")
        it = self.frames(fmt=fmt, eye=eye, start=index, end=index + 1)
        try:
            for f in it:
                return np.array(f)
        finally:
            it.close()
        raise InputError(f"{self.path}: has no frame {index}")


def as_source(video) -> Source:
    """``video`` if it is a :class:`Source`, else ``Source.open(video)`` (mono equirect)."""
    return video if isinstance(video, Source) else Source.open(video)


def _check_right_eye(info: MediaInfo, right: str, layout: str) -> None:
    """InputError unless ``right`` is a video matching ``info`` (the left eye's file):
    same stored size, frame rate and frame count, both one eye each (layout mono)."""
    if layout != "mono":
        raise InputError(
            f"{right}: --right takes the right eye's own equirect file; --layout {layout} "
            "is for one file holding both eyes (drop one of them)"
        )
    r = probe(right)
    if not r.is_video and info.is_video:
        raise InputError(f"{right}: a still image; --right needs the right eye's video")
    r.eye_size("mono")  # 2:1, else InputError naming the file
    if (r.width, r.height) != (info.width, info.height):
        raise InputError(
            f"{right}: right eye is {r.width}x{r.height}; the left eye ({info.path}) is "
            f"{info.width}x{info.height}: the two eye files must have the same size"
        )
    if abs(r.fps - info.fps) > 1e-6 * info.fps:
        raise InputError(
            f"{right}: right eye is {r.fps:g} fps; the left eye ({info.path}) is {info.fps:g} fps"
        )
    if r.n_frames != info.n_frames:
        raise InputError(
            f"{right}: right eye has {r.n_frames} frames; the left eye ({info.path}) has "
            f"{info.n_frames}: the two eye files must have the same frames"
        )
