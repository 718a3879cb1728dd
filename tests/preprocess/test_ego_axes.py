"""The camera's rate about each of its axes from ``vimsim ego``'s estimate, against synthetic truth: yaw, pitch and roll within 3 %, and how little translation leaks into rotation."""

from __future__ import annotations

import numpy as np
import pytest

from simulator.media.gridfile import load_grid
from simulator.preprocess import preprocess_sphere
from simulator.preprocess.egocsv import EgoTable
from simulator.sphere.windows import grid_preset
from simulator.synth import SynthConfig
from simulator.synth.clip import synthesize

#: Every test renders and preprocesses 512x256 clips: a few seconds each.
pytestmark = pytest.mark.slow

AXES = {"yaw": (0.0, -1.0, 0.0), "pitch": (1.0, 0.0, 0.0), "roll": (0.0, 0.0, 1.0)}


def _rates(tmp_path, axis: str, omega: float, *, frames: int = 6, flow: str = "dis"):
    """Mean yaw, pitch, roll rates (deg/s, vimsim ego's columns) of a rotate clip whose camera
    turns at ``omega`` about one of its axes (+ direction: yaw right, pitch up, roll
    right ear down; the scene's axis is the content's, the opposite of the camera's)."""
    cfg = SynthConfig(
        scene="rotate", seconds=frames / 30, size=(512, 256), axis=AXES[axis], omega_dps=omega
    )
    v = synthesize(cfg, tmp_path / f"{axis}.mp4")[0]
    g = load_grid(
        preprocess_sphere(v, tmp_path / f"{axis}.npz", grid=grid_preset("default"), flow=flow)
    )
    om = g.extras["ego_omega_dps"].astype(float)
    t = EgoTable(np.arange(len(om)), np.arange(len(om)) / 30, om, g.extras["ego_confidence"])
    return t.rates_dps()[1:].mean(axis=0)  # row 0 repeats row 1


@pytest.mark.parametrize("axis", list(AXES))
def test_rate_about_each_axis_within_3_percent(tmp_path, axis):
    """The default flow at 30 and 120 deg/s: the turning axis's rate within 3 % (its sign
    too), the other two under 1.5 % of omega (bench/calibrate.py prints 5-120 deg/s)."""
    for omega in (30.0, 120.0):
        rates = dict(zip(AXES, _rates(tmp_path, axis, omega, frames=5), strict=True))
        assert abs(rates[axis] - omega) < 0.03 * omega, (omega, rates)
        for other in set(AXES) - {axis}:
            assert abs(rates[other]) < 0.015 * omega, (omega, rates)


@pytest.mark.parametrize("axis", list(AXES))
def test_slow_rate_about_each_axis_within_3_percent(tmp_path, axis):
    """The default flow at 5, 10 and 20 deg/s (0.4-1.7 tile pixels per frame, where sphere
    mode reads slow pairs at twice DIS's resolution): the turning axis's rate within 3 %,
    the other two under 0.3 deg/s. (Before that, with DIS's variational refinement on slow
    pairs, 5 deg/s read +8.5 / +13.4 / +12.7 %: docs/ego.md.)"""
    for omega in (5.0, 10.0, 20.0):
        rates = dict(zip(AXES, _rates(tmp_path, axis, omega, frames=10), strict=True))
        assert abs(rates[axis] - omega) < 0.03 * omega, (omega, rates)
        for other in set(AXES) - {axis}:
            assert abs(rates[other]) < 0.3, (omega, rates)


def test_translation_leaks_under_1_dps_into_rotation(tmp_path):
    """A 2 m/s walk straight ahead through the room (no rotation), then the same walk while
    turning right at 30 deg/s: the estimated rotation is under 1 deg/s on the straight walk
    (every frame), and the yaw rate of the turning one is 30 within 3 %."""
    from simulator.synth.camera_path import CameraTrajectory
    from simulator.synth.trajectory import synthesize_trajectory

    t = np.arange(0.0, 12 / 30, 1 / 60)
    pos = np.column_stack([0 * t, 0 * t, 2.0 * t])
    for name, yaw_dps in (("walk", 0.0), ("turn", 30.0)):
        traj = CameraTrajectory.from_poses_deg(t, pos, yaw_dps * t, 0 * t, 0 * t, source=name)
        v = synthesize_trajectory(traj, tmp_path / f"{name}.mp4", size=(512, 256))[0]
        g = load_grid(preprocess_sphere(v, tmp_path / f"{name}.npz", grid=grid_preset("default")))
        om = g.extras["ego_omega_dps"][1:].astype(float)
        if yaw_dps == 0:
            assert np.linalg.norm(om, axis=1).max() < 1.0, om
        else:
            assert abs(om[:, 1].mean() - yaw_dps) < 0.03 * yaw_dps, om
            assert np.abs(om[:, [0, 2]].mean(axis=0)).max() < 1.0, om
