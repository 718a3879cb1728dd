"""preprocess.tiles: sphere-mode tiles sampled straight from each projection (ffmpeg v360's frames) equal the equirect's tiles."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from media_helpers import smooth_equirect

from simulator.preprocess import SphereConfig
from simulator.preprocess.sphere import _CUBE, FieldEstimator
from simulator.preprocess.tiles import ProjectionTiles, downscale, tile_dirs, tile_frames
from simulator.sphere.projections import converter
from simulator.testing.reference import v360_convert

CASES = [
    ("c3x2", (768, 512), ""),
    ("c6x1", (1536, 256), ""),
    ("eac", (768, 512), ""),
    ("dfisheye", (1024, 512), ":h_fov=190:v_fov=190"),
    ("hequirect", (512, 512), ""),
]


class _Src:
    """A source's converter and its ``frames`` arguments (what tile_frames asks of it)."""

    def __init__(self, conv):
        self.converter = conv

    def frames(self, convert=True, **kw):
        return {"convert": convert, **kw}


def _psnr(a, b, m) -> float:
    d = (a.astype(float) - b.astype(float))[m]
    return float(10 * np.log10(255**2 / max((d**2).mean(), 1e-9)))


@pytest.mark.parametrize("tile_size", [32, 256])
@pytest.mark.parametrize("name,size,opts", CASES)
def test_projection_tiles_match_the_equirect_tiles(name, size, opts, tile_size):
    lens = 190.0 if name == "dfisheye" else None
    conv = converter(name, size, lens)
    E = smooth_equirect(*conv.equirect_size)
    src = v360_convert(E, name, size, opts)
    cfg = SphereConfig(tile_size=tile_size)
    est = FieldEstimator(conv.equirect_size, 30.0, cfg)
    g = est._geo
    assert (g.level >= 2) if tile_size == 32 else g.level == 0  # downscaled and not
    if name == "eac" and g.level:  # no face atlas: the equirect path (tested elsewhere)
        frames, sample = tile_frames(_Src(conv), est.tiles, (g.size, 100.0, _CUBE, g.level), 0, 1)
        assert sample == est.tiles and frames["convert"]
        return
    frames, sample = tile_frames(_Src(conv), est.tiles, (g.size, 100.0, _CUBE, g.level), 0, 1, True)
    assert sample == est.tiles and frames["convert"]  # a caller that must see equirect frames
    pt = ProjectionTiles(conv, g.size, cfg.tile_fov_deg, _CUBE, g.level)
    gray = np.ascontiguousarray(src[..., 0])
    tiles = pt(gray)
    ref = est.tiles(np.ascontiguousarray(E[..., 0]))  # the analytic equirect's tiles
    assert tiles.shape == ref.shape
    ok = conv.maps(tile_dirs(g.size, cfg.tile_fov_deg, _CUBE))[2].astype(np.uint8)
    ok = cv2.erode(ok, np.ones((5, 5), np.uint8)).reshape(ref.shape).astype(bool)
    assert ok.mean() > (0.3 if name == "hequirect" else 0.95)
    assert _psnr(tiles, ref, ok) > 36, name
    assert (
        tiles[~conv.maps(tile_dirs(g.size, cfg.tile_fov_deg, _CUBE))[2].reshape(ref.shape)] == 0
    ).all()
    # and the same as the two-resampling path (converted to equirect, then tiled)
    two = est.tiles(conv(gray))
    assert _psnr(tiles, two, ok) > 36, name
    # a wrong layout would not pass: the projection's halves swapped
    sw = np.ascontiguousarray(np.roll(gray, gray.shape[1] // 2, axis=1))
    assert _psnr(pt(sw), ref, ok) < 30


def test_downscale_is_the_frame_at_its_size_and_area_mean():
    f = np.arange(64 * 32, dtype=np.uint8).reshape(32, 64)
    assert downscale(f, (64, 32)) is not None and np.array_equal(downscale(f[:, :64], (64, 32)), f)
    s = downscale(np.kron(np.eye(2, dtype=np.uint8) * 200, np.ones((4, 4), np.uint8)), (2, 2))
    assert s.tolist() == [[200, 0], [0, 200]]


def test_downscale_by_8_or_more_means_16_evenly_spread_pixels_and_keeps_centres():
    rng = np.random.default_rng(3)
    f = rng.integers(0, 256, (64, 128), dtype=np.uint8)
    s = downscale(f, (16, 8)).astype(np.float64)
    # each output pixel: mean of the middle 2x2 of each 4x4 quarter of its 8x8 block
    mid = f.astype(np.float64).reshape(16, 4, 32, 4)[:, 1:3, :, 1:3].mean(axis=(1, 3))
    want = mid.reshape(8, 2, 16, 2).mean(axis=(1, 3))
    assert np.abs(s - want).max() <= 1.0  # uint8 rounding of the two steps
    assert s.std() < 0.3 * f.std()  # averaged (16 samples), not point-sampled
    # a ramp: the output's centres map as (x + 0.5) * w / W - 0.5
    ramp = np.tile(np.arange(128, dtype=np.uint8), (64, 1))
    r = downscale(ramp, (16, 8)).astype(np.float64)
    assert np.abs(r - ((np.arange(16) + 0.5) * 8 - 0.5)[None, :]).max() <= 0.5
