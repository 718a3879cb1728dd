"""AVTrack360 (Fremerey et al., MMSys 2018) head traces: one JSON file, many videos per user."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from simulator.core.errors import InputError
from simulator.traces.path import HeadPath
from simulator.traces.readers.common import _check_finite, _check_increasing, _dedupe_times
from simulator.traces.readers.formats import TraceFormat


def _read_avtrack360(p: Path, video: str | None) -> HeadPath:
    """AVTrack360 ``Head_rotation/<subject>.json``: one entry per video, integer degrees,
    ``sec`` = playback time. Their pitch is + down, yaw + right (yaw 0 = start view),
    roll + right ear down: ours = (yaw, -pitch, roll), applied yaw, pitch, roll."""
    try:
        obj = json.loads(p.read_text(encoding="utf-8-sig"))
        entries = obj["data"]
        names = [str(e["filename"]) for e in entries]
    except RecursionError:
        raise InputError(f"{p}: JSON nested too deeply; not an AVTrack360 file") from None
    except (json.JSONDecodeError, UnicodeDecodeError, KeyError, TypeError) as e:
        raise InputError(
            f"{p}: not an AVTrack360 head rotation file ({type(e).__name__}: {e})"
        ) from None
    if video is None:
        if len(names) == 1:
            video = names[0]
        else:
            raise InputError(
                f"{p}: holds {len(names)} videos; choose one with --video (one of {', '.join(names)})"
            )
    want = video if video.endswith(".mp4") else f"{video}.mp4"
    if want not in names:
        raise InputError(f"{p}: no video {video!r}; available: {', '.join(names)}")
    try:
        samples = entries[names.index(want)]["pitch_yaw_roll_data_hmd"]
    except (KeyError, TypeError):
        raise InputError(
            f"{p}: video {want}: entry has no pitch_yaw_roll_data_hmd samples; "
            "not an AVTrack360 head rotation file?"
        ) from None
    try:
        data = np.array(
            [
                [float(s["sec"]), float(s["yaw"]), float(s["pitch"]), float(s["roll"])]
                for s in samples
            ]
        )
    except (KeyError, TypeError, ValueError):
        raise InputError(f"{p}: video {want}: samples need numeric sec, yaw, pitch, roll") from None
    if data.size == 0:
        raise InputError(f"{p}: video {want} has no samples")
    # Errors name the 1-based sample of the video's entry (JSON has no useful line numbers).
    src = f"{p}: video {want}"
    labels = np.arange(1, len(data) + 1)
    _check_finite(src, ["sec", "yaw", "pitch", "roll"], data, labels, "sample")
    keep = _dedupe_times(data[:, 0])
    data, labels = data[keep], labels[keep]
    _check_increasing(src, data[:, 0], labels, "sample")
    return HeadPath.from_angles_deg(
        data[:, 0], data[:, 1], -data[:, 2], data[:, 3], source=f"{p}:{want}"
    )


#: The format this module reads (the registry of ``simulator.traces.readers``).
TRACE_FORMATS = (
    TraceFormat("avtrack360", lambda p, video=None, **_: _read_avtrack360(p, video),
                lambda s: s.is_json and "pitch_yaw_roll_data_hmd" in s.text, rank=10),
)  # fmt: skip
