"""Helpers of the discomfort tests: a rotate clip turning the camera at given per-axis rates."""

from __future__ import annotations

from pathlib import Path

import numpy as np

#: The synthetic rating rule: roll weighs 5x yaw, pitch 3x (rates in deg/s).
WEIGHTS = {"yaw": 1.0, "pitch": 3.0, "roll": 5.0}


def rotate_clip(path: Path, yaw: float, pitch: float, roll: float, *, frames: int = 5, seed=0):
    """A rotate clip whose camera turns at these rates (deg/s) about its own axes: the scene's
    axis is the content's (camera rates: yaw = -axis_y, pitch = axis_x, roll = axis_z)."""
    from simulator.synth import SynthConfig
    from simulator.synth.clip import synthesize

    axis = np.array([pitch, -yaw, roll], float)
    cfg = SynthConfig(
        scene="rotate", seconds=frames / 30, size=(256, 128), axis=tuple(axis),
        omega_dps=float(np.linalg.norm(axis)), seed=seed,
    )  # fmt: skip
    return synthesize(cfg, path)[0]
