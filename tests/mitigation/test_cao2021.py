"""The authors' runtime rule (nearest window, list indexing, fixed px/frame scale) against a
brute-force reference written from the issue text, and their grain layout."""

from __future__ import annotations

import math

import numpy as np
import pytest

from simulator.core.errors import InputError
from simulator.mitigation.cao2021 import (
    CAO_HIGH_PX,
    CAO_LOW_PX,
    FixedPxRule,
    cao_grain_field,
    fibonacci_sphere,
    list_row,
    nearest_flow,
    nearest_window,
)
from simulator.sphere.windows import grid_preset

GRID = grid_preset("cao2021", size=(16, 16))


def _wrap(a: float) -> float:
    a = math.fmod(a, 360.0)
    if a <= -180.0:
        a += 360.0
    if a > 180.0:
        a -= 360.0
    return a


def ref_centre(yaw: float, pitch: float) -> tuple[float, float]:
    """Issue 43, word for word: candidates ceil/floor(x/15)*15; yaw candidates above 165
    moved by -360 and below -165 by +360; the smaller plain absolute difference wins (a tie:
    the ceil candidate, vimsim's choice)."""
    yaw, pitch = _wrap(yaw), _wrap(pitch)
    ys = []
    for c in (math.ceil(yaw / 15) * 15, math.floor(yaw / 15) * 15):
        if c > 165:
            c -= 360
        elif c < -165:
            c += 360
        ys.append(c)
    y = ys[0] if abs(yaw - ys[0]) <= abs(yaw - ys[1]) else ys[1]
    pc, pf = math.ceil(pitch / 15) * 15, math.floor(pitch / 15) * 15
    p = pc if abs(pitch - pc) <= abs(pitch - pf) else pf
    return float(y), float(p)


def ref_flow(csv_texts: dict, k: int, yaw: float, pitch: float) -> float:
    """Their reader: the number after the comma of every non-empty line (header included);
    flow at frame k = list[k-1], 0 for k < 1 and beyond the list."""
    y, p = ref_centre(yaw, pitch)
    lst = [float(ln.split(",")[1]) for ln in csv_texts[(y, p)].splitlines() if ln.strip()]
    return lst[k - 1] if 1 <= k <= len(lst) else 0.0


def _csvs(pof):
    texts = {}
    for i, p in enumerate(GRID.pitch_deg):
        for j, y in enumerate(GRID.yaw_deg):
            rows = "".join(f"{t},{float(pof[t, i, j])!r}\n" for t in range(pof.shape[0]))
            texts[(float(y), float(p))] = ",0\n" + rows
    return texts


def test_cao2021_grid_preset():
    g = grid_preset("cao2021")
    assert g.shape == (13, 24) and g.n_windows == 312
    assert g.size == (1600, 1440) and g.hfov_deg == 107.0
    assert g.vfov_deg == pytest.approx(96.3)
    assert g.pitch_deg[0] == -90 and g.pitch_deg[-1] == 90
    assert g.yaw_deg[0] == -180 and g.yaw_deg[-1] == 165


def test_nearest_window_edges():
    cases = {
        (170.0, 0.0): (165.0, 0.0),  # between 165 and 180: 165, never -180
        (179.999, 0.0): (165.0, 0.0),
        (180.0, 0.0): (-180.0, 0.0),  # both candidates become -180
        (-180.0, 0.0): (-180.0, 0.0),  # wraps to +180
        (-170.0, 0.0): (-165.0, 0.0),
        (-179.9, 0.0): (-165.0, 0.0),
        (7.5, 7.5): (15.0, 15.0),  # ties: the ceil candidate
        (0.0, 89.0): (0.0, 90.0),
        (0.0, -90.0): (0.0, -90.0),
        (350.0, 0.0): (-15.0, 0.0),
    }
    for (yaw, pitch), want in cases.items():
        assert ref_centre(yaw, pitch) == want, (yaw, pitch)
        p, y = nearest_window(yaw, pitch, GRID.yaw_deg, GRID.pitch_deg)
        assert (GRID.yaw_deg[y], GRID.pitch_deg[p]) == want, (yaw, pitch)


def test_nearest_flow_matches_brute_force():
    rng = np.random.default_rng(43)
    T = 9
    pof = rng.uniform(0, 60, (T, *GRID.shape)).astype(np.float32)
    texts = _csvs(pof)
    n = 3000
    yaw = np.concatenate([rng.uniform(-540, 540, n), [165, 170, 180, -180, -165, -172.5, 172.5]])
    pitch = np.concatenate([rng.uniform(-90, 90, n), [90, -90, 89.9, -89.9, 0, 7.5, -7.5]])
    k = np.concatenate([rng.integers(-2, T + 4, n), [0, 1, 2, T + 1, T + 2, 3, 4]])
    got = nearest_flow(pof, k, yaw, pitch, GRID.yaw_deg, GRID.pitch_deg)
    want = np.array([ref_flow(texts, int(a), float(b), float(c)) for a, b, c in zip(k, yaw, pitch)])
    np.testing.assert_array_equal(got, want)
    assert got[k == 1].max() == 0 and got[k == 0].max() == 0  # frame 1 reads the header
    assert np.all(got[k > T + 1] == 0)  # past the list
    i = np.nonzero(k == 2)[0][0]
    p, y = nearest_window(yaw[i], pitch[i], GRID.yaw_deg, GRID.pitch_deg)
    assert got[i] == pof[0, p, y]  # frame 2 shows row 0 (the 88 deg frame in their data)


def test_list_row():
    np.testing.assert_array_equal(list_row([-1, 0, 1, 2, 3, 11, 12], 10), [-1, -1, -1, 0, 1, 9, -1])


def test_fixed_px_rule():
    r = FixedPxRule()
    assert (r.low_px, r.high_px) == (CAO_LOW_PX, CAO_HIGH_PX) == (0.18, 53.73)
    np.testing.assert_allclose(r([0.0, 0.18, (0.18 + 53.73) / 2, 53.73, 100]), [0, 0, 0.5, 1, 1])
    with pytest.raises(InputError):
        FixedPxRule(5.0, 5.0)


def test_nearest_window_refuses_off_step_grid():
    g = grid_preset("default", size=(16, 16))  # pitch multiples of 7.5: fine with step 7.5
    p, _y = nearest_window(0.0, 80.0, g.yaw_deg, g.pitch_deg, pitch_step_deg=7.5)
    assert g.pitch_deg[p] == 37.5  # beyond the rows: clamped to the last
    with pytest.raises(InputError):
        nearest_window(0.0, 0.0, g.yaw_deg, g.pitch_deg, pitch_step_deg=10.0)


def test_grain_layout_count_and_coverage():
    f = cao_grain_field()
    n = round(180 * 360 / 0.5**2)
    assert n == 259200 and f.centers.shape == (n // 2, 3)
    assert f.radius_rad == pytest.approx(math.radians(0.25))
    assert f.config.inner_deg == 0 and f.config.outer_deg <= 1e-6  # no cutout
    np.testing.assert_allclose(np.linalg.norm(f.centers, axis=1), 1.0, atol=1e-12)
    # A kept half of the Fibonacci points: rows of the full layout.
    full = fibonacci_sphere(n)
    assert np.isin(f.centers[:, 1], full[:, 1]).all()
    assert cao_grain_field() is f and cao_grain_field(seed=1) is not f
    # Coverage: blocked fraction of random directions; even over the sphere (each band).
    from scipy.spatial import cKDTree

    rng = np.random.default_rng(0)
    d = rng.normal(size=(40000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    chord = 2 * math.sin(f.radius_rad / 2)
    hit = cKDTree(f.centers).query(d, distance_upper_bound=chord)[0] < chord
    frac = hit.mean()
    # Half of 259200 grains of 5.98e-5 sr, placed apart: 1 - exp(-n a / 4 pi) .. n a / 4 pi
    a = 2 * math.pi * (1 - math.cos(f.radius_rad)) * (n // 2) / (4 * math.pi)
    assert 1 - math.exp(-a) - 0.02 < frac < min(a, 1.0) + 0.02, (frac, a)
    for lo in (-1.0, -0.5, 0.0, 0.5):
        band = (d[:, 1] >= lo) & (d[:, 1] < lo + 0.5)
        assert abs(hit[band].mean() - frac) < 0.03
