"""Sphere-mode tiles sampled straight from a frame of a non-equirect projection (one resampling), and the area downscaling they use.

Sphere mode samples its cube-face tiles from a frame lowered to the tiles' density
(:class:`simulator.preprocess.sphere._TileGeometry`). :class:`ProjectionTiles` samples
the tiles of a cubemap, fisheye or VR180 frame with one ``cv2.remap`` (tile pixel ->
direction -> projection pixel, composed once), instead of converting every frame to the
equirect working frame and resampling that; :func:`downscale` lowers the stored frame
(or its face atlas) by area averaging in exact halvings (OpenCV's fast 2x path).
"""

from __future__ import annotations

import functools
import math

import cv2
import numpy as np
from numpy.typing import NDArray

from simulator.sphere.geometry import head_rotation, perspective_rays
from simulator.sphere.projections import EquirectConverter

__all__ = ["ProjectionTiles", "downscale", "tile_dirs", "tile_frames"]


def downscale(frame: NDArray[np.uint8], size: tuple[int, int]) -> NDArray[np.uint8]:
    """``frame`` at ``size = (w, h)`` by area averaging (the frame itself when it already
    is that size); pixel centres map as ``(x + 0.5) * w / W - 0.5``. Halvings first:
    OpenCV's exact-2x area path is ~6x faster than one 8x area resize (the same means).

    Lowered by 8 or more (8K and larger sources), the first 4x step averages only the
    middle 2x2 pixels of each 4x4 block (a bilinear resize: rows ``4y+1``, ``4y+2``, so
    half the frame is read): each output pixel is then the mean of 16 of its 64 pixels,
    evenly spread, and its centre maps as above. Reading the frame once is most of this
    function's time at 8K (bound by memory bandwidth, which the decoder shares): 4.2 ->
    2.6 ms of CPU per 7680x3840 frame; at 0.5 deg per tile pixel the flow sees no
    difference (``bench/source_8k.py``, docs/sources.md)."""
    w, h = int(size[0]), int(size[1])
    f = frame
    H, W = f.shape[:2]
    if W >= 8 * w and H >= 8 * h and W % 4 == 0 and H % 4 == 0:
        f = cv2.resize(f, (W // 4, H // 4), interpolation=cv2.INTER_LINEAR)
    while f.shape[1] >= 2 * w and f.shape[0] >= 2 * h:
        f = cv2.resize(f, (f.shape[1] // 2, f.shape[0] // 2), interpolation=cv2.INTER_AREA)
    if f.shape[1] != w or f.shape[0] != h:
        f = cv2.resize(f, (w, h), interpolation=cv2.INTER_AREA)
    return np.ascontiguousarray(f)


def tile_dirs(size: int, fov_deg: float, faces) -> NDArray[np.float64]:
    """World directions ``(n * size, size, 3)`` of the pixels of square perspective tiles
    of ``fov_deg`` looking at ``faces = ((yaw_deg, pitch_deg), ...)``, stacked."""
    dirs, _ = perspective_rays((size, size), fov_deg, fov_deg)
    R = head_rotation([a[0] for a in faces], [a[1] for a in faces], 0.0).as_matrix()
    world = np.einsum("nij,hwj->nhwi", R, dirs.astype(np.float64), optimize=True)
    return world.reshape(len(faces) * size, size, 3)


class ProjectionTiles:
    """Tiles ``(n, s, s)`` of gray frames stored in a non-equirect projection, sampled with
    one bilinear remap from the frame (its face atlas for cubemaps) lowered ``level``
    octaves (area averaging), the same density the equirect path's pyramid gives.
    Uncovered directions are black, as in the converted equirect frame."""

    def __init__(self, conv: EquirectConverter, size: int, fov_deg: float, faces, level: int):
        k = 2**level
        # the atlas pad must hold the bilinear reach after downscaling: 2 px at its scale
        pad = 2 * k + 2 if level else 0
        if pad > conv.PAD:
            conv = EquirectConverter(conv.name, conv.size, conv.lens_fov_deg, pad=pad)
        self._conv = conv
        mx, my, ok = self._conv.maps(tile_dirs(size, fov_deg, faces))
        probe = np.zeros((conv.size[1], conv.size[0]), np.uint8)
        H, W = self._conv.atlas(probe).shape
        self.small_size = (max(1, math.ceil(W / k)), max(1, math.ceil(H / k)))
        sx, sy = self.small_size[0] / W, self.small_size[1] / H
        mx = np.where(ok, (mx + 0.5) * sx - 0.5, -16.0).astype(np.float32)
        my = ((my + 0.5) * sy - 0.5).astype(np.float32)
        self.m1, self.m2 = cv2.convertMaps(mx, my, cv2.CV_16SC2)
        self.n_tiles, self.size = len(faces), int(size)

    def __call__(self, frame: NDArray[np.uint8]) -> NDArray[np.uint8]:
        src = downscale(self._conv.atlas(frame), self.small_size)
        out = cv2.remap(src, self.m1, self.m2, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
        return out.reshape(self.n_tiles, self.size, self.size)


@functools.lru_cache(maxsize=4)
def _projection_tiles(conv, size, fov_deg, faces, level) -> ProjectionTiles:
    return ProjectionTiles(conv, size, fov_deg, faces, level)


def tile_frames(
    source, equirect_tiles, tiling, start: int, end: int | None, equirect: bool = False
):
    """(gray frames, their tile sampler) of a :class:`simulator.media.source.Source`: an
    equirect source's frames and ``equirect_tiles``; another projection's frames as stored
    and a :class:`ProjectionTiles` of ``tiling = (size, fov_deg, faces, level)``, unless
    ``equirect`` (a caller that must see the equirect working frames: converted ones)."""
    conv = source.converter
    if conv is None or equirect or (conv.name == "eac" and tiling[3] > 0):
        # eac has no face atlas: lowering its frame would mix faces; convert it first
        return source.frames(fmt="gray", start=start, end=end), equirect_tiles
    sample = _projection_tiles(conv, *tiling)
    return source.frames(fmt="gray", start=start, end=end, convert=False), sample
