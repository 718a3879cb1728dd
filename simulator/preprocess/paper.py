"""Paper-mode preprocessing (sections 3.2-3.4): a video's sliding-window POF matrix.

For every frame pair ``(t-1, t)`` every window of a :class:`~simulator.sphere.windows.WindowGrid`
is extracted from both frames (gray, bilinear, :class:`~simulator.sphere.windows.WindowExtractor`),
the dense flow inside the window is computed (:mod:`simulator.flow`) and reduced to two
scalars:

``pof_px``  (window pixels / frame)
    The paper's measure: the mean flow magnitude ``|f(p)|`` over the window's pixels.
    Both sums read the flow on every second pixel when the backend computes it at 1/4
    resolution (DIS ultrafast and fast, :func:`reduce_stride`), on every pixel otherwise.
``pof_dps`` (deg/s of visual angle)
    ``sum_p Omega(p) * angle(ray(p), ray(p + f(p))) * fps / sum_p Omega(p)``: the
    solid-angle-weighted (``Omega``) mean angle between the ray of a pixel centre and the
    ray of its flow target, times the frame rate. Rays follow
    :func:`~simulator.sphere.geometry.perspective_rays`: the continuous window position
    ``(x, y)`` (pixel centres at ``i + 0.5``) has its ray through
    ``u = (x / w * 2 - 1) tan(hfov / 2)``, ``v = (1 - y / h * 2) tan(vfov / 2)`` on the
    plane ``z = 1``; flow targets outside the window still have a ray. The angle between
    a window's own rays does not depend on the window's orientation, so one set of
    per-pixel constants serves every window (:class:`simulator.flow.rays.RayAngles`, shared
    with sphere mode).

Frame ``t = 0`` repeats ``t = 1`` (SPEC.md). The result is written with
:func:`simulator.media.gridfile.save_grid` (atomic: the grid file appears only when complete).

Pipeline (:mod:`simulator.preprocess.pairs`): a background thread decodes frame t+1 and
extracts its windows (into a recycled buffer) while a thread pool computes pair t; for thread-safe backends each worker runs the
flow and the reduction of one window at a time (the flow is reduced while in cache), and
two frame pairs are in flight so both cores stay busy across frame boundaries. Results do
not depend on threads or chunking (bit-identical to the one-thread batch path).

Streaming and checkpoints: frames are decoded one at a time (memory flat in the video's
length; the (T, P, Y) result grows by 2 KB per frame for the default grid). Finished rows
are saved periodically to ``GRID.npz.partial.npz`` beside the output (atomically), and on
Ctrl-C before exiting; ``resume=True`` continues from it and gives the same grid as an
uninterrupted run (every row depends on its two frames only, which are decoded
identically). A checkpoint made from another video or with other options is refused,
naming the difference.
"""

from __future__ import annotations

import json
import math
import os
import warnings
from collections.abc import Callable
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from simulator.core.errors import InputError
from simulator.core.fileio import atomic_output
from simulator.core.progress import Progress
from simulator.flow.base import FlowBackend, make_backend, native_stride
from simulator.flow.rays import RayAngles
from simulator.media.coverage import coverage_masks, coverage_meta
from simulator.media.gridfile import content_hash, save_grid
from simulator.media.source import Source, as_source
from simulator.preprocess.cao2021 import frame0_defect_meta, is_cao2021_grid
from simulator.preprocess.common import (
    check_output_dir,
    common_meta,
    flow_rate_scale,
    frame_range,
)
from simulator.preprocess.pairs import PairPipeline
from simulator.sphere.geometry import perspective_rays
from simulator.sphere.windows import WindowExtractor, WindowGrid

__all__ = ["WindowFlowReducer", "checkpoint_path", "preprocess_video", "reduce_stride"]

_CKPT_FORMAT = "vimsim-preprocess-checkpoint"


_CKPT_VERSION = 1

#: Window sampling. Bilinear, not bicubic: 0.6x the extraction CPU and closer to the
#: analytic rotation truth (bench/preprocess_accuracy.py, DIS ultrafast, median error
#: yaw 15 deg/s 3.53 -> 3.17 %, oblique 15 deg/s 3.64 -> 3.16 %; docs/paper_speed.md).
_INTERP = "linear"


class WindowFlowReducer:
    """Reduce window flow fields to ``(pof_dps, pof_px)`` (see the module docstring).

    Parameters
    ----------
    size : (w, h), window pixels
    hfov_deg, vfov_deg : float, degrees, the windows' exact FOVs
    stride : int >= 1, keyword-only
        Read the flow on every ``stride``-th pixel only (rows and columns ``stride // 2,
        stride // 2 + stride, ...``, :class:`simulator.flow.rays.RayAngles`): both sums run
        over those pixels (solid-angle weights renormalised over them). For backends that
        compute flow at a lower resolution and upsample it (DIS ultrafast and fast work at
        1/4 resolution, :func:`reduce_stride`), stride 2 reads the same field 4x faster.

    Call with ``flow`` ``(N, h, w, 2)`` float32 (window px / frame) and ``fps``; returns
    ``(dps, px)``, each ``(N,)`` float64: deg/s and px/frame.

    The per-pixel angles are :class:`simulator.flow.rays.RayAngles` (the formula sphere mode
    uses too). Sums are float64 pairwise sums, independent of memory alignment and
    threads: results are bit-reproducible.
    """

    def __init__(self, size: tuple[int, int], hfov_deg: float, vfov_deg: float, *, stride: int = 1):
        w, h = int(size[0]), int(size[1])
        _, sa = perspective_rays((w, h), hfov_deg, vfov_deg)
        self.size = (w, h)
        self._rays = RayAngles((w, h), hfov_deg, vfov_deg, stride=stride)
        self.stride = self._rays.stride
        sel = self._rays.sel
        sa = sa[sel, sel].astype(np.float64)
        self._npx = float(sa.size)
        self._wt32 = (sa / sa.sum()).astype(np.float32)

    def _one(self, f: NDArray[np.float32]) -> tuple[float, float]:
        """``(sum of weighted angles (rad), sum of |f| (px))`` of one window's flow."""
        ang, mag = self._rays.into_scratch(f, magnitude=True)
        # float64 pairwise sums: the order does not depend on memory alignment or threads
        # (BLAS dot and cv2.mean/magnitude do), so results are bit-reproducible (--resume).
        px_sum = float(np.sum(mag, dtype=np.float64))
        np.multiply(ang, self._wt32, out=mag)
        return float(np.sum(mag, dtype=np.float64)), px_sum

    def angles(self, flow: NDArray[np.float32]) -> NDArray[np.float32]:
        """Per-pixel angle in **radians** between each ray and its flow target's ray,
        ``(h, w)`` float32, for one window's flow ``(h, w, 2)``."""
        return self._rays(flow)

    def __call__(
        self, flow: NDArray[np.float32], fps: float
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        flow = np.asarray(flow, np.float32)
        if flow.ndim != 4 or flow.shape[1:] != (self.size[1], self.size[0], 2):
            raise ValueError(
                f"flow must be (N, {self.size[1]}, {self.size[0]}, 2); got {flow.shape}"
            )
        n = flow.shape[0]
        dps = np.empty(n)
        px = np.empty(n)
        k = math.degrees(1.0) * float(fps)
        npx = self._npx
        for i in range(n):
            a, m = self._one(flow[i])
            dps[i] = a * k
            px[i] = m / npx
        return dps, px


def reduce_stride(backend: FlowBackend) -> int:
    """The stride at which paper mode reads a backend's flow: its declared
    :attr:`~simulator.flow.base.FlowBackend.native_stride` (2 for DIS ``ultrafast`` and
    ``fast``: finest scale 2, flow computed at 1/4 resolution then upsampled bilinearly;
    the same rule as sphere mode), 1 for a plain function."""
    return native_stride(backend)


def checkpoint_path(output: str | os.PathLike) -> Path:
    """The checkpoint file of an output grid: ``GRID.npz.partial.npz`` beside it."""
    return Path(str(output) + ".partial.npz")


def _flatten(d: dict, prefix: str = "") -> dict:
    out = {}
    for k, v in d.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict):
            out.update(_flatten(v, key + "."))
        else:
            out[key] = v
    return out


def _save_checkpoint(path: Path, identity: dict, dps: list, px: list) -> None:
    meta = {
        "format": _CKPT_FORMAT,
        "version": _CKPT_VERSION,
        "identity": identity,
        "done": len(dps),
    }
    with atomic_output(path) as tmp, open(tmp, "wb") as fh:
        np.savez(
            fh,
            pof_dps=np.asarray(dps, np.float32).reshape(len(dps), *identity["grid_shape"]),
            pof_px=np.asarray(px, np.float32).reshape(len(px), *identity["grid_shape"]),
            meta=np.array(json.dumps(meta, sort_keys=True)),
        )


def _load_checkpoint(path: Path, identity: dict) -> tuple[list, list]:
    try:
        with np.load(path, allow_pickle=False) as z:
            meta = json.loads(str(z["meta"]))
            dps, px = z["pof_dps"], z["pof_px"]
    except Exception as e:  # noqa: BLE001 - any unreadable checkpoint is the same user error
        raise InputError(
            f"{path}: unreadable preprocess checkpoint ({type(e).__name__}: {e}); delete it"
        ) from None
    if (
        not isinstance(meta, dict)
        or meta.get("format") != _CKPT_FORMAT
        or meta.get("version") != _CKPT_VERSION
    ):
        raise InputError(
            f"{path}: not a vimsim preprocess checkpoint of version {_CKPT_VERSION}; delete it"
        )
    theirs, ours = _flatten(meta.get("identity", {})), _flatten(identity)
    # Video identity first, then options: the message names the most telling difference.
    for key in sorted(set(theirs) | set(ours), key=lambda k: (not k.startswith("video."), k)):
        a, b = theirs.get(key), ours.get(key)
        if isinstance(a, list):
            a = [x for x in a]
        if isinstance(b, (tuple, list)):
            b = list(b)
        if a != b:
            raise InputError(
                f"{path}: checkpoint was made with {key} = {a!r}, this run has {b!r}; "
                "rerun with the original video and options, or delete the checkpoint"
            )
    n = int(meta.get("done", -1))
    if dps.shape != px.shape or dps.shape[0] != n or dps.shape[1:] != tuple(identity["grid_shape"]):
        raise InputError(
            f"{path}: checkpoint arrays are inconsistent ({dps.shape}, {n} rows); delete it"
        )
    return list(dps), list(px)


def _identity(
    source: Source, grid: WindowGrid, backend: FlowBackend, stride: int, span: tuple[int, int]
) -> dict:
    """What a checkpoint must match to be resumed: the video, the grid, the flow and the range."""
    info = source.info
    return {
        "video": {
            "width": info.width,
            "height": info.height,
            "sar": round(info.sar, 9),
            "fps": info.fps,
            "n_frames": info.n_frames,
            "content_hash": content_hash(source.path),
        },
        "grid": grid.to_dict(),
        "grid_shape": list(grid.shape),
        "flow": backend.describe(),
        "reduce_stride": stride,
        "window_interp": _INTERP,
        "layout": source.layout,
        "eye": source.eye,
        "start_frame": span[0],
        "end_frame": span[1],
    }


def _grid_arrays(
    source: Source,
    grid: WindowGrid,
    backend: FlowBackend,
    identity: dict,
    rows: tuple[list, list],
    start_f: int,
    stride: int,
) -> tuple[NDArray, NDArray, dict]:
    """``(pof_dps, pof_px, meta)`` of the finished rows: frame-rate scale and coverage applied."""
    dps_rows, px_rows = rows
    n_rows = len(dps_rows)
    meta = common_meta(
        source,
        n_rows=n_rows,
        start_frame=start_f,
        flow=backend.describe(),
        content_hash=identity["video"]["content_hash"],
        units={
            "pof_dps": "deg/s of visual angle (solid-angle-weighted mean)",
            "pof_px": "window px/frame (mean magnitude)",
        },
    )
    meta["reduce_stride"] = stride
    meta["window_interp"] = _INTERP
    dps_all, px_all = np.stack(dps_rows), np.stack(px_rows)
    scale = flow_rate_scale(source.info, start_f, n_rows)
    if scale is not None:  # variable frame rate: deg/s over each row's true interval
        dps_all = dps_all * scale[:, None, None].astype(np.float32)
    cov = coverage_meta(source.covered, grid, None)
    if cov is not None:  # windows outside the projection: no flow measured
        meta["coverage"] = cov
        dps_all, px_all = (a * coverage_masks(meta)[0] for a in (dps_all, px_all))
    return dps_all, px_all, meta


def preprocess_video(
    video: str | os.PathLike,
    output: str | os.PathLike,
    *,
    grid: WindowGrid,
    flow: str | FlowBackend = "dis",
    start_s: float = 0.0,
    end_s: float | None = None,
    resume: bool = False,
    checkpoint_every_s: float = 60.0,
    threads: int | None = None,
    cache: bool = True,
    progress: Progress | None = None,
    on_frame: Callable[[int], None] | None = None,
) -> Path:
    """Compute a video's grid file (``pof_dps``, ``pof_px``; see the module docstring).

    Parameters
    ----------
    video : a :class:`simulator.media.source.Source` (stereo layout and the eye to use,
        projection) or the path of any FFmpeg-readable video (mono equirect, 2:1)
    output : the grid file to write (``.npz``)
    grid : the window grid (FOVs, steps, window size)
    flow : a backend or its ``--flow`` text (``dis``, ``farneback``, ``torch:MODEL.pt``)
    start_s, end_s : seconds; frames ``round(start_s * fps) <= i < round(end_s * fps)``
    resume : continue from ``checkpoint_path(output)`` if it exists
    checkpoint_every_s : wall-clock seconds between periodic checkpoints (0: every frame)
    threads : worker threads for the flow (default: CPU count)
    cache : read and store the window maps in the user cache folder
        (:mod:`simulator.core.mapcache`; False: ``--no-cache``)
    progress : ``progress(done, total)`` in frames, called as rows complete (the CLI draws a bar)
    on_frame : called with the grid row index after each row (tests use it to interrupt)

    Returns
    -------
    Path of the written grid file. Raises InputError on bad input (nothing written) and
    :class:`PreprocessInterrupted` on Ctrl-C (after saving a checkpoint).
    """
    source = as_source(video)
    src, info = source.path, source.info
    if not info.is_video:
        raise InputError(
            f"{src}: is a still image; preprocess needs a video with at least 2 frames"
        )
    if info.n_frames < 1:
        raise InputError(f"{src}: video stream has no frames")
    eye_w, eye_h = source.eye_size
    start_f, end_f = frame_range(info, float(start_s), end_s, src)
    out = check_output_dir(output)
    backend = flow if isinstance(flow, FlowBackend) else make_backend(flow, size=grid.size)
    ckpt = checkpoint_path(out)
    stride = reduce_stride(backend)
    identity = _identity(source, grid, backend, stride, (start_f, end_f))
    dps_rows: list[NDArray] = []
    px_rows: list[NDArray] = []
    if ckpt.exists():
        if not resume:
            raise InputError(
                f"{out}: a checkpoint of an interrupted run exists ({ckpt}); pass --resume to "
                "continue it or delete it to start again"
            )
        dps_rows, px_rows = _load_checkpoint(ckpt, identity)
    elif resume:
        warnings.warn(f"no checkpoint {ckpt}; starting from the first frame", stacklevel=2)

    extractor = WindowExtractor(grid, (eye_w, eye_h), cache=cache)
    reducer = WindowFlowReducer(grid.size, grid.hfov_deg, grid.vfov_deg, stride=stride)
    PairPipeline(
        source,
        grid,
        backend,
        reducer,
        extractor,
        interp=_INTERP,
        span=(start_f, end_f),
        rows=(dps_rows, px_rows),
        threads=threads,
        checkpoint=lambda: _save_checkpoint(ckpt, identity, dps_rows, px_rows),
        ckpt=ckpt,
        checkpoint_every_s=checkpoint_every_s,
        progress=progress,
        on_frame=on_frame,
    ).run()
    total = end_f - start_f
    n_rows = len(dps_rows)
    if n_rows < 2:
        raise InputError(f"{src}: only {n_rows} frame(s) could be decoded; flow needs at least 2")
    dps_all, px_all, meta = _grid_arrays(
        source, grid, backend, identity, (dps_rows, px_rows), start_f, stride
    )
    if n_rows != total:
        warnings.warn(f"{src}: expected {total} frames, decoded {n_rows}", stacklevel=2)
    if is_cao2021_grid(grid):  # their row 0, for --preset cao2021-code only (docs/parity.md)
        meta["cao"] = frame0_defect_meta(source, grid, backend, start_f)
    save_grid(out, dps_all, px_all, grid, meta)
    ckpt.unlink(missing_ok=True)
    return out
