"""A fitted discomfort model as plain JSON (never pickled): its schema check, loading, saving and predictions.

``MODEL.json`` (``vimsim calibrate``'s output) holds::

    format: "vimsim-discomfort-model", format_version: 1
    features_version   (simulator.discomfort.features.FEATURES_VERSION when fitted)
    features           [{name, unit, mean, scale, coef}]  standardisation + ridge weights
    intercept, alpha   the ridge's intercept (rating units) and its penalty
    cross_validation   {lcc, srocc, rmse, lcc_ci, srocc_ci, rmse_ci, folds, grouped,
                        scheme, n, residual_low, residual_high}
    ratings            {min, max, mean, n, n_videos, per_viewing}
    training_set_hash, vimsim_version

A prediction is ``intercept + sum(coef * (x - mean) / scale)``, in the ratings' units.
Its band (``predicted_low``, ``predicted_high``) adds the 2.5th and 97.5th percentiles
of the held-out residuals (rated - predicted): 95 % of the held-out ratings fell that
far from their predictions. A prediction outside the ratings' range [min, max] is
*extrapolated*: the model never saw a rating there.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass
from pathlib import Path

from simulator.core.errors import InputError
from simulator.core.fileio import atomic_output, check_input_file, json_text
from simulator.discomfort.features import FEATURES_VERSION, feature_names

__all__ = ["MODEL_FORMAT", "Model", "Prediction", "load_model", "save_model", "validate_model"]

MODEL_FORMAT = "vimsim-discomfort-model"
MODEL_FORMAT_VERSION = 1

_CV_NUMBERS = ("lcc", "srocc", "rmse", "residual_low", "residual_high")
_CV_INTERVALS = ("lcc_ci", "srocc_ci", "rmse_ci")
_RATING_NUMBERS = ("min", "max", "mean")


@dataclass(frozen=True)
class Prediction:
    """``value`` and its held-out band ``low``..``high`` (rating units); ``extrapolated``
    when ``value`` lies outside the training ratings' range."""

    value: float
    low: float
    high: float
    extrapolated: bool


@dataclass(frozen=True)
class Model:
    """A checked model (:func:`validate_model`): the JSON object ``data`` and its ``path``."""

    data: dict
    path: str = ""

    @property
    def names(self) -> list[str]:
        return [f["name"] for f in self.data["features"]]

    @property
    def cv(self) -> dict:
        return self.data["cross_validation"]

    def predict(self, feats: dict[str, float]) -> Prediction:
        """The prediction for one video's or viewing's features (a dict by name)."""
        missing = [n for n in self.names if n not in feats]
        if missing:
            raise InputError(f"{self.path or 'model'}: features missing: {', '.join(missing)}")
        v = float(self.data["intercept"])
        for f in self.data["features"]:
            v += float(f["coef"]) * (float(feats[f["name"]]) - float(f["mean"])) / float(f["scale"])
        cv, r = self.cv, self.data["ratings"]
        return Prediction(
            v, v + float(cv["residual_low"]), v + float(cv["residual_high"]),
            not (float(r["min"]) <= v <= float(r["max"])),
        )  # fmt: skip


def _num(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


def _schema_problem(d) -> str | None:
    """The first way ``d`` departs from the schema (module docstring), or None."""
    if not isinstance(d, dict):
        return "is not a JSON object"
    if d.get("format") != MODEL_FORMAT or d.get("format_version") != MODEL_FORMAT_VERSION:
        return f"is not a {MODEL_FORMAT} version {MODEL_FORMAT_VERSION} file"
    if d.get("features_version") != FEATURES_VERSION:
        return (
            f"was fitted on features version {d.get('features_version')!r}; this vimsim "
            f"computes version {FEATURES_VERSION!r} (re-run vimsim calibrate)"
        )
    feats = d.get("features")
    if not isinstance(feats, list) or not feats:
        return "'features' must be a non-empty list"
    known = set(feature_names())
    for i, f in enumerate(feats):
        if not isinstance(f, dict) or f.get("name") not in known:
            return f"features[{i}]: unknown or missing feature name"
        if not all(_num(f.get(k)) for k in ("mean", "scale", "coef")) or f["scale"] <= 0:
            return f"features[{i}] ({f['name']}): mean, scale > 0 and coef must be numbers"
    if len({f["name"] for f in feats}) != len(feats):
        return "a feature is listed twice"
    if not _num(d.get("intercept")) or not _num(d.get("alpha")):
        return "'intercept' and 'alpha' must be numbers"
    cv = d.get("cross_validation")
    if not isinstance(cv, dict) or not all(_num(cv.get(k)) for k in _CV_NUMBERS):
        return f"'cross_validation' must hold numbers {', '.join(_CV_NUMBERS)}"
    for k in _CV_INTERVALS:
        ci = cv.get(k)
        if not (isinstance(ci, list) and len(ci) == 2 and all(_num(x) for x in ci)):
            return f"cross_validation.{k} must be [low, high]"
    if not isinstance(cv.get("grouped"), bool) or not isinstance(cv.get("folds"), int):
        return "cross_validation.grouped (true/false) and .folds (an integer) are required"
    r = d.get("ratings")
    if not isinstance(r, dict) or not all(_num(r.get(k)) for k in _RATING_NUMBERS):
        return f"'ratings' must hold numbers {', '.join(_RATING_NUMBERS)}"
    if r["min"] > r["max"]:
        return "ratings.min is above ratings.max"
    return None


def validate_model(d, source: str = "model") -> Model:
    """``d`` (a parsed JSON object) as a :class:`Model`; InputError naming ``source`` and
    the first problem."""
    problem = _schema_problem(d)
    if problem:
        raise InputError(f"{source}: {problem}")
    return Model(d, source)


def load_model(path: str | os.PathLike) -> Model:
    """Read and check ``MODEL.json`` (plain JSON; nothing is unpickled or run)."""
    p = check_input_file(path, "model")
    try:
        d = json.loads(p.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, ValueError, RecursionError) as e:
        msg = str(e).splitlines()[0] if str(e) else type(e).__name__
        raise InputError(f"{p}: model is not JSON ({msg})") from None
    return validate_model(d, str(p))


def save_model(path: str | os.PathLike, data: dict) -> Path:
    """Check ``data`` against the schema and write it atomically as JSON."""
    validate_model(data, str(path))
    with atomic_output(path) as tmp:
        Path(tmp).write_text(json_text(data) + "\n", encoding="utf-8")
    return Path(path)
