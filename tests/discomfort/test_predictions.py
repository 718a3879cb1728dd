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


def _study(clip, tmp_path, model_text):
    m = tmp_path / "s.toml"
    m.write_text(f'[[videos]]\nid = "c"\npath = "{clip}"\nmethod = "sphere"\n\n'
                 '[[viewings]]\nvideo = "c"\nviewers = { n = 2, seed = 3 }\n\n' + model_text)  # fmt: skip
    return m


@pytest.mark.slow  # a whole study and its report
@pytest.mark.parametrize("per_viewing", [False, True])
def test_a_study_with_a_model_predicts_each_viewing(clip, tmp_path, capsys, per_viewing):
    """[model] path: viewings.csv gets the columns (a video-level model: the video's
    prediction for every viewer; a per-viewing one: each viewer's own), study.json and the
    report's viewings page the model's held-out SROCC and RMSE."""
    model_json(tmp_path / "m.json", coef={"epof_mean_dps": 1.0}, per_viewing=per_viewing)
    m = _study(clip, tmp_path, '[model]\npath = "m.json"\n')
    out = tmp_path / "o"
    assert main(["study", str(m), "-o", str(out), "--cache-dir", str(tmp_path / "c"),
                 "--workers", "1", "--no-progress"]) == 0  # fmt: skip
    rows = _rows(out / "viewings.csv")
    assert len(rows) == 2 and all(r["predicted_discomfort"] for r in rows)
    s = json.loads((out / "study.json").read_text())
    assert s["model"]["srocc"] == 0.88 and "held-out SROCC 0.88" in s["model"]["note"]
    grid = load_grid(s["videos"]["c"]["grid"])
    video_pred = load_model(tmp_path / "m.json").predict(features_from_grid(grid)).value
    values = [float(r["predicted_discomfort"]) for r in rows]
    if per_viewing:  # each viewer's EPOF, not the sphere's mean
        assert values[0] != values[1] and all(abs(v - video_pred) > 1e-6 for v in values)
    else:
        assert values == pytest.approx([video_pred] * 2, rel=1e-6)
    assert main(["report", str(out)]) == 0
    page = (out / "report" / "viewings.html").read_text()
    assert "predicted_discomfort" in page and "held-out SROCC 0.88" in page


def test_a_study_refuses_a_bad_model_before_any_work(clip, tmp_path, capsys):
    model_json(tmp_path / "m.json", features_version="0")
    m = _study(clip, tmp_path, '[model]\npath = "m.json"\n')
    out = tmp_path / "o"
    rc = main(["study", str(m), "-o", str(out), "--no-progress"])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and "[model]" in err and "features version" in err and "\n" not in err
    assert not out.exists()
