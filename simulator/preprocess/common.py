"""What both preprocessing methods share: frame ranges, output checks and the grid meta they write."""

from __future__ import annotations

import math
import os
from dataclasses import replace
from pathlib import Path

import numpy as np

from simulator.core.errors import InputError
from simulator.media.gridfile import content_hash

__all__ = ["PreprocessInterrupted", "field_meta", "sphere_meta"]


class PreprocessInterrupted(KeyboardInterrupt):
    """Ctrl-C during :func:`preprocess_video`; the checkpoint was saved (message says where)."""

    def __init__(self, message: str):
        super().__init__(message)
        self.message = message


def check_output_dir(output: str | os.PathLike) -> Path:
    """``output`` as a Path after checking that its directory exists and is writable
    (InputError otherwise): called before any work, so a typo fails at once."""
    out = Path(output)
    parent = out.parent if str(out.parent) else Path(".")
    if not parent.is_dir() or not os.access(parent, os.W_OK):
        raise InputError(f"{out}: output directory {parent} does not exist or is not writable")
    return out


def frame_range(info, start_s: float, end_s: float | None, src: str) -> tuple[int, int]:
    """Video frames ``start <= i < end`` of ``--start``/``--end`` (seconds) for preprocess
    (both modes): ``start = round(start_s * fps)``, ``end = round(end_s * fps)`` capped at
    the video's frame count. InputError (naming ``src``) for a negative or non-finite
    start, an end not after the start, a start past the end of the video, or fewer than
    2 frames (flow needs a pair)."""
    fps = info.fps
    if not (start_s >= 0 and math.isfinite(start_s)):
        raise InputError(f"{src}: --start must be seconds >= 0; got {start_s}")
    if getattr(info, "frame_times", None) is not None:  # variable rate: by timestamps
        t = info.frame_times
        s = int(np.searchsorted(t, start_s - 0.5 / fps))
        e = info.n_frames if end_s is None else int(np.searchsorted(t, end_s - 0.5 / fps))
    else:
        s = round(start_s * fps)
        e = info.n_frames if end_s is None else min(info.n_frames, round(end_s * fps))
    if end_s is not None and not (end_s > start_s):
        raise InputError(f"{src}: --end ({end_s} s) must be after --start ({start_s} s)")
    if s >= info.n_frames:
        raise InputError(
            f"{src}: --start {start_s} s is past the end of the video ({info.duration_s:.3f} s)"
        )
    if e - s < 2:
        raise InputError(
            f"{src}: {e - s} frame(s) in the chosen range; flow needs at least 2 frames "
            f"(video: {info.n_frames} frames at {fps:g} fps)"
        )
    return s, e


def flow_rate_scale(info, start_frame: int, n_rows: int):
    """Per grid row, the factor turning deg/s computed with ``fps`` into deg/s over the
    true interval between the row's two frames (a variable-rate stream; row 0 repeats
    row 1), or None for a constant rate."""
    if info.frame_times is None:
        return None
    t = info.times_s(np.arange(max(0, start_frame - 1), start_frame + n_rows))
    dt = np.diff(t)
    if start_frame == 0:
        dt = np.concatenate([dt[:1], dt])
    dt = dt[-n_rows:].copy()
    if n_rows > 1:
        dt[0] = dt[1]  # row 0 repeats row 1
    return 1.0 / (info.fps * np.maximum(dt, 1e-6))


def common_meta(
    source,
    *,
    n_rows: int,
    start_frame: int,
    flow: dict,
    content_hash: str,
    units: dict,
) -> dict:
    """The grid-file ``meta`` both methods write (paper and sphere mode): frames, flow,
    layout, eye, the frame range, units and the video's identity (``GridFile.check_video``
    compares it with a video) of ``source`` (a :class:`simulator.media.source.Source`)."""
    info = source.info
    fps = info.fps
    vfr = {}
    if info.frame_times is not None:  # the stream's timestamps of the grid's rows
        t = info.times_s(np.arange(start_frame, start_frame + n_rows))
        vfr = {"frame_times_s": [round(float(v), 6) for v in t]}
    return {
        **vfr,
        "fps": fps,
        "n_frames": n_rows,
        "flow": flow,
        "layout": source.layout,
        "eye": source.eye,
        "projection": source.projection,
        "source": source.settings(),
        "start_frame": start_frame,
        "end_frame": start_frame + n_rows,
        "start_s": float(info.times_s([start_frame])[0]),
        "eye_size": list(source.eye_size),
        "units": units,
        "frame0": "repeats frame 1",
        "video": {
            "path": str(Path(source.path).resolve()),
            "width": info.width,
            "height": info.height,
            "sar": info.sar,
            "codec": info.codec,
            "n_frames": info.n_frames,
            "content_hash": content_hash,
        },
    }


def field_meta(config, dtype: str = "float16") -> dict:
    """The ``meta["field"]`` entry of a grid file holding a field."""
    return {
        "method": "sphere",
        "units": "deg/s",
        "dtype": dtype,
        "cell_deg": float(config.cell_deg),
        "layout": "lonlat: row 0 = north (lat centre 90 - (i + 0.5) * cell_deg), column 0 = lon -180 (centre -180 + (j + 0.5) * cell_deg); cell = solid-angle mean speed of content at frame t-1, flow t-1 -> t",
        "tiles": config.to_dict(),
    }


def sphere_meta(source, T, start_f, desc, cov, config, default_stride, field_dtype) -> dict:
    """The meta of a sphere-mode grid file (:func:`simulator.preprocess.sphere.preprocess_sphere`)."""
    return {
        "method": "sphere",
        **common_meta(
            source,
            n_rows=T,
            start_frame=start_f,
            flow=desc,
            content_hash=content_hash(source.path),
            units={
                "pof_dps": "deg/s of visual angle (solid-angle-weighted mean), derived from field_dps",
                "pof_px": "window px/frame (mean magnitude), derived from field_dps assuming isotropic flow directions per cell (approximate)",
                "field_dps": "deg/s of visual angle",
            },
        ),
        **({} if cov is None else {"coverage": cov}),
        "field": field_meta(replace(config, stride=config.stride or default_stride), field_dtype),
    }
