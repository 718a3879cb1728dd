"""Discomfort features (simulator/discomfort/features.py) against the analytic truth of synthetic rotations."""

from __future__ import annotations

import math

import numpy as np
import pytest
from discomfort_helpers import rotate_clip

from simulator.core.errors import InputError
from simulator.discomfort.features import (
    FEATURES,
    FEATURES_VERSION,
    feature_names,
    features_from_grid,
)
from simulator.media.gridfile import load_grid
from simulator.preprocess import preprocess_sphere
from simulator.sphere.windows import grid_preset
from simulator.traces.path import HeadPath


def _grid(tmp_path, name, yaw, pitch, roll, frames=6):
    v = rotate_clip(tmp_path / f"{name}.mp4", yaw, pitch, roll, frames=frames)
    return load_grid(preprocess_sphere(v, tmp_path / f"{name}.npz", grid=grid_preset("default")))


def test_table_is_named_versioned_and_documented():
    names = feature_names()
    assert len(names) == len(set(names)) and FEATURES_VERSION
    for f in FEATURES:
        assert f.unit in ("deg/s", "deg/s^2", "s", "1") and f.description
        assert f.name.endswith("_dps") == (f.unit == "deg/s")


@pytest.mark.parametrize("axis", ["yaw", "pitch", "roll"])
def test_rates_and_epof_of_a_rotation_about_one_axis(tmp_path, axis):
    """A camera turning at 40 deg/s about one axis: that axis's mean |rate| is 40 within 3 %,
    the others under 1.5 deg/s; the sphere-mean EPOF of a rotation is omega * pi/4 (the mean
    of sin(angle to the axis) over the sphere) within 5 %, nearly all of it rotational."""
    omega = 40.0
    rates = {"yaw": 0.0, "pitch": 0.0, "roll": 0.0, axis: omega}
    g = _grid(tmp_path, axis, rates["yaw"], rates["pitch"], rates["roll"])
    f = features_from_grid(g)
    assert list(f) == feature_names()
    for a in ("yaw", "pitch", "roll"):
        got = f[f"{a}_rate_mean_dps"]
        if a == axis:
            assert abs(got - omega) < 0.03 * omega, (a, got)
            assert abs(f[f"{a}_rate_block_max_dps"] - omega) < 0.03 * omega
        else:
            assert got < 1.5, (a, got)
    assert abs(f["rotation_mean_dps"] - omega) < 0.03 * omega
    assert abs(f["epof_mean_dps"] - omega * math.pi / 4) < 0.05 * omega * math.pi / 4
    assert f["epof_trans_mean_dps"] < 0.1 * f["epof_mean_dps"]
    assert abs(f["epof_rot_mean_dps"] + f["epof_trans_mean_dps"] - f["epof_mean_dps"]) < 1e-6
    assert f["duration_s"] == pytest.approx(6 / 30)
    assert f["ego_confidence_mean"] > 0.6
    assert f["opacity_mean"] == pytest.approx(
        np.clip((f["epof_mean_dps"] - 5) / 25, 0, 1), abs=0.05
    )


def _viewport_truth(omega, axis_in_view):
    """Mean speed (deg/s) of a rotation at ``omega`` about ``axis_in_view`` (unit, view
    frame: +z forward) over a 107 x 107 deg perspective view, by solid angle."""
    u = np.tan(np.radians(107 / 2)) * np.linspace(-1, 1, 801)
    x, y = np.meshgrid(u, u)
    d = np.stack([x, y, np.ones_like(x)], -1)
    n = np.linalg.norm(d, axis=-1)
    w = 1 / n**3  # solid angle of a pixel of the image plane z = 1
    sin = np.linalg.norm(np.cross(d / n[..., None], axis_in_view), axis=-1)
    return omega * float((sin * w).sum() / w.sum())


def test_viewing_features_use_the_head_path(tmp_path):
    """A yawing camera watched straight up (the axis at the view centre) and straight ahead:
    each viewing's EPOF is the analytic mean speed over its viewport within 5 %; the camera's
    rates are the camera's whatever the head does."""
    g = _grid(tmp_path, "yaw", 40.0, 0.0, 0.0)
    t = np.array([0.0, 1.0])
    up = HeadPath.from_angles_deg(t, np.zeros(2), np.full(2, 90.0), np.zeros(2))
    ahead = HeadPath.from_angles_deg(t, np.zeros(2), np.zeros(2), np.zeros(2))
    f_up, f_ahead = features_from_grid(g, up), features_from_grid(g, ahead)
    want_up = _viewport_truth(40.0, np.array([0.0, 0.0, 1.0]))
    want_ahead = _viewport_truth(40.0, np.array([0.0, 1.0, 0.0]))
    assert abs(f_up["epof_mean_dps"] - want_up) < 0.05 * want_up, (f_up, want_up)
    assert abs(f_ahead["epof_mean_dps"] - want_ahead) < 0.05 * want_ahead, (f_ahead, want_ahead)
    assert f_up["yaw_rate_mean_dps"] == f_ahead["yaw_rate_mean_dps"]


def test_a_grid_without_the_camera_rotation_is_refused(tmp_path):
    """A grid without the per-frame camera rotation (paper mode, or made before vimsim
    estimated it) or without a field: refused naming the grid and the fix."""
    from dataclasses import replace

    g = _grid(tmp_path, "p", 20.0, 0.0, 0.0, frames=3)
    for bare in (replace(g, extras={}), replace(g, field_dps=None)):
        with pytest.raises(InputError, match="p.npz.*--method sphere"):
            features_from_grid(bare)


def test_a_poorly_fitted_frame_weighs_less_in_the_rates():
    """Frames whose ego fit has confidence 0 do not count in the rates' means and blocks;
    equal confidences give the plain mean."""
    from types import SimpleNamespace

    from simulator.discomfort.features import _rate_features

    om = np.zeros((7, 3))
    om[:, 1] = [10, 10, 10, 10, 10, 90, 90]  # yaw rate = omega_y
    conf = np.array([1, 1, 1, 1, 1, 0, 0], float)
    g = SimpleNamespace(extras={"ego_omega_dps": om, "ego_confidence": conf}, fps=30.0)
    f = _rate_features(g, np.arange(7), 30)
    assert f["yaw_rate_mean_dps"] == pytest.approx(10.0)
    assert f["yaw_rate_block_max_dps"] == pytest.approx(10.0)
    g = SimpleNamespace(extras={"ego_omega_dps": om, "ego_confidence": np.full(7, 0.5)}, fps=30.0)
    assert _rate_features(g, np.arange(7), 30)["yaw_rate_mean_dps"] == pytest.approx(230 / 7)


def test_a_head_following_the_content_sees_no_view_rotation(tmp_path):
    """A camera yawing right at 40 deg/s moves the content left; a head turning left at 40
    deg/s follows it: the view's rotation against the content is ~0 while the camera's is
    40; a still head sees the camera's. A constant rotation has ~no angular acceleration."""
    g = _grid(tmp_path, "yaw", 40.0, 0.0, 0.0)
    t = np.array([0.0, 1.0])
    follow = HeadPath.from_angles_deg(t, [0.0, -40.0], np.zeros(2), np.zeros(2))
    still = HeadPath.from_angles_deg(t, np.zeros(2), np.zeros(2), np.zeros(2))
    f, s = features_from_grid(g, follow), features_from_grid(g, still)
    assert f["view_rate_mean_dps"] < 0.05 * 40 and f["rotation_mean_dps"] > 38
    assert s["view_rate_mean_dps"] == pytest.approx(s["rotation_mean_dps"])
    assert features_from_grid(g)["view_rate_mean_dps"] == pytest.approx(s["rotation_mean_dps"])
    assert s["rotation_change_mean_dps2"] < 0.1 * 40 * 30  # jitter only, far below 1 rad/s^2
