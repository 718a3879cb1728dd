"""Textures of the synthetic scenes: the bundled panorama, a procedural one, and a mipmapped sampler."""

from __future__ import annotations

import os
from importlib import resources
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from simulator.core.errors import InputError
from simulator.sphere.geometry import equirect_pixel_lonlat, lonlat_to_dir

__all__ = ["load_texture", "procedural_panorama"]

_BUNDLED = "panorama.jpg"


def _bundled_texture_path() -> Path:
    return Path(str(resources.files("simulator") / "data" / _BUNDLED))


def load_texture(path: str | os.PathLike | None = None) -> tuple[NDArray[np.uint8], str]:
    """An RGB texture ``(H, W, 3)`` uint8 and a short name for it.

    ``None`` loads the panorama bundled in ``simulator/data/`` (procedural, see
    ``simulator/data/CREDITS.md``). Any image Pillow reads is accepted (for the rotate
    scene it should be a 2:1 equirect panorama; for the box scenes it is tiled).
    """
    from PIL import Image, UnidentifiedImageError

    p = _bundled_texture_path() if path is None else Path(path)
    if not p.is_file():
        raise InputError(f"{p}: texture file not found")
    try:
        with Image.open(p) as im:
            im.load()
            rgb = np.asarray(im.convert("RGB"))
    except (UnidentifiedImageError, OSError, ValueError, Image.DecompressionBombError) as e:
        raise InputError(
            f"{p}: texture is not a readable image ({type(e).__name__}: {e})"
        ) from None
    if rgb.shape[0] < 8 or rgb.shape[1] < 8:
        raise InputError(f"{p}: texture is {rgb.shape[1]}x{rgb.shape[0]}; need at least 8x8 pixels")
    return np.ascontiguousarray(rgb), ("bundled:" + _BUNDLED if path is None else str(p))


def procedural_panorama(size: tuple[int, int] = (1024, 512), seed: int = 0) -> NDArray[np.uint8]:
    """A richly textured equirect panorama ``(H, W, 3)`` uint8 made of 3-D noise on the sphere.

    Multi-octave smooth (cubic) noise sampled at the unit direction of each pixel, so it
    is seamless at the +-180 deg seam and at the poles. Colour from two low-frequency
    channels, luminance detail from two more, and contour lines for sharp edges (optical
    flow needs texture at every scale). This made ``simulator/data/panorama.jpg``
    (``size=(1024, 512), seed=0``).
    """
    from scipy import ndimage

    W, H = int(size[0]), int(size[1])
    rng = np.random.default_rng(seed)
    lon, lat = equirect_pixel_lonlat(W, H)
    LO, LA = np.meshgrid(lon, lat)
    d = lonlat_to_dir(LO, LA).reshape(-1, 3)
    chans = []
    for beta, octaves in (
        (0.9, (2, 4, 8, 16)),
        (0.9, (2, 4, 8, 16, 32)),
        (0.7, (4, 8, 16, 32, 64, 128)),
        (0.4, (16, 32, 64, 128)),
    ):
        acc = np.zeros(H * W)
        for f in octaves:
            n = 2 * f + 4
            lattice = rng.standard_normal((n, n, n))
            coords = (d * f + n / 2).T + rng.uniform(0, 1, (3, 1))
            acc += ndimage.map_coordinates(lattice, coords, order=3, mode="grid-wrap") * f ** (
                -beta
            )
        acc = (acc - acc.mean()) / acc.std()
        chans.append(acc.reshape(H, W))
    z0, z1, z2, z3 = chans
    hue = (np.arctan2(z0, z1) / (2 * np.pi) + 0.5) * 179
    sat = np.clip(0.5 + 0.25 * np.tanh(z0), 0, 1) * 255
    lum = 0.5 + 0.25 * np.tanh(1.2 * z2) + 0.15 * np.tanh(1.5 * z3)
    lines = 0.55 + 0.45 * (np.abs(np.sin(3.0 * z1 + 2.0 * z2)) > 0.25)
    val = np.clip(lum * lines, 0, 1) * 255
    hsv = np.stack([hue, sat, val], -1).astype(np.uint8)
    return cv2.cvtColor(hsv, cv2.COLOR_HSV2RGB)


class _MipTexture:
    """A periodic texture with a mip pyramid packed into one atlas, for trilinear lookups.

    The image is mirror-tiled 2 x 2 (so it repeats without seams), halved with box
    filtering down to 8 pixels, followed by one constant level of the mean colour (a
    footprint of more than one coarsest texel fades to the average: no aliasing at any
    distance), and each level is padded by wrapping so that bilinear taps at a tile edge
    read the other side. Two ``cv2.remap`` calls per frame.
    """

    _P = 2  # wrap padding, pixels

    def __init__(self, img: NDArray[np.uint8]):
        tile = np.concatenate([img, img[:, ::-1]], axis=1)
        tile = np.concatenate([tile, tile[::-1]], axis=0)
        h, w = tile.shape[:2]
        # Even sizes all the way down: crop to a multiple of 2^k.
        levels = [tile.astype(np.float32)]
        while min(levels[-1].shape[:2]) >= 16 and all(s % 2 == 0 for s in levels[-1].shape[:2]):
            prev = levels[-1]
            levels.append(
                cv2.resize(
                    prev, (prev.shape[1] // 2, prev.shape[0] // 2), interpolation=cv2.INTER_AREA
                )
            )
        # Past the coarsest level, fade to the mean colour: one more level, constant (the
        # limit of box filtering a periodic texture), so that walls whose pixel footprint
        # covers many texture periods show their average instead of moire at any distance.
        mean = levels[-1].reshape(-1, 3).mean(axis=0)
        levels.append(np.broadcast_to(mean, levels[-1].shape).astype(np.float32))
        p = self._P
        padded = [np.pad(lv, ((p, p), (p, p), (0, 0)), mode="wrap") for lv in levels]
        width = padded[0].shape[1]
        offs, rows = [], 0
        for pl in padded:
            offs.append(rows)
            rows += pl.shape[0]
        atlas = np.zeros((rows, width, 3), np.float32)
        for o, pl in zip(offs, padded):
            atlas[o : o + pl.shape[0], : pl.shape[1]] = pl
        self.atlas = atlas
        self.size = (w, h)  # texels of level 0 per period
        self.n_levels = len(levels)
        self._w = np.array([lv.shape[1] for lv in levels], np.float32)
        self._h = np.array([lv.shape[0] for lv in levels], np.float32)
        self._off = np.array(offs, np.float32)

    def _coords(self, u: NDArray, v: NDArray, level: NDArray) -> tuple[NDArray, NDArray]:
        s = np.exp2(-level.astype(np.float32))
        w, h = self._w[level], self._h[level]
        x = np.mod(u * s - 0.5, w) + self._P
        y = np.mod(v * s - 0.5, h) + (self._P + self._off[level])
        return x, y

    def sample(self, u: NDArray, v: NDArray, lod: NDArray) -> NDArray[np.float32]:
        """Trilinear lookup at level-0 texel coordinates ``u, v`` (any float) and level of
        detail ``lod`` (log2 of the footprint in texels); returns ``(..., 3)`` float32."""
        # Reduce to one period in float64 once (every level's period is the same in
        # level-0 texels), then work in float32.
        u = np.mod(u, self.size[0]).astype(np.float32)
        v = np.mod(v, self.size[1]).astype(np.float32)
        lod = np.clip(lod, 0.0, self.n_levels - 1.0)
        l0 = np.floor(lod).astype(np.intp)
        l1 = np.minimum(l0 + 1, self.n_levels - 1)
        f = (lod - l0).astype(np.float32)[..., None]
        x0, y0 = self._coords(u, v, l0)
        x1, y1 = self._coords(u, v, l1)
        a = cv2.remap(self.atlas, x0, y0, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        b = cv2.remap(self.atlas, x1, y1, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        return a * (1.0 - f) + b * f
