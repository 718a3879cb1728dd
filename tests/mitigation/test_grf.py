"""GRF grain layout, count, cutout and bucket lookup (pure numpy; the rendered geometry is
checked in test_render.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial import cKDTree

from simulator.core.errors import InputError
from simulator.mitigation.grf import GrainField, GrfConfig, cutout_alpha, grain_count


def _random_dirs(n: int, seed: int = 1) -> np.ndarray:
    d = np.random.default_rng(seed).normal(size=(n, 3))
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def test_grain_count_matches_overlap_formula():
    cfg = GrfConfig()
    n = grain_count(cfg)
    a = 2 * math.pi * (1 - math.cos(math.radians(0.75)))
    assert cfg.grain_solid_angle_sr == pytest.approx(a)
    # 1 - (1 - a/4pi)^n = 0.5 within rounding of n
    assert 1 - (1 - a / (4 * math.pi)) ** n == pytest.approx(0.5, abs=1e-4)
    # ~ 1 - exp(-n a / 4 pi); far more grains than the no-overlap count 0.5 * 4pi / a
    assert n > 0.5 * 4 * math.pi / a * 1.3


@pytest.mark.parametrize("density", [0.2, 0.5, 0.8])
def test_blocked_fraction_on_the_sphere(density):
    cfg = GrfConfig(density=density, seed=3)
    f = GrainField.from_config(cfg)
    d = _random_dirs(40000)
    chord = 2 * math.sin(f.radius_rad / 2)
    hit = np.array([len(x) > 0 for x in cKDTree(f.centers).query_ball_point(d, chord)])
    # binomial sd of 40000 samples ~ 0.0025, layout fluctuation over the sphere smaller
    assert hit.mean() == pytest.approx(density, abs=0.01)


def test_seeded_and_world_unit_vectors():
    a = GrainField.from_config(GrfConfig(seed=7))
    b = GrainField.from_config(GrfConfig(seed=7))
    c = GrainField.from_config(GrfConfig(seed=8))
    assert np.array_equal(a.centers, b.centers)
    assert not np.array_equal(a.centers, c.centers)
    assert np.allclose(np.linalg.norm(a.centers, axis=1), 1.0)
    assert not a.centers.flags.writeable
    # uniform on the sphere: mean direction ~ 0, |y| uniform in [0, 1]
    assert np.abs(a.centers.mean(axis=0)).max() < 0.02
    assert abs(np.abs(a.centers[:, 1]).mean() - 0.5) < 0.01


def test_cutout_ramp():
    cfg = GrfConfig()
    e = np.array([0, 17.9, 18, 29, 40, 60])
    assert np.allclose(cutout_alpha(e, cfg), [0, 0, 0, 0.5, 1, 1])
    assert cutout_alpha(23.5, GrfConfig(inner_deg=20, outer_deg=27)) == pytest.approx(0.5)


@pytest.mark.parametrize(
    "kw,match",
    [
        ({"density": 1.0}, "density"),
        ({"density": 0.0}, "density"),
        ({"grain_deg": -1}, "grain size"),
        ({"inner_deg": 40, "outer_deg": 18}, "inner < outer"),
        ({"seed": -1}, "seed"),
        ({"distance_m": 0.0}, "distance"),
    ],
)
def test_config_bad_input(kw, match):
    with pytest.raises(InputError, match=match):
        GrfConfig(**kw)


@pytest.mark.parametrize("margin", [0.0, 0.004])
def test_buckets_list_every_grain_near_a_ray(margin):
    """The cell of any direction lists every grain whose grown disc reaches it (seam,
    poles included): the shader's lookup never misses a grain."""
    f = GrainField.from_config(GrfConfig(seed=2))
    b = f.buckets(margin)
    d = np.concatenate([_random_dirs(3000), [[0, 1, 0], [0, -1, 0], [0, 0, -1], [-1e-4, 0.3, -1]]])
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    lat = np.arcsin(np.clip(d[:, 1], -1, 1))
    lon = np.arctan2(d[:, 0], d[:, 2])
    band = np.clip(np.floor((lat + math.pi / 2) / b.cell_rad).astype(int), 0, b.n_bands - 1)
    first, n_lon = b.bands[band, 0], b.bands[band, 1]
    cell = first + np.minimum(
        np.floor((lon + math.pi) / (2 * math.pi) * n_lon).astype(int), n_lon - 1
    )
    reach = 2 * math.sin((f.radius_rad + margin) / 2)
    near = cKDTree(f.centers).query_ball_point(d, reach * 0.999)
    missing = 0
    for i, grains in enumerate(near):
        listed = b.entries[b.cell_start[cell[i]] : b.cell_start[cell[i] + 1], :3]
        for g in grains:
            if not np.any(np.all(np.abs(listed - f.centers[g]) < 1e-6, axis=1)):
                missing += 1
    assert missing == 0
    # compact: about 2 grains per cell on average at the default cell size
    assert b.entries.shape[0] / (b.cell_start.size - 1) < 3.0
