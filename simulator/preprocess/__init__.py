"""Preprocessing: a video's optical flow per window (paper mode) or per frame on the sphere (sphere mode).

The stage's public names are re-exported here (``from simulator.preprocess import ...``); each
submodule says what it holds.
"""

from __future__ import annotations

from simulator.preprocess.common import PreprocessInterrupted, field_meta
from simulator.preprocess.paper import (
    WindowFlowReducer,
    checkpoint_path,
    preprocess_video,
    reduce_stride,
)
from simulator.preprocess.sphere import (
    FieldEstimator,
    SphereConfig,
    field_from_frames,
    field_from_video,
    preprocess_sphere,
)
from simulator.sphere.cells import window_pof

__all__ = [
    "FieldEstimator",
    "PreprocessInterrupted",
    "SphereConfig",
    "WindowFlowReducer",
    "checkpoint_path",
    "field_from_frames",
    "field_from_video",
    "field_meta",
    "preprocess_sphere",
    "preprocess_video",
    "reduce_stride",
    "window_pof",
]
