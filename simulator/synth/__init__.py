"""Synthetic 360 deg clips with analytic ground-truth optical flow: scenes, textures, clip and truth files.

The stage's public names are re-exported here (``from simulator.synth import ...``); each
submodule says what it holds.
"""

from __future__ import annotations

from simulator.core.choices import SCENES
from simulator.synth.clip import Truth, load_truth, synthesize, truth_path_for
from simulator.synth.scenes import (
    SynthConfig,
    SynthScene,
    angular_speed_dps,
    make_scene,
    window_truth_dps,
)
from simulator.synth.textures import load_texture, procedural_panorama

__all__ = [
    "SCENES",
    "SynthConfig",
    "SynthScene",
    "Truth",
    "angular_speed_dps",
    "load_texture",
    "load_truth",
    "make_scene",
    "procedural_panorama",
    "synthesize",
    "truth_path_for",
    "window_truth_dps",
]
