"""Sphere-mode preprocessing: the optical flow of each frame as one angular-speed field on the sphere.

The paper computes flow for 198-264 overlapping windows per frame and needs a new run for
every headset FOV. Here the flow of a frame pair is computed once, on a few overlapping
perspective *tiles* covering the sphere (a cube with faces a little wider than 90 deg),
converted to angular speed per pixel and splatted into lon/lat cells
(:class:`simulator.sphere.cells.CellGrid`); any viewport or window grid is a weighted sum
over cells (:mod:`simulator.epof.exact`).

Speeds are **deg/s of visual angle**: the angle between the ray of a pixel of frame t-1
and the ray of its flow target in frame t, times fps. The field ``field_dps`` is float32,
shape (T, n_lat, n_lon), laid out like an equirect frame (:mod:`simulator.sphere.cells`); a
cell holds the solid-angle mean speed of its content at frame t-1 (flow t-1 -> t); frame 0
repeats frame 1.
"""

from __future__ import annotations

import functools
import math
import warnings
from collections.abc import Callable, Iterable
from dataclasses import dataclass, replace

import cv2
import numpy as np
from numpy.typing import NDArray
from scipy import sparse

from simulator.core.errors import InputError
from simulator.core.progress import Counter, Progress
from simulator.flow.base import FlowBackend, make_backend, native_stride
from simulator.flow.rays import RayAngles
from simulator.media.coverage import COVERED_SHARE, cell_coverage, coverage_masks, coverage_meta
from simulator.media.gridfile import FieldSpool, save_grid
from simulator.media.source import as_source
from simulator.media.video import prefetch
from simulator.preprocess.artefacts import SignalCollector, artefacts_meta, detect_artefacts
from simulator.preprocess.common import check_output_dir, flow_rate_scale, frame_range, sphere_meta
from simulator.preprocess.ego import EGO_META, EgoRows, FrameParts, MidpointSplat, adjust_parts
from simulator.preprocess.fixedcontent import keyframe_flags
from simulator.preprocess.slowflow import SlowFine, slow_flow_desc
from simulator.preprocess.tiles import downscale, tile_frames
from simulator.sphere.cells import CellGrid, _cell_geometry, window_pof
from simulator.sphere.geometry import (
    dir_to_lonlat,
    equirect_remap_coords,
    head_rotation,
    pad_equirect,
    perspective_rays,
)
from simulator.sphere.windows import WindowGrid

__all__ = [
    "FieldEstimator",
    "SphereConfig",
    "field_from_frames",
    "field_from_video",
    "preprocess_sphere",
]

#: Cube faces as (yaw_deg, pitch_deg): front, right, back, left, up, down.
_CUBE = ((0.0, 0.0), (90.0, 0.0), (180.0, 0.0), (-90.0, 0.0), (0.0, 90.0), (0.0, -90.0))


#: A flow function or backend (:class:`simulator.flow.base.FlowBackend`): ``flow(prev, cur)`` with
#: ``(N, h, w)`` uint8 tiles returns ``(N, h, w, 2)`` float32 pixel flow ``(dx, dy)`` from prev
#: to cur (x right, y down).
FlowFn = Callable[[NDArray[np.uint8], NDArray[np.uint8]], NDArray[np.float32]]


@dataclass(frozen=True)
class SphereConfig:
    """How the field is computed.

    tile_fov_deg : float, degrees in (90, 150)
        FOV of each of the 6 cube-face tiles (a little wider than 90 deg so faces overlap
        and every direction lies well inside some tile).
    tile_size : int, pixels
        Side of each square tile. The default 100 deg / 256 px (0.53 deg per pixel at the
        tile centre) was picked in bench/sphere_accuracy.py-style runs on the synthetic
        scenes: window error 0.6-1.5% median against 1.1-4.2% for 110 deg / 192 px (a
        positive bias that grows with the pixel's angular size) at ~1.3x the flow time.
    cell_deg : float, degrees
        Cell size of the lon/lat field; must divide 180.
    stride : int or None
        Evaluate the flow on every ``stride``-th pixel of each tile. ``None``: 2 for DIS
        ``ultrafast``/``fast`` (they compute flow at 1/4 resolution and upsample it, so
        nothing is lost), else 1.
    """

    tile_fov_deg: float = 100.0
    tile_size: int = 256
    cell_deg: float = 4.0
    stride: int | None = None

    def __post_init__(self) -> None:
        if not (90.0 < float(self.tile_fov_deg) < 150.0):
            raise InputError(
                f"sphere tile FOV must be degrees in (90, 150); got {self.tile_fov_deg}"
            )
        if not (16 <= int(self.tile_size) <= 1024):
            raise InputError(f"sphere tile size must be 16..1024 pixels; got {self.tile_size}")
        object.__setattr__(self, "tile_size", int(self.tile_size))
        CellGrid(self.cell_deg)  # validates
        if self.stride is not None and not (1 <= int(self.stride) <= 8):
            raise InputError(f"sphere flow stride must be 1..8 pixels; got {self.stride}")

    def to_dict(self) -> dict:
        return {
            "tile_fov_deg": float(self.tile_fov_deg),
            "tile_size": self.tile_size,
            "tiles": "cube",
            "cell_deg": float(self.cell_deg),
            "stride": self.stride,
        }


class _TileGeometry:
    """Everything about the tiles that depends only on config and frame size."""

    def __init__(self, cfg: SphereConfig, equirect_size: tuple[int, int], stride: int):
        W, H = equirect_size
        s, fov = cfg.tile_size, cfg.tile_fov_deg
        t = math.tan(math.radians(fov) / 2.0)
        # Pyramid level: halve the equirect while its pixels stay finer than a tile's
        # centre pixel (anti-aliasing for the linear remap, and a cheaper remap). The
        # halvings are 2x2 area means (:func:`simulator.preprocess.tiles.downscale`, as the
        # projection path's): at 8K 4 ms of CPU per frame against 11 for three pyrDowns.
        centre_px_deg = math.degrees(2.0 * math.atan(t / s))
        # Stored pixels may be non-square (e.g. SAR 9:8): lon and lat steps are checked apart.
        level, w, h = 0, W, H
        while (
            w % 4 == 0
            and max(360.0 / (w // 2), 180.0 / ((h + 1) // 2)) <= centre_px_deg
            and min(w // 2, (h + 1) // 2) >= 32
        ):
            w, h = w // 2, (h + 1) // 2
            level += 1
        self.level = level
        self.small_size = (w, h)
        dirs, sa = perspective_rays((s, s), fov, fov)
        R = head_rotation(
            [a[0] for a in _CUBE], [a[1] for a in _CUBE], 0.0
        ).as_matrix()  # (6, 3, 3)
        world = np.einsum("nij,hwj->nhwi", R, dirs.astype(np.float64), optimize=True)  # BLAS: 40x
        mx, my = equirect_remap_coords(world.reshape(len(_CUBE) * s, s, 3), *self.small_size)
        self.m1, self.m2 = cv2.convertMaps(mx, my, cv2.CV_16SC2)
        # Flow is evaluated on every ``stride``-th pixel (DIS presets with finest scale 2
        # compute flow at 1/4 resolution and upsample it: stride 2 loses nothing).
        st = self.stride = stride
        sel = np.arange(st // 2, s, st)
        # Per-pixel ray angles of the tile's flow (the formula paper mode uses), on the
        # evaluated pixels; their tile-plane coordinates u0, v0 (tan units, x right, y up).
        self.rays = RayAngles((s, s), fov, fov, stride=st)
        # Blend weight: 1 inside the cube face each tile owns (max(|u|,|v|) <= 1), falling
        # smoothly to 0 at the tile border where flow is least reliable.
        m = np.maximum(np.abs(self.rays.u0), np.abs(self.rays.v0)).astype(np.float64)
        x = np.clip((t - m) / (t - 1.0), 0.0, 1.0)
        blend = x * x * (3.0 - 2.0 * x)
        sub_world = world[:, sel][:, :, sel].reshape(-1, 3)
        w = np.broadcast_to(sa[np.ix_(sel, sel)] * blend, (len(_CUBE), len(sel), len(sel))).reshape(
            -1
        )
        lon, lat = dir_to_lonlat(sub_world)
        cells = CellGrid(cfg.cell_deg)
        idx = cells.index(lon, lat)
        self.splat = _splat_matrix(idx, w, cells, sub_world)
        self.n_tiles = len(_CUBE)
        self.size = s
        self.midpoint = MidpointSplat(
            R, s, t, self.rays.sel, self.rays.u0, self.rays.v0, w, cells, self.splat,
            self.rays._cx, self.rays._cy,
        )  # fmt: skip

    def tiles(self, frame: NDArray[np.uint8]) -> NDArray[np.uint8]:
        f = downscale(frame, self.small_size) if self.level else np.ascontiguousarray(frame)
        out = cv2.remap(
            pad_equirect(f), self.m1, self.m2, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE
        )
        return out.reshape(self.n_tiles, self.size, self.size)

    def angles(self, flow: NDArray[np.float32]) -> NDArray[np.float32]:
        """Angle (radians) between each evaluated pixel's ray and its flow target's ray;
        flow is ``(N, s, s, 2)`` pixels (x right, y down) -> ``(N, s', s')``."""
        return self.rays(flow)


def _splat_matrix(idx: NDArray, w: NDArray, cells: CellGrid, dirs: NDArray) -> sparse.csr_matrix:
    """Sparse ``(C, n_px)`` matrix: cell value = weighted mean of its pixels' values; cells
    no pixel centre falls in (tiny polar cells) copy their nearest covered cell."""
    C = cells.n_cells
    keep = w > 0
    idx, w, cols = idx[keep], w[keep], np.nonzero(keep)[0]
    tot = np.bincount(idx, weights=w, minlength=C)
    covered = tot > 0
    rows, vals = idx, w / tot[idx]
    if not covered.all():
        centre = _cell_geometry(cells.cell_deg)[0]
        empty = np.nonzero(~covered)[0]
        full = np.nonzero(covered)[0]
        near = full[np.argmax(centre[empty] @ centre[full].T, axis=1)]
        # Rows of the nearest covered cells, re-labelled.
        m = sparse.csr_matrix((vals, (rows, cols)), shape=(C, len(keep)))
        extra = m[near].tocoo()
        rows = np.concatenate([rows, empty[extra.row]])
        cols = np.concatenate([cols, extra.col])
        vals = np.concatenate([vals, extra.data])
    return sparse.csr_matrix((vals.astype(np.float32), (rows, cols)), shape=(C, len(keep)))


def _backend(flow, tile_size: int) -> tuple[FlowFn, int, dict]:
    """``(flow function, default stride, description for meta)`` of a flow spec, for
    square tiles of ``tile_size`` pixels."""

    be = make_backend(flow, size=(tile_size, tile_size)) if isinstance(flow, str) else flow
    stride = native_stride(be)
    desc = (
        be.describe()
        if isinstance(be, FlowBackend)
        else {"method": getattr(be, "__name__", "custom")}
    )
    return be, stride, slow_flow_desc(be, desc)


class FieldEstimator:
    """Per-frame angular-speed fields of an equirect video, one frame pair at a time.

    Parameters
    ----------
    equirect_size : (W, H), pixels of one eye's equirect frame (stored pixels)
    fps : float, frames per second (converts per-frame angles to deg/s)
    config : SphereConfig
    flow : str or FlowBackend or FlowFn
        Pixel flow between two stacks of tiles: a ``--flow`` text (``"dis"`` = OpenCV DIS
        ultrafast, ``"dis:fast"``, ``"farneback"``, ``"torch:MODEL.pt"``), a
        :class:`simulator.flow.base.FlowBackend`, or any function of that signature.

    Use :meth:`tiles` on each decoded gray frame, then :meth:`field` on consecutive tile
    stacks; :func:`field_from_frames` and :func:`field_from_video` do the loop.
    """

    def __init__(
        self,
        equirect_size: tuple[int, int],
        fps: float,
        config: SphereConfig = SphereConfig(),
        *,
        flow: str | FlowFn = "dis",
    ):
        if not (fps > 0) or not math.isfinite(fps):
            raise InputError(f"frame rate must be > 0 frames/s; got {fps}")
        W, H = int(equirect_size[0]), int(equirect_size[1])
        # The 2:1 display aspect (with the sample aspect ratio) is the caller's check
        # (MediaInfo.eye_size); stored pixels may be non-square.
        if W % 2 or W < 64 or H < 32 or not (0.8 <= W / H <= 4.5):
            raise InputError(
                f"sphere mode needs an equirect frame with an even width >= 64 and about 2:1 "
                f"(stored pixels may be non-square); got {W}x{H}"
            )
        self.config = config
        self.cells = CellGrid(config.cell_deg)
        self.fps = float(fps)
        self.equirect_size = (W, H)
        be, stride, self.flow_desc = _backend(flow, config.tile_size)
        self._flow = SlowFine(be)  # the default DIS: slow pairs read finer
        self.stride = int(config.stride or stride)
        self._geo = _tile_geometry(config, (W, H), self.stride)

    def tiles(self, frame: NDArray[np.uint8]) -> NDArray[np.uint8]:
        """The 6 cube-face tiles ``(6, s, s)`` uint8 of a gray ``(H, W)`` frame."""
        if frame.shape[:2] != self.equirect_size[::-1] or frame.ndim != 2:
            raise InputError(
                f"expected a gray {self.equirect_size[0]}x{self.equirect_size[1]} frame; got shape {frame.shape}"
            )
        return self._geo.tiles(frame)

    def field(self, prev_tiles: NDArray[np.uint8], tiles: NDArray[np.uint8]) -> NDArray[np.float32]:
        """Angular-speed field ``(n_lat, n_lon)`` float32 in deg/s of the flow prev -> cur."""
        return self.parts(prev_tiles, tiles).field

    def parts(self, prev_tiles: NDArray[np.uint8], tiles: NDArray[np.uint8]) -> FrameParts:
        """The field of the flow prev -> cur, its translational part (the residual once
        the fitted camera rotation is removed, :mod:`simulator.preprocess.ego`) and the
        camera's angular velocity with its confidence."""
        fl = self._flow(prev_tiles, tiles)
        fxy = self._geo.rays.components(fl)  # gathered once for both
        ang, _ = self._geo.rays.into_scratch(fl, components=fxy)
        f, tr, fit = self._geo.midpoint(fl, ang, fxy)
        k = math.degrees(1.0) * self.fps
        shape = self.cells.shape
        return FrameParts(
            (f * k).astype(np.float32).reshape(shape),
            (tr * k).astype(np.float32).reshape(shape),
            (-fit.w * k).astype(np.float32),
            float(fit.confidence),
        )


@functools.lru_cache(maxsize=4)
def _tile_geometry(cfg: SphereConfig, equirect_size: tuple[int, int], stride: int) -> _TileGeometry:
    return _TileGeometry(cfg, equirect_size, stride)


class _FieldRows:
    """Per-frame fields appended into one preallocated ``(T, n_lat, n_lon)`` float32 array
    (grown by doubling if ``expected`` was short), row 0 reserved for the copy of row 1:
    peak memory is the result itself, with no list of rows and no final stack."""

    def __init__(self, shape: tuple[int, int], expected: int):
        self._a = np.empty((max(2, int(expected)), *shape), np.float32)
        self.n = 1  # rows filled, counting the reserved row 0

    def append(self, f: NDArray[np.float32]) -> None:
        if self.n == len(self._a):
            grown = np.empty((2 * len(self._a), *self._a.shape[1:]), np.float32)
            grown[: self.n] = self._a
            self._a = grown
        self._a[self.n] = f
        self.n += 1

    def result(self) -> NDArray[np.float32]:
        """``(n, n_lat, n_lon)``; row 0 = row 1 (frame 0 has no predecessor)."""
        a = self._a[: self.n]
        a[0] = a[1]
        return a if self.n > 0.9 * len(self._a) else a.copy()


def field_from_frames(
    frames: Iterable[NDArray[np.uint8]],
    equirect_size: tuple[int, int],
    fps: float,
    config: SphereConfig = SphereConfig(),
    *,
    flow: str | FlowFn = "dis",
    progress: Callable[[int], None] | None = None,
) -> NDArray[np.float32]:
    """Fields ``(T, n_lat, n_lon)`` float32 deg/s of a sequence of gray equirect frames.

    Frame t holds the flow from frame t-1 to t; frame 0 repeats frame 1. Needs >= 2 frames.
    ``progress(n)`` is called after each frame with the number of frames done.
    """
    est = FieldEstimator(equirect_size, fps, config, flow=flow)
    return _fields(est, (est.tiles(f) for f in frames), 256, progress, "")


def _fields(
    est: FieldEstimator, tiles, expected: int, progress, source: str, sink=None, ego=None,
    mask=None, scale=None,
):  # fmt: skip
    """The field of each consecutive pair of ``tiles`` (one frame's tiles per item; frame 0
    repeats frame 1) into one :class:`_FieldRows` of ``expected`` frames (or ``sink``), the
    rotation and translational field into ``ego`` (:class:`EgoRows`); ``source`` prefixes
    the error for < 2 frames; ``mask``, ``scale``: see :func:`simulator.preprocess.ego.adjust_parts`."""
    out = _FieldRows(est.cells.shape, expected) if sink is None else sink
    prev = None
    n = 0
    for t in tiles:
        if prev is not None:
            k = None if scale is None else scale[min(n, len(scale) - 1)]
            p = adjust_parts(est.parts(prev, t), mask, k)
            out.append(p.field)
            if ego is not None:
                ego.append(p)
        prev = t
        n += 1
        if progress is not None:
            progress(n)
    if (out.n if sink is None else out.n_rows) < 2:
        raise InputError(f"{source}sphere mode needs at least 2 frames; got {n}")
    return out.result() if sink is None else out



def field_from_video(
    source,
    config: SphereConfig = SphereConfig(),
    *,
    start: int = 0,
    end: int | None = None,
    flow: str | FlowFn = "dis",
    progress: Callable[[int], None] | None = None,
    sink: FieldSpool | None = None,
    ego: EgoRows | None = None,
    on_frame: Callable[[NDArray[np.uint8]], None] | None = None,
) -> tuple[NDArray[np.float32], object]:
    """Fields ``(T, n_lat, n_lon)`` float32 deg/s of a video file, and its ``MediaInfo``.

    ``source``: a :class:`simulator.media.source.Source` (its eye) or a path (mono
    equirect). Decodes the Y plane only; decoding and tile extraction run in a background thread
    while flow and splatting run in the caller's. Frames ``start <= k < end``.
    ``on_frame(gray)`` sees every decoded frame first (in the decoding thread), as an
    equirect working frame (a non-equirect source is then converted before tiling).
    """

    source = as_source(source)
    info, path = source.info, source.path
    if not info.is_video:
        raise InputError(f"{path}: sphere mode needs a video; got a still image")
    est = FieldEstimator(source.eye_size, info.fps, config, flow=flow)
    g = est._geo  # a non-equirect source: tiles straight from its frames (one resampling)
    tiling = (g.size, est.config.tile_fov_deg, _CUBE, g.level)
    frames, sample = tile_frames(source, est.tiles, tiling, start, end, on_frame is not None)
    seen = frames if on_frame is None else (on_frame(f) or f for f in frames)
    tiles = prefetch((sample(f) for f in seen), depth=4)
    last = info.n_frames if end is None else min(int(end), info.n_frames)
    try:
        mask = None if source.covered is None else cell_coverage(source.covered, config.cell_deg)
        mask = None if mask is None else (mask >= COVERED_SHARE).astype(np.float32)
        scale = flow_rate_scale(info, int(start), last - int(start))
        return _fields(
            est, tiles, last - int(start), progress, f"{path}: ", sink, ego, mask, scale
        ), info
    finally:
        tiles.close()  # stops the decoding thread now, not when garbage-collected
        frames.close()  # closes the video file


def preprocess_sphere(
    video,
    output,
    *,
    grid: WindowGrid,
    config: SphereConfig = SphereConfig(),
    flow: str | FlowFn = "dis",
    start_s: float = 0.0,
    end_s: float | None = None,
    field_dtype: str = "float16",
    progress: Progress | None = None,
    artefacts: bool = False,
):
    """``vimsim preprocess --method sphere``: the field of a video and, derived from it,
    the window matrix of ``grid``, written as one grid file (atomic).

    The grid file holds everything a paper-mode grid holds (``pof_dps``, ``pof_px`` of
    ``grid``, any preset and FOV; ``pof_px`` approximate, see :func:`window_pof`) plus
    ``field_dps`` (T, n_lat, n_lon) and ``meta["field"]`` (:func:`field_meta`).
    No checkpoints: sphere mode runs at tens of frames per second. ``artefacts``: also
    detect codec keyframes, cuts, fades and overlays in the same decoding pass
    (:mod:`simulator.preprocess.artefacts`) and store them as ``meta["artefacts"]``.

    Every check (video, range, output directory, flow backend) runs before any work; the
    backend is built once (a ``torch:MODEL.pt`` is loaded and validated once).

    Returns the output Path. InputError on bad input (nothing written).
    """

    source = as_source(video)  # checked once: the layout must fit the frame
    src, info, video = source.path, source.info, source.path
    if not info.is_video:
        raise InputError(
            f"{src}: is a still image; preprocess needs a video with at least 2 frames"
        )
    if field_dtype not in ("float16", "float32"):
        raise InputError(f"field dtype must be float16 or float32; got {field_dtype!r}")
    fps = info.fps
    start_f, end_f = frame_range(info, float(start_s), end_s, src)
    out = check_output_dir(output)
    backend, default_stride, desc = _backend(flow, config.tile_size)
    bar = Counter(progress, end_f - start_f)

    def tick(n: int) -> None:
        bar.update(n - bar.done)

    cells = CellGrid(config.cell_deg)
    # the field streams to an unnamed temporary file: memory flat in the video's length
    spool = FieldSpool(cells.shape, out.parent if str(out.parent) else ".")
    ego = EgoRows(FieldSpool(cells.shape, out.parent if str(out.parent) else "."))
    col = SignalCollector() if artefacts else None
    try:
        try:
            field_from_video(
                source, config, start=start_f, end=end_f,
                flow=backend, progress=tick, sink=spool, ego=ego, on_frame=col and col.add,
            )  # fmt: skip
        finally:
            bar.close()
        if not spool.finite:
            raise InputError(f"{src}: flow gave non-finite values")
        parts = [window_pof(c, cells.cell_deg, grid, fps) for c in spool.chunks()]
        dps = np.concatenate([d for d, _ in parts])
        px = np.concatenate([x for _, x in parts])
        cov = coverage_meta(source.covered, grid, config.cell_deg)
        if cov is not None:  # windows outside the projection: no flow measured
            dps, px = (a * coverage_masks({"coverage": cov})[0] for a in (dps, px))
        T = spool.n_rows
        if T != end_f - start_f:
            warnings.warn(f"{src}: expected {end_f - start_f} frames, decoded {T}", stacklevel=2)
        meta = sphere_meta(source, T, start_f, desc, cov, config, default_stride, field_dtype)
        if col is not None:
            sig = replace(col.result(fps, src),  # codec keyframes: confirmed by the packets' flags
                          key=keyframe_flags(source.path, start=start_f, end=end_f))  # fmt: skip
            meta["artefacts"] = artefacts_meta(detect_artefacts(sig, dps))
        meta["ego"] = EGO_META
        save_grid(
            out, dps, px, grid, meta, field_dps=(spool, field_dtype),
            field_trans_dps=(ego.trans, field_dtype), extras=ego.arrays(),
        )  # fmt: skip
    except OSError as e:
        if e.filename is None:  # the spool beside the output filled the disk: name the output
            e.filename = str(out)
        raise
    finally:
        spool.close()
        ego.trans.close()
    return out
