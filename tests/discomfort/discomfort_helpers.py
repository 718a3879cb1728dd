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


def model_json(path: Path, *, coef: dict | None = None, per_viewing: bool = False, **top) -> Path:
    """A schema-valid MODEL.json written by hand: rating = 10 + sum(coef * (x - 0) / 1)
    (features unscaled), held-out band -2..+3, ratings 0..100."""
    import json

    from simulator.discomfort.features import FEATURES, FEATURES_VERSION

    coef = coef or {"epof_mean_dps": 1.0}
    data = {
        "format": "vimsim-discomfort-model", "format_version": 1,
        "features_version": FEATURES_VERSION,
        "features": [
            {"name": f.name, "unit": f.unit, "mean": 0.0, "scale": 1.0, "coef": coef.get(f.name, 0.0)}
            for f in FEATURES
        ],
        "intercept": 10.0, "alpha": 1.0,
        "cross_validation": {
            "lcc": 0.9, "srocc": 0.88, "rmse": 1.5, "lcc_ci": [0.8, 0.95],
            "srocc_ci": [0.7, 0.95], "rmse_ci": [1.0, 2.0], "folds": 4, "grouped": True,
            "scheme": "GroupKFold(4)", "n": 12, "residual_low": -2.0, "residual_high": 3.0,
        },
        "ratings": {"min": 0.0, "max": 100.0, "mean": 50.0, "n": 12, "n_videos": 12,
                    "per_viewing": per_viewing},
        "training_set_hash": "sha256:0", "vimsim_version": "0.1.0",
    }  # fmt: skip
    data.update(top)
    path.write_text(json.dumps(data))
    return path
