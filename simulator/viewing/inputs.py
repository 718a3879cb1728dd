"""Checks of one viewing's inputs: the time range and an EPOF CSV's opacity."""

from __future__ import annotations

import numpy as np

from simulator.core.errors import InputError
from simulator.epof.viewing import EpofResult
from simulator.media.gridfile import content_hash

__all__ = ["csv_opacity", "frame_range"]


def frame_range(
    n_frames: int,
    fps: float,
    start_s: float | None = None,
    end_s: float | None = None,
    *,
    video: str = "",
    times=None,
) -> tuple[int, int]:
    """Video frames ``f0 <= i < f1`` whose times ``i / fps`` lie in ``[start_s, end_s)``.

    None = the video's start / end. InputError (naming ``video``) for a range outside the
    video (``start_s`` < 0 or at/after the last frame, ``end_s`` beyond the video's
    duration ``n_frames / fps``), ``end_s <= start_s``, or a range holding no frame.
    ``times``: each frame's presentation time (a variable-rate stream,
    :attr:`simulator.media.video.MediaInfo.frame_times`) instead of ``i / fps``.
    """
    if times is not None:
        return _frame_range_times(np.asarray(times, float), fps, start_s, end_s, video)
    dur = n_frames / fps
    src = f"{video}: " if video else ""
    s = 0.0 if start_s is None else float(start_s)
    e = dur if end_s is None else float(end_s)
    if not (np.isfinite(s) and np.isfinite(e)):
        raise InputError(f"{src}--start/--end must be finite seconds; got {s}, {e}")
    if s < 0 or s >= dur:  # before --end: a --start past the end never talks of an --end
        raise InputError(f"{src}--start {s:g} s is outside the video (0 to {dur:g} s)")
    if e <= s:
        raise InputError(f"{src}--end {e:g} s must be after --start {s:g} s")
    if e > dur + 1e-6:
        raise InputError(f"{src}--end {e:g} s is beyond the video's end ({dur:g} s)")
    eps = 1e-6
    f0 = int(np.ceil(s * fps - eps))
    f1 = min(n_frames, int(np.ceil(e * fps - eps)))
    if f1 <= f0:
        raise InputError(f"{src}--start {s:g} s to --end {e:g} s holds no frame at {fps:g} fps")
    return f0, f1


def _frame_range_times(times, fps: float, start_s, end_s, video: str) -> tuple[int, int]:
    """:func:`frame_range` of frames at ``times`` (seconds, increasing)."""
    src = f"{video}: " if video else ""
    dt = np.diff(times)
    dur = float(times[-1] + (np.median(dt) if dt.size else 1.0 / fps))
    s = float(times[0]) if start_s is None else float(start_s)
    e = dur if end_s is None else float(end_s)
    if not (np.isfinite(s) and np.isfinite(e)):
        raise InputError(f"{src}--start/--end must be finite seconds; got {s}, {e}")
    if e <= s:
        raise InputError(f"{src}--end {e:g} s must be after --start {s:g} s")
    if s < 0 or s >= dur:
        raise InputError(f"{src}--start {s:g} s is outside the video (0 to {dur:g} s)")
    if e > dur + 1e-6:
        raise InputError(f"{src}--end {e:g} s is beyond the video's end ({dur:g} s)")
    f0 = int(np.searchsorted(times, s - 1e-6, side="left"))
    f1 = int(np.searchsorted(times, e - 1e-6, side="left"))
    if f1 <= f0:
        raise InputError(f"{src}--start {s:g} s to --end {e:g} s holds no frame")
    return f0, f1


def csv_opacity(res: EpofResult, path, frames, n_video: int, video=None) -> np.ndarray:
    """The opacity of video frames ``frames`` from an EPOF CSV (InputError unless the CSV
    has a row for each of them and no frame beyond the video, and, when the CSV records
    the content hash of its video (``# video_content_hash``), ``video`` has that hash)."""
    want = (res.meta.get("settings") or {}).get("video_content_hash")
    if video is not None and isinstance(want, str) and want != content_hash(video):
        raise InputError(
            f"{path}: EPOF CSV was computed for another video (its video_content_hash is "
            f"not that of {video}); compute it with vimsim epof on this video's grid"
        )
    fr = np.asarray(res.frame, np.int64)
    if fr.size and (fr.min() < 0 or fr.max() >= n_video):
        raise InputError(
            f"{path}: EPOF CSV has frames {int(fr.min())}..{int(fr.max())}; the video has "
            f"frames 0..{n_video - 1}: an EPOF CSV of another video?"
        )
    pos = {int(f): i for i, f in enumerate(fr)}
    missing = [int(f) for f in frames if int(f) not in pos]
    if missing:
        raise InputError(
            f"{path}: EPOF CSV has {fr.size} rows (frames {int(fr.min())}..{int(fr.max())}); "
            f"the render needs frames {int(frames[0])}..{int(frames[-1])} "
            f"({len(missing)} missing, first {missing[0]})"
        )
    op = np.asarray(res.opacity, float)[[pos[int(f)] for f in frames]]
    if np.any((op < 0) | (op > 1)):
        raise InputError(f"{path}: opacity outside [0, 1] in the EPOF CSV")
    return op
