"""A discomfort model's predictions where decisions are made: vimsim screen --model, and a study's [model] path."""

from __future__ import annotations

import csv
import json

import pytest
from discomfort_helpers import model_json

from simulator.cli import main
from simulator.discomfort.features import features_from_grid
from simulator.discomfort.model import load_model
from simulator.discomfort.predict import MODEL_COLUMNS
from simulator.media.gridfile import load_grid


@pytest.fixture(scope="module")
def clip(tmp_path_factory):
    from simulator.synth import SynthConfig, synthesize

    d = tmp_path_factory.mktemp("pred")
    synthesize(
        SynthConfig("rotate", seconds=0.5, fps=10, size=(128, 64), omega_dps=40.0), d / "c.mp4"
    )
    return d / "c.mp4"


def _rows(path):
    lines = [ln for ln in path.read_text().splitlines() if not ln.startswith("#")]
    return list(csv.DictReader(lines))


@pytest.mark.slow  # a whole screening
def test_screen_adds_the_predictions_beside_the_models_accuracy(clip, tmp_path, capsys):
    m = model_json(tmp_path / "m.json", coef={"epof_mean_dps": 2.0})
    out = tmp_path / "o"
    rc = main(["screen", str(clip), "-o", str(out), "--viewers", "2", "--workers", "1",
               "--no-progress", "--cache-dir", str(tmp_path / "cache"), "--model", str(m)])  # fmt: skip
    assert rc == 0
    text = (out / "screen" / "comparison.csv").read_text()
    assert "held-out SROCC 0.88" in text and "RMSE 1.5" in text
    (row,) = _rows(out / "screen" / "comparison.csv")
    assert all(c in row for c in MODEL_COLUMNS)
    grid = json.loads((out / "study.json").read_text())["videos"]["c"]["grid"]
    want = load_model(m).predict(features_from_grid(load_grid(grid)))
    assert float(row["predicted_discomfort"]) == pytest.approx(want.value, rel=1e-6)
    assert float(row["predicted_low"]) == pytest.approx(want.value - 2.0, rel=1e-6)
    assert float(row["predicted_high"]) == pytest.approx(want.value + 3.0, rel=1e-6)
    assert row["predicted_extrapolated"] == "0"
    page = (out / "screen" / "index.html").read_text()
    assert "predicted_discomfort" in page and "held-out SROCC 0.88" in page
    assert "predicted discomfort" in capsys.readouterr().out


@pytest.mark.slow  # a whole screening
def test_a_prediction_outside_the_ratings_is_marked_extrapolated(clip, tmp_path):
    m = model_json(tmp_path / "m.json", coef={"epof_mean_dps": 100.0})
    out = tmp_path / "o"
    assert main(["screen", str(clip), "-o", str(out), "--viewers", "1", "--workers", "1",
                 "--no-progress", "--cache-dir", str(tmp_path / "cache"), "--model", str(m)]) == 0  # fmt: skip
    (row,) = _rows(out / "screen" / "comparison.csv")
    assert row["predicted_extrapolated"] == "1"


@pytest.mark.parametrize(
    ("top", "words"),
    [({"features_version": "0"}, "features version"), ({"intercept": None}, "intercept")],
)
def test_screen_refuses_a_bad_model_before_any_work(clip, tmp_path, capsys, top, words):
    m = model_json(tmp_path / "m.json", **top)
    out = tmp_path / "o"
    rc = main(["screen", str(clip), "-o", str(out), "--no-progress", "--model", str(m)])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and "m.json" in err and words in err and "\n" not in err
    assert not out.exists()
