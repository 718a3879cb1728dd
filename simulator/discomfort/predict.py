"""Predicted discomfort where decisions are made: the columns a model adds to a screening's or a study's tables, from a grid file.

:data:`MODEL_COLUMNS`: ``predicted_discomfort`` (rating units of the model's training
ratings), ``predicted_low`` / ``predicted_high`` (its held-out 95 % band,
:mod:`simulator.discomfort.model`) and ``predicted_extrapolated`` (1 when the prediction
lies outside the training ratings' range, else 0). A model fitted on per-viewing ratings
(``ratings.per_viewing``) predicts a viewing from its head path; otherwise every viewing
of a video gets the video's prediction. :func:`model_note` is the line shown beside
them: the model's held-out SROCC and RMSE.
"""

from __future__ import annotations

import os
from pathlib import Path

from simulator.core.errors import InputError
from simulator.discomfort.features import features_from_grid
from simulator.discomfort.model import Model, load_model
from simulator.media.gridfile import load_grid

__all__ = ["MODEL_COLUMNS", "model_note", "model_summary", "predict_columns", "study_model"]

MODEL_COLUMNS: tuple[str, ...] = (
    "predicted_discomfort", "predicted_low", "predicted_high", "predicted_extrapolated",
)  # fmt: skip


def predict_columns(model: Model, grid: str | os.PathLike, headpath=None) -> dict:
    """:data:`MODEL_COLUMNS` of one video (``headpath`` None, or a video-level model) or one
    viewing, from its sphere-mode grid file."""
    per_viewing = bool(model.data["ratings"].get("per_viewing"))
    g = load_grid(grid)
    p = model.predict(features_from_grid(g, headpath if per_viewing else None))
    return dict(zip(MODEL_COLUMNS, (p.value, p.low, p.high, int(p.extrapolated)), strict=True))


def model_summary(model: Model) -> dict:
    """What a table's reader needs beside the predictions: the model file, its held-out
    figures and the ratings' range."""
    cv, r = model.cv, model.data["ratings"]
    return {
        "path": model.path, "srocc": cv["srocc"], "srocc_ci": cv["srocc_ci"], "rmse": cv["rmse"],
        "lcc": cv["lcc"], "grouped": cv["grouped"], "folds": cv["folds"],
        "ratings_min": r["min"], "ratings_max": r["max"], "per_viewing": bool(r.get("per_viewing")),
    }  # fmt: skip


def model_note(model: Model) -> str:
    """One line: the model, its held-out SROCC and RMSE, how they were measured."""
    s = model_summary(model)
    how = "whole groups held out" if s["grouped"] else "leave-one-out, no groups"
    return (
        f"predicted discomfort by model {os.path.basename(s['path'])}: held-out SROCC "
        f"{s['srocc']:.2f} [{s['srocc_ci'][0]:.2f}, {s['srocc_ci'][1]:.2f}], RMSE {s['rmse']:.3g} "
        f"({how}, {s['folds']} folds); ratings {s['ratings_min']:.3g} to {s['ratings_max']:.3g}, "
        "predictions outside are extrapolated"
    )


def study_model(manifest: Path, base: Path, table, videos) -> Path | None:
    """A study manifest's ``[model]`` table (``path = "MODEL.json"``, relative to the
    manifest's folder ``base``): the model's path, its JSON checked now (schema, features
    version); ``videos``: ``(id, method)`` of each video, all of which must be in sphere
    mode (the features need its field). None without the table; InputError naming the
    manifest, ``[model]`` and the problem."""
    if table is None:
        return None
    where = f"{manifest}: [model]"
    if not isinstance(table, dict) or set(table) != {"path"} or not isinstance(table["path"], str):
        raise InputError(f'{where}: expected exactly one key, path = "MODEL.json"')
    p = Path(table["path"])
    p = p if p.is_absolute() else base / p
    try:
        load_model(p)
    except InputError as e:
        raise InputError(f"{where}: {e}") from None
    for vid, method in videos:
        if method != "sphere":
            raise InputError(
                f"{where}: video {vid!r} is preprocessed in {method} mode; the model's features "
                'need method = "sphere"'
            )
    return p
