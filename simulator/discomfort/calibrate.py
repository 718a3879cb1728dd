"""``vimsim calibrate``: a lab's ratings in, a discomfort model with its held-out accuracy out (MODEL.json, weights table, calibration plot).

Steps: read and check ``RATINGS.csv`` (:mod:`simulator.discomfort.ratings`) and every
head path it names; for each distinct video, its sphere-mode grid from the cache folder
(made there, atomically, when missing: ``<content hash>.npz``; a cached file is used
only when it is the grid of that very video, by content hash); the features of each
row (:mod:`simulator.discomfort.features`); the ridge pipeline and its cross-validation
(:mod:`simulator.discomfort.fit`). Outputs, each written atomically after all the work:

- ``MODEL.json`` (:mod:`simulator.discomfort.model`),
- ``<MODEL>.weights.csv``: one row per feature: ``feature,unit,weight_per_sd,
  coef_per_unit,mean,sd,heldout_srocc_without`` (largest ``|weight_per_sd|`` first;
  ``weight_per_sd`` = the rating change for one standard deviation of the feature;
  ``heldout_srocc_without`` = the held-out SROCC of the model refitted without it, same
  folds: what the feature adds),
- ``<MODEL>.calibration.png``: held-out predicted against rated, with the figures,
- ``<MODEL>.features.csv``: the features of every row with its rating (the table the
  model was fitted on).

The side files are replaced only when the ``MODEL.json`` being replaced lists them
(written by an earlier ``vimsim calibrate``); any other existing file of those names is
refused before any work.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from simulator import __version__
from simulator.core.errors import InputError
from simulator.core.fileio import (
    atomic_output,
    check_not_input,
    check_output_dir,
    check_output_file,
    csv_cell,
)
from simulator.core.progress import Progress
from simulator.discomfort.features import (
    FEATURES,
    FEATURES_VERSION,
    feature_names,
    features_from_grid,
)
from simulator.discomfort.fit import cross_validate, fit_pipeline, model_terms, srocc_without
from simulator.discomfort.model import MODEL_FORMAT, MODEL_FORMAT_VERSION, save_model
from simulator.discomfort.ratings import Ratings, read_ratings
from simulator.epof.parts import has_parts
from simulator.media.gridfile import content_hash, load_grid
from simulator.preprocess.sphere import preprocess_sphere
from simulator.sphere.windows import grid_preset
from simulator.traces.readers import load_headpath

__all__ = ["Calibration", "calibrate", "describe", "grid_for", "side_paths"]

_SIDES = ("weights.csv", "calibration.png", "features.csv")


@dataclass(frozen=True)
class Calibration:
    """What ``calibrate`` wrote (``paths``) and the model's JSON object (``model``)."""

    model: dict
    paths: dict[str, Path]


def side_paths(model_path: str | os.PathLike) -> dict[str, Path]:
    """The side files of a model path: ``{"weights.csv": ..., ...}``."""
    m = Path(model_path)
    stem = m.name[: -len(m.suffix)] if m.suffix else m.name
    return {s: m.with_name(f"{stem}.{s}") for s in _SIDES}


def _check_outputs(model_path: Path, inputs: list[Path]) -> dict[str, Path]:
    check_output_file(model_path, inputs)
    sides = side_paths(model_path)
    mine: set[str] = set()
    if model_path.is_file():
        try:
            old = json.loads(model_path.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, ValueError, RecursionError):
            old = None
        if not (isinstance(old, dict) and old.get("format") == MODEL_FORMAT):
            raise InputError(
                f"{model_path}: exists and is not a vimsim model; refusing to replace it "
                "(move it or choose another -o)"
            )
        mine = {str(v) for v in (old.get("outputs") or {}).values()}
    for p in sides.values():
        check_not_input(p, inputs)
        if (p.exists() or p.is_symlink()) and p.name not in mine:
            raise InputError(
                f"{p}: exists and was not written by vimsim calibrate; refusing to replace "
                "it (move it or choose another -o)"
            )
    return sides


def grid_for(video: Path, cache: Path, *, progress: Progress | None = None) -> Path:
    """The sphere-mode grid of ``video`` in the folder ``cache`` (both made when missing; a
    folder made here and left empty by a failure is removed)."""
    made = not Path(cache).exists()
    check_output_dir(cache)
    try:
        return _grid_in(video, Path(cache), progress)
    except BaseException:
        if made:
            with contextlib.suppress(OSError):
                Path(cache).rmdir()  # only when empty
        raise


def _grid_in(video: Path, cache: Path, progress) -> Path:
    want = content_hash(video)
    g = cache / f"{want.removeprefix('sha256:')[:20]}.npz"
    if g.exists():
        try:
            grid = load_grid(g)
            ok = grid.meta.get("video", {}).get("content_hash") == want and has_parts(grid)
        except InputError:
            ok = False
        if not ok:
            raise InputError(
                f"{g}: exists and is not the sphere grid of {video}; refusing to replace it "
                "(remove it or choose another --grids folder)"
            )
        return g
    return preprocess_sphere(video, g, grid=grid_preset("default"), progress=progress)


def _set_hash(ratings: Ratings, hashes: dict[Path, str]) -> str:
    rows = [
        [hashes[r.video], r.rating, r.group, content_hash(r.trace) if r.trace else None,
         r.participant]
        for r in ratings.rows
    ]  # fmt: skip
    return "sha256:" + hashlib.sha256(json.dumps(rows, sort_keys=True).encode()).hexdigest()


def _features(ratings: Ratings, cache: Path, progress) -> tuple[np.ndarray, dict[Path, str]]:
    traces = {r.trace: None for r in ratings.rows if r.trace is not None}
    for r in ratings.rows:
        if r.trace is not None and traces[r.trace] is None:
            try:
                traces[r.trace] = load_headpath(r.trace)
            except InputError as e:
                raise InputError(f"{ratings.path}: row {r.line}: {e}") from None
    grids, hashes, per_video = {}, {}, {}
    first = {}
    for r in ratings.rows:
        first.setdefault(r.video, r.line)
    for k, v in enumerate(ratings.videos):
        try:
            grids[v] = grid_for(v, cache)
        except InputError as e:  # not a video, a still, a foreign cache file: name the row
            raise InputError(f"{ratings.path}: row {first[v]}: {e}") from None
        hashes[v] = content_hash(v)
        if progress is not None:
            progress(k + 1, len(ratings.videos))
    rows = []
    for r in ratings.rows:
        try:
            grid = load_grid(grids[r.video])
            if r.trace is None:
                if r.video not in per_video:
                    per_video[r.video] = features_from_grid(grid)
                f = per_video[r.video]
            else:
                f = features_from_grid(grid, traces[r.trace])
        except InputError as e:
            raise InputError(f"{ratings.path}: row {r.line}: {e}") from None
        rows.append([f[n] for n in feature_names()])
    return np.asarray(rows, np.float64), hashes


def _weights_csv(terms: dict, without: dict) -> str:
    buf = io.StringIO()
    buf.write("feature,unit,weight_per_sd,coef_per_unit,mean,sd,heldout_srocc_without\n")
    for f in sorted(terms["features"], key=lambda f: -abs(f["coef"])):
        buf.write(
            f"{csv_cell(f['name'])},{csv_cell(f['unit'])},{f['coef']:.6g},"
            f"{f['coef'] / f['scale']:.6g},{f['mean']:.6g},{f['scale']:.6g},"
            f"{without[f['name']]:.4f}\n"
        )
    return buf.getvalue()


def _features_csv(ratings: Ratings, X: np.ndarray, pred: np.ndarray) -> str:
    buf = io.StringIO()
    buf.write(
        "video,group,trace,participant,rating,heldout_predicted," + ",".join(feature_names()) + "\n"
    )
    base = ratings.path.resolve().parent
    for r, x, p in zip(ratings.rows, X, pred, strict=True):
        rel = [os.path.relpath(q, base) if q is not None else "" for q in (r.video, r.trace)]
        cells = [rel[0], r.group or "", rel[1], r.participant]
        buf.write(",".join(csv_cell(c) for c in cells) + f",{r.rating:.10g},{p:.6g},")
        buf.write(",".join(f"{v:.10g}" for v in x) + "\n")
    return buf.getvalue()


def _plot(path: Path, cv, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    s = cv.summary
    fig, ax = plt.subplots(figsize=(5.2, 5.0), dpi=110)
    ax.scatter(cv.rated, cv.predicted, s=18, color="tab:blue", alpha=0.8)
    lo = float(min(cv.rated.min(), cv.predicted.min()))
    hi = float(max(cv.rated.max(), cv.predicted.max()))
    ax.plot([lo, hi], [lo, hi], color="0.4", ls="--", lw=1)
    ax.set_xlabel("rated")
    ax.set_ylabel("predicted (held out)")
    ax.set_title(
        f"{title}\nLCC {s['lcc']:.2f} [{s['lcc_ci'][0]:.2f}, {s['lcc_ci'][1]:.2f}]  "
        f"SROCC {s['srocc']:.2f} [{s['srocc_ci'][0]:.2f}, {s['srocc_ci'][1]:.2f}]  "
        f"RMSE {s['rmse']:.3g}\n{s['scheme']}",
        fontsize=8,
    )
    fig.tight_layout()
    with atomic_output(path) as tmp:
        fig.savefig(tmp)
    plt.close(fig)


def calibrate(
    ratings_path: str | os.PathLike,
    model_path: str | os.PathLike,
    *,
    grids: str | os.PathLike | None = None,
    seed: int = 0,
    progress: Progress | None = None,
) -> Calibration:
    """Fit, judge and write a model (module docstring). ``grids``: the cache folder of
    sphere-mode grids (default ``<MODEL>.grids`` beside the model); ``seed``: the
    bootstrap's. InputError before anything is written for bad input."""
    ratings = read_ratings(ratings_path)
    model_path = Path(model_path)
    inputs = [ratings.path, *ratings.videos, *(r.trace for r in ratings.rows if r.trace)]
    sides = _check_outputs(model_path, inputs)
    stem = side_paths(model_path)["weights.csv"].name.removesuffix(".weights.csv")
    cache = Path(grids) if grids is not None else model_path.with_name(stem + ".grids")
    X, hashes = _features(ratings, cache, progress)
    y = np.array([r.rating for r in ratings.rows])
    groups = np.array([r.group for r in ratings.rows]) if ratings.grouped else None
    cv = cross_validate(X, y, groups, seed=seed)
    terms = model_terms(fit_pipeline(X, y), feature_names())
    without = srocc_without(X, y, groups, feature_names())
    data = {
        "format": MODEL_FORMAT, "format_version": MODEL_FORMAT_VERSION,
        "features_version": FEATURES_VERSION, **terms,
        "cross_validation": cv.summary,
        "ratings": {
            "min": float(y.min()), "max": float(y.max()), "mean": float(y.mean()),
            "n": len(y), "n_videos": len(ratings.videos),
            "per_viewing": any(r.trace is not None for r in ratings.rows),
            "file": ratings.path.name, "csv_hash": ratings.csv_hash,
        },
        "training_set_hash": _set_hash(ratings, hashes),
        "vimsim_version": __version__,
        "feature_units": {f.name: f.unit for f in FEATURES},
        "outputs": {k: p.name for k, p in sides.items()},
    }  # fmt: skip
    save_model(model_path, data)  # first: it lists the side files a later run may replace
    with atomic_output(sides["weights.csv"]) as tmp:
        tmp.write_text(_weights_csv(terms, without), encoding="utf-8")
    with atomic_output(sides["features.csv"]) as tmp:
        tmp.write_text(_features_csv(ratings, X, cv.predicted), encoding="utf-8")
    _plot(sides["calibration.png"], cv, f"{ratings.path.name}: {len(y)} ratings")
    return Calibration(data, {"model": model_path, **sides})


def describe(data: dict) -> str:
    """One line: the model's held-out figures."""
    s = data["cross_validation"]
    return (
        f"held-out SROCC {s['srocc']:.3f} [{s['srocc_ci'][0]:.2f}, {s['srocc_ci'][1]:.2f}], "
        f"LCC {s['lcc']:.3f}, RMSE {s['rmse']:.3g} ({s['scheme']}, {s['n']} ratings)"
    )
