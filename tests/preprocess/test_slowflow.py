"""Sphere mode's flow at low and high speed: slow frame pairs read at twice DIS's resolution, the tile blend at the flow's target, the residual speed without its noise bias."""

from __future__ import annotations

import cv2
import numpy as np

from simulator.flow.dis import DISFlow
from simulator.preprocess import FieldEstimator, SphereConfig
from simulator.preprocess.ego import residual_speed
from simulator.preprocess.slowflow import SLOW_PX, SlowFine, _FineDIS
from simulator.sphere.cells import CellGrid
from simulator.sphere.geometry import lonlat_to_dir
from simulator.synth import SynthConfig, make_scene


def _tiles(omega_dps, n=3, fps=30.0):
    sc = make_scene(
        SynthConfig(scene="rotate", size=(512, 256), axis=(0, 1, 0), omega_dps=omega_dps, fps=fps)
    )
    est = FieldEstimator((512, 256), fps, SphereConfig())
    frames = [cv2.cvtColor(sc.render(k / fps), cv2.COLOR_RGB2GRAY) for k in range(n)]
    return est, [est.tiles(f) for f in frames]


def test_slow_pairs_are_read_finer_from_the_second_pair_on():
    """10 deg/s (under a pixel per frame): the first pair is plain DIS ultrafast, the
    next one DIS ultrafast down to finest scale 1 (all six tiles), with no variational
    refinement; 150 deg/s and a still camera: always plain."""
    est, t = _tiles(10.0)
    sr = SlowFine(DISFlow())
    plain, fine = DISFlow(), _FineDIS("ultrafast")
    assert np.array_equal(sr(t[0], t[1]), plain(t[0], t[1]))
    assert np.all(sr._last < SLOW_PX)
    second = sr(t[1], t[2])
    assert np.array_equal(second, fine(t[1], t[2]))
    assert not np.array_equal(second, plain(t[1], t[2]))
    assert not np.array_equal(second, DISFlow("ultrafast", 5)(t[1], t[2]))
    _, f = _tiles(150.0)
    fast = SlowFine(DISFlow())
    fast(f[0], f[1])
    assert np.all(fast._last > SLOW_PX)
    assert np.array_equal(fast(f[1], f[2]), plain(f[1], f[2]))
    # only the default flow adapts, and the grid says so
    assert est.flow_desc["fine_slow"] == {"below_px": SLOW_PX, "from_px": 0.1, "finest_scale": 1}
    # a still camera: nothing moves, nothing read finer
    still = SlowFine(DISFlow())
    still(t[0], t[0])
    assert np.all(still._last < 0.1)
    assert np.array_equal(still(t[0], t[0]), plain(t[0], t[0]))
    given = FieldEstimator((512, 256), 30.0, SphereConfig(), flow="dis:ultrafast+refine5")
    assert "fine_slow" not in given.flow_desc
    assert SlowFine(DISFlow("fast"))._fine is None


def test_tile_blend_at_the_flow_target():
    """No flow: the static weights; a flow that carries pixels out of their tile: weight 0
    for those pixels, unchanged for pixels whose target stays inside the cube face."""
    est, _ = _tiles(10.0, n=1)
    mp = est._geo.midpoint
    z = np.zeros((6, *mp.u0.shape), np.float32)
    assert np.allclose(mp._frame_weight(z, z), mp.weight)
    fx = np.full_like(z, 40.0)  # 40 px right: the right border band leaves the tile
    w = mp._frame_weight(fx, z).reshape(z.shape)
    base = mp.weight.reshape(z.shape)
    leaves = mp.u0 + 40.0 * mp.cx > mp.tan_half
    stays = (np.abs(mp.u0 + 40.0 * mp.cx) <= 1.0) & (np.abs(mp.v0) <= 1.0)
    assert np.all(w[:, leaves] == 0) and np.any(base[:, leaves] > 0)
    assert np.allclose(w[:, stays], base[:, stays])


def _dirs(cell=6.0):
    cells = CellGrid(cell)
    lon, lat = cells.centres_lonlat()
    return lonlat_to_dir(*np.meshgrid(lon, lat)).reshape(-1, 3)


def _tangent_noise(rng, d, sigma):
    n = rng.normal(0, sigma, d.shape)
    return n - (n * d).sum(axis=1, keepdims=True) * d


def test_residual_speed_discounts_the_noise_not_the_parallax():
    """No translation fitted: a pure rotation's residual (noise of 4 % of the speed per
    component, whose length averages 5 % of the speed) reads < 0.4 of that (0.46 sigma:
    what is left of Gaussian noise once its power is removed), while content moving on
    its own (a tenth of the cells) keeps its speed; a translation fitted: the residual's
    whole length."""
    rng = np.random.default_rng(3)
    d = _dirs()
    speed = np.full(len(d), 1.0)
    ok = np.ones(len(d), bool)
    noise = _tangent_noise(rng, d, 0.04)
    biased = np.linalg.norm(noise, axis=1).mean()
    assert biased > 0.045
    none = np.zeros(3)
    assert residual_speed(noise, d, none, speed, ok).mean() < 0.4 * biased
    movers = rng.random(len(d)) < 0.1
    vec = noise + np.where(movers[:, None], _tangent_noise(rng, d, 0.5), 0.0)
    st = residual_speed(vec, d, none, speed, ok)
    big = movers & (np.linalg.norm(vec, axis=1) > 0.3)
    assert big.sum() > 10
    assert np.all(st[big] > 0.95 * np.linalg.norm(vec[big], axis=1))
    t = np.array([0.2, 0.1, 1.0]) / np.linalg.norm([0.2, 0.1, 1.0])
    par = 0.2 * np.cross(d, t) + noise
    assert np.allclose(residual_speed(par, d, t, speed, ok), np.linalg.norm(par, axis=1))
