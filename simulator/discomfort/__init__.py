"""Expected discomfort: features a video shows, a model calibrated on a lab's own ratings, and its predictions.

``features`` (what is measured, versioned, with units), ``ratings`` (RATINGS.csv),
``fit`` (the scikit-learn pipeline and its held-out cross-validation), ``model`` (MODEL.json:
schema, loading, predictions), ``calibrate`` (``vimsim calibrate``). See docs/calibrate.md.
"""

from __future__ import annotations

from simulator.discomfort.features import FEATURES, FEATURES_VERSION, Feature, features_from_grid
from simulator.discomfort.model import Model, Prediction, load_model

__all__ = [
    "FEATURES",
    "FEATURES_VERSION",
    "Feature",
    "Model",
    "Prediction",
    "features_from_grid",
    "load_model",
]
