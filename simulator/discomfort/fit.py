"""Fitting a discomfort model to ratings: a standardised ridge regression, judged by held-out cross-validation with bootstrap intervals.

The model is scikit-learn's ``make_pipeline(StandardScaler(), RidgeCV(alphas))``:
features standardised, then ridge regression whose penalty is picked by RidgeCV's own
inner (efficient leave-one-out) cross-validation. It is judged by *outer*
cross-validation: with groups (content, scenes) ``GroupKFold`` holds whole groups out
(``min(5, groups)`` folds), so each prediction is of content the model did not see;
without groups, leave-one-out (each row predicted by a model fitted on the others: an
optimistic figure when rows share content, which the model's JSON says by
``grouped: false``). From the held-out predictions: Pearson's LCC, Spearman's SROCC and
the RMSE, each with a 95 % percentile bootstrap interval (rows resampled; with groups,
whole groups resampled), and the residuals' 2.5th / 97.5th percentiles (the band of a
prediction, :mod:`simulator.discomfort.model`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from sklearn.linear_model import RidgeCV
from sklearn.model_selection import GroupKFold, LeaveOneOut, cross_val_predict
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import StandardScaler

from simulator.discomfort.features import FEATURES

__all__ = [
    "ALPHAS",
    "CrossValidation",
    "cross_validate",
    "fit_pipeline",
    "metrics",
    "model_terms",
    "srocc_without",
]

#: Ridge penalties RidgeCV chooses from (standardised features).
ALPHAS: tuple[float, ...] = tuple(float(a) for a in np.logspace(-3, 4, 29))
#: Bootstrap resamples of the held-out predictions.
N_BOOT = 1000


@dataclass(frozen=True)
class CrossValidation:
    """Held-out predictions ``predicted`` (N,) of the ratings ``rated`` (N,), and the
    figures of ``cross_validation`` in MODEL.json (``summary``)."""

    predicted: NDArray[np.float64]
    rated: NDArray[np.float64]
    summary: dict


def fit_pipeline(X: NDArray, y: NDArray):
    """The fitted ``StandardScaler -> RidgeCV`` pipeline of rows ``X`` (N, F), ratings ``y``."""
    return make_pipeline(StandardScaler(), RidgeCV(alphas=ALPHAS)).fit(X, y)


def _rank(x: NDArray) -> NDArray[np.float64]:
    """Ranks 1..N, ties given their mean rank (as ``scipy.stats.rankdata``)."""
    _, inv, cnt = np.unique(x, return_inverse=True, return_counts=True)
    start = np.cumsum(cnt) - cnt
    return (start + (cnt + 1) / 2.0)[inv]


def _pearson(a: NDArray, b: NDArray) -> float:
    a, b = a - a.mean(), b - b.mean()
    den = math.sqrt(float(a @ a) * float(b @ b))
    return float(a @ b) / den if den > 0 else 0.0


def metrics(pred: NDArray, rated: NDArray) -> tuple[float, float, float]:
    """``(lcc, srocc, rmse)`` of predictions against ratings: Pearson's r, Spearman's rho
    (Pearson's r of the ranks, ties at their mean rank: scipy.stats' figures, computed
    in plain numpy since the bootstrap asks for them a thousand times) and the RMSE. A
    constant's correlations are 0."""
    pred, rated = np.asarray(pred, np.float64), np.asarray(rated, np.float64)
    rmse = float(np.sqrt(np.mean((pred - rated) ** 2)))
    return _pearson(pred, rated), _pearson(_rank(pred), _rank(rated)), rmse


def _bootstrap(pred, rated, groups, seed: int) -> dict[str, list[float]]:
    """95 % percentile intervals of the three metrics, resampling rows (or whole groups)."""
    rng = np.random.default_rng(seed)
    units = np.unique(groups) if groups is not None else np.arange(len(pred))
    idx_of = {u: np.flatnonzero(groups == u) for u in units} if groups is not None else None
    draws = []
    for _ in range(N_BOOT):
        pick = rng.choice(len(units), len(units))
        idx = np.concatenate([idx_of[units[k]] for k in pick]) if idx_of is not None else pick
        draws.append(metrics(pred[idx], rated[idx]))
    d = np.asarray(draws)
    lo, hi = np.percentile(d, [2.5, 97.5], axis=0)
    return {
        k: [float(lo[i]), float(hi[i])] for i, k in enumerate(("lcc_ci", "srocc_ci", "rmse_ci"))
    }


def _splitter(y: NDArray, groups: NDArray | None):
    if groups is not None:
        folds = min(5, len(np.unique(groups)))
        return folds, GroupKFold(n_splits=folds), f"GroupKFold({folds}): whole groups held out"
    return len(y), LeaveOneOut(), "leave-one-out (no groups given)"


def srocc_without(X: NDArray, y: NDArray, groups: NDArray | None, names: list[str]) -> dict:
    """What each feature adds: ``{name: held-out SROCC of the model refitted without it}``
    (same folds as :func:`cross_validate`; no bootstrap)."""
    X, y = np.asarray(X, np.float64), np.asarray(y, np.float64)
    _, cv, _ = _splitter(y, groups)
    out = {}
    for j, name in enumerate(names):
        pipe = make_pipeline(StandardScaler(), RidgeCV(alphas=ALPHAS))
        pred = cross_val_predict(pipe, np.delete(X, j, axis=1), y, groups=groups, cv=cv)
        out[name] = metrics(pred, y)[1]
    return out


def cross_validate(
    X: NDArray, y: NDArray, groups: NDArray | None, *, seed: int = 0
) -> CrossValidation:
    """Held-out predictions and their figures (module docstring); ``groups`` (N,) labels
    or None (leave-one-out)."""
    X, y = np.asarray(X, np.float64), np.asarray(y, np.float64)
    groups = None if groups is None else np.asarray(groups)
    folds, cv, scheme = _splitter(y, groups)
    pipe = make_pipeline(StandardScaler(), RidgeCV(alphas=ALPHAS))
    pred = cross_val_predict(pipe, X, y, groups=groups, cv=cv)
    lcc, srocc, rmse = metrics(pred, y)
    res = y - pred
    lo, hi = np.percentile(res, [2.5, 97.5])
    summary = {
        "lcc": lcc, "srocc": srocc, "rmse": rmse, **_bootstrap(pred, y, groups, seed),
        "folds": int(folds), "grouped": groups is not None, "scheme": scheme, "n": len(y),
        "residual_low": float(lo), "residual_high": float(hi),
    }  # fmt: skip
    return CrossValidation(pred, y, summary)


def model_terms(pipe, names: list[str]) -> dict:
    """``features`` (name, unit, mean, scale, coef), ``intercept`` and ``alpha`` of a fitted
    pipeline, as MODEL.json holds them (a constant feature gets scale 1)."""
    sc, ridge = pipe[0], pipe[-1]
    units = {f.name: f.unit for f in FEATURES}
    scale = np.where(sc.scale_ > 0, sc.scale_, 1.0)
    feats = [
        {"name": n, "unit": units[n], "mean": float(m), "scale": float(s), "coef": float(c)}
        for n, m, s, c in zip(names, sc.mean_, scale, ridge.coef_, strict=True)
    ]
    return {"features": feats, "intercept": float(ridge.intercept_), "alpha": float(ridge.alpha_)}
