"""vimsim calibrate: a synthetic rating rule recovered, the model's JSON round trip, the refusals of bad input."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from simulator.cli import main
from simulator.core.errors import InputError
from simulator.discomfort.features import FEATURES
from simulator.discomfort.model import load_model, validate_model


@pytest.fixture(scope="module")
def calibrated(rated_clips, tmp_path_factory):
    """The 12 rated clips calibrated once (the grid cache filled on the way)."""
    out = tmp_path_factory.mktemp("model") / "model.json"
    args = [
        "calibrate",
        str(rated_clips.ratings),
        "-o",
        str(out),
        "--grids",
        str(rated_clips.grids),
    ]
    assert main(args) == 0
    return out


@pytest.mark.slow  # 12 synthetic clips made and calibrated once (~10 s CPU)
def test_a_rule_weighing_roll_5x_and_pitch_3x_is_recovered(calibrated, rated_clips):
    """Ratings = |yaw| + 3 |pitch| + 5 |roll| (deg/s) on 12 clips in 4 scenes: held out by
    scene (GroupKFold), SROCC >= 0.9; the per-axis weights come out in the rule's order."""
    m = load_model(calibrated)
    cv = m.cv
    assert cv["grouped"] is True and cv["folds"] == 4 and cv["n"] == 12
    assert cv["srocc"] >= 0.9, cv
    assert cv["srocc_ci"][0] <= cv["srocc"] <= cv["srocc_ci"][1]
    assert cv["rmse_ci"][0] <= cv["rmse"] <= cv["rmse_ci"][1]
    coef = {f["name"]: f["coef"] for f in m.data["features"]}
    w = {a: coef[f"{a}_rate_mean_dps"] / next(
        f["scale"] for f in m.data["features"] if f["name"] == f"{a}_rate_mean_dps")
        for a in ("yaw", "pitch", "roll")}  # fmt: skip
    assert w["roll"] > w["pitch"] > w["yaw"], w


@pytest.mark.slow  # 12 synthetic clips made and calibrated once (~10 s CPU)
def test_outputs_beside_the_model(calibrated):
    d = calibrated.parent
    assert {p.name for p in d.iterdir()} >= {
        "model.json", "model.weights.csv", "model.calibration.png", "model.features.csv",
    }  # fmt: skip
    rows = (d / "model.weights.csv").read_text().splitlines()
    assert rows[0] == "feature,unit,weight_per_sd,coef_per_unit,mean,sd,heldout_srocc_without"
    assert len(rows) == len(FEATURES) + 1
    assert rows[1].split(",")[0].startswith("roll_rate")  # the largest weight first
    without = {r.split(",")[0]: float(r.split(",")[-1]) for r in rows[1:]}
    assert all(-1 <= v <= 1 for v in without.values())
    assert (d / "model.calibration.png").read_bytes()[:4] == b"\x89PNG"
    data = json.loads(calibrated.read_text())
    for key in ("training_set_hash", "vimsim_version", "ratings", "alpha", "intercept"):
        assert key in data
    assert data["ratings"]["min"] < data["ratings"]["max"]


@pytest.mark.slow  # 12 synthetic clips made and calibrated once (~10 s CPU)
def test_model_round_trip_predicts_as_the_pipeline(calibrated, rated_clips):
    """MODEL.json read back predicts each clip's features as the fitted pipeline does."""
    from simulator.discomfort.features import feature_names
    from simulator.discomfort.fit import fit_pipeline

    table = (calibrated.parent / "model.features.csv").read_text().splitlines()
    head = table[0].split(",")
    rows = [ln.split(",") for ln in table[1:]]
    names = feature_names()
    X = np.array([[float(r[head.index(n)]) for n in names] for r in rows])
    y = np.array([float(r[head.index("rating")]) for r in rows])
    m = load_model(calibrated)
    pipe_pred = fit_pipeline(X, y).predict(X)
    ours = [m.predict(dict(zip(names, x, strict=True))) for x in X]
    assert np.allclose([p.value for p in ours], pipe_pred, rtol=1e-6, atol=1e-6)
    assert all(p.low < p.value < p.high for p in ours)
    far = dict(zip(names, X[0] * 10, strict=True))
    assert m.predict(far).extrapolated and not ours[int(np.argmin(abs(y - y.mean())))].extrapolated
    again = validate_model(json.loads(json.dumps(m.data)))
    assert again.data == m.data


@pytest.mark.slow  # 12 synthetic clips made and calibrated once (~10 s CPU)
def test_rerun_replaces_its_own_files_and_reuses_the_grids(calibrated, rated_clips, capsys):
    before = sorted(p.name for p in rated_clips.grids.iterdir())
    args = [
        "calibrate",
        str(rated_clips.ratings),
        "-o",
        str(calibrated),
        "--grids",
        str(rated_clips.grids),
    ]
    assert main(args) == 0
    assert sorted(p.name for p in rated_clips.grids.iterdir()) == before
    out = capsys.readouterr().out
    assert "held-out SROCC" in out and "GroupKFold" in out


def _bad(tmp_path, capsys, text, *, videos=8, model=None, names="r.csv"):
    for i in range(videos):
        (tmp_path / f"v{i}.mp4").write_bytes(b"not decoded before the checks")
    (tmp_path / "r.csv").write_text(text)
    out = model or tmp_path / "m.json"
    before = set(tmp_path.iterdir())
    rc = main(["calibrate", str(tmp_path / "r.csv"), "-o", str(out)])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and "\n" not in err and names in err, err
    assert set(tmp_path.iterdir()) == before  # nothing written
    return err


def _rows(n=8, group=True, rating=lambda i: i):
    head = "video,rating,group" if group else "video,rating"
    return (
        head
        + "\n"
        + "".join(
            f"v{i}.mp4,{rating(i)}" + (f",g{i % 3}" if group else "") + "\n" for i in range(n)
        )
    )


@pytest.mark.parametrize(
    "text, words",
    [
        (_rows(7), "7 rated video(s)"),
        (_rows(8).replace(",g2\n", ",g1\n").replace(",g0\n", ",g1\n"), "1 group(s)"),
        (_rows(8, rating=lambda i: "nan" if i == 3 else i), "row 5: rating 'nan'"),
        (_rows(8, rating=lambda i: "x" if i == 0 else i), "row 2: rating 'x'"),
        (_rows(8) + "v9.mp4,3,g0\n", "v9.mp4: video file not found"),
        (_rows(8) + "v1.mp4,3,g0\n", "row 10: duplicate of row 3"),
        (_rows(8).replace("video,rating,group", "video,rating,scene"), "unknown column(s) scene"),
        (_rows(8).replace("video,rating,group", "video,group"), "rating missing"),
        (_rows(8).replace("v2.mp4,2,g2", "v2.mp4,2,"), "row 4: group is empty"),
    ],
)
def test_bad_ratings_are_refused_naming_file_and_row(tmp_path, capsys, text, words):
    assert words in _bad(tmp_path, capsys, text)


def test_a_user_file_beside_the_model_is_never_replaced(tmp_path, capsys):
    (tmp_path / "m.weights.csv").write_text("mine\n")
    err = _bad(tmp_path, capsys, _rows(8), names="m.weights.csv")  # before any video is read
    assert "not written by vimsim calibrate" in err
    assert (tmp_path / "m.weights.csv").read_text() == "mine\n"


@pytest.mark.slow  # 12 synthetic clips made and calibrated once (~10 s CPU)
def test_models_failing_the_schema_are_refused(calibrated, tmp_path):
    data = json.loads(calibrated.read_text())
    cases = [
        ({**data, "features_version": "0"}, "features version '0'"),
        ({**data, "cross_validation": {}}, "cross_validation"),
        ({**data, "features": [{"name": "no_such", "mean": 0, "scale": 1, "coef": 1}]}, "unknown"),
        ({**data, "intercept": "1"}, "intercept"),
        ([1, 2], "not a JSON object"),
    ]
    for i, (d, words) in enumerate(cases):
        p = tmp_path / f"bad{i}.json"
        p.write_text(json.dumps(d))
        with pytest.raises(InputError, match=words) as e:
            load_model(p)
        assert str(p) in str(e.value)
    p = tmp_path / "pickle.json"
    p.write_bytes(b"\x80\x04\x95")
    with pytest.raises(InputError, match="not JSON"):
        load_model(p)
    shutil.copy(calibrated, tmp_path / "ok.json")
    assert load_model(tmp_path / "ok.json").names


def test_metrics_are_scipys_figures():
    """LCC and SROCC (plain numpy, for the bootstrap's speed) equal scipy.stats' Pearson and
    Spearman, ties included; a constant's correlations are 0."""
    from scipy import stats

    from simulator.discomfort.fit import metrics

    rng = np.random.default_rng(0)
    for _ in range(50):
        a = np.round(rng.normal(size=rng.integers(3, 30)), 1)
        b = np.round(a + rng.normal(size=len(a)), 1)
        lcc, srocc, rmse = metrics(a, b)
        assert lcc == pytest.approx(stats.pearsonr(a, b)[0], abs=1e-12)
        assert srocc == pytest.approx(stats.spearmanr(a, b)[0], abs=1e-12)
        assert rmse == pytest.approx(np.sqrt(np.mean((a - b) ** 2)))
    assert metrics(np.ones(4), np.arange(4.0))[:2] == (0.0, 0.0)


def test_cross_validation_holds_whole_groups_out():
    """Grouped: GroupKFold over the groups (each prediction from a fit without its group);
    a feature that only identifies the group cannot predict a held-out group."""
    from simulator.discomfort.fit import cross_validate

    rng = np.random.default_rng(1)
    groups = np.repeat(np.arange(6), 4)
    y = groups * 10.0 + rng.normal(0, 0.1, len(groups))
    X = np.column_stack([rng.normal(size=len(y)), (groups == 0).astype(float)])
    cv = cross_validate(X, y, groups.astype(str))
    assert cv.summary["grouped"] and cv.summary["folds"] == 5
    assert cv.summary["srocc"] < 0.6  # nothing learnt transfers to unseen groups
    loo = cross_validate(np.column_stack([y + rng.normal(0, 1, len(y))]), y, None)
    assert not loo.summary["grouped"] and loo.summary["folds"] == len(y)
    assert loo.summary["srocc"] > 0.9


def _trace(path, pitch, seconds=1.0):
    path.write_text(f"time_s,yaw_deg,pitch_deg,roll_deg\n0,0,{pitch},0\n{seconds},0,{pitch},0\n")
    return path.name


@pytest.mark.slow  # 24 viewings' features (the grids come from the session's cache)
def test_ratings_per_viewing_use_each_trace(rated_clips, calibrated, tmp_path):
    """A trace column: each row's features are its viewing's (looking up or ahead at the same
    clip give different EPOF), the model says per_viewing, and its training-set hash
    differs from the per-video one's."""
    d = rated_clips.folder
    up, ahead = _trace(d / "up.csv", 90.0), _trace(d / "ahead.csv", 0.0)
    lines = ["video,rating,group,trace,participant"]
    for ln in rated_clips.ratings.read_text().splitlines()[1:]:
        v, rating, g = ln.split(",")
        lines += [f"{v},{float(rating) * 0.5},{g},{up},p1", f"{v},{rating},{g},{ahead},p2"]
    csv_path = d / "viewings.csv"
    csv_path.write_text("\n".join(lines) + "\n")
    out = tmp_path / "m.json"
    assert (
        main(["calibrate", str(csv_path), "-o", str(out), "--grids", str(rated_clips.grids)]) == 0
    )
    m = load_model(out)
    assert m.data["ratings"]["per_viewing"] is True and m.data["ratings"]["n"] == 24
    rows = (tmp_path / "m.features.csv").read_text().splitlines()
    head = rows[0].split(",")
    e = [float(r.split(",")[head.index("epof_mean_dps")]) for r in rows[1:3]]
    assert e[0] < 0.8 * e[1]  # the same clip, looked at along the yaw axis vs at the horizon
    assert rows[1].split(",")[head.index("trace")] == "up.csv"
    assert m.data["training_set_hash"] != load_model(calibrated).data["training_set_hash"]


def test_a_trace_that_is_missing_or_unreadable_is_refused_naming_the_row(tmp_path, capsys):
    text = _rows(8).replace("video,rating,group", "video,rating,group,trace")
    text = "\n".join(ln + ("," if i else "") for i, ln in enumerate(text.splitlines())) + "\n"
    bad = text.replace("v3.mp4,3,g0,", "v3.mp4,3,g0,nope.csv")
    err = _bad(tmp_path, capsys, bad, names="row 5")
    assert "nope.csv" in err and "not found" in err


def test_an_output_that_is_not_a_model_is_never_replaced(tmp_path, capsys):
    (tmp_path / "m.json").write_text('{"mine": true}\n')
    err = _bad(tmp_path, capsys, _rows(8), names="m.json")
    assert "is not a vimsim model" in err
    assert (tmp_path / "m.json").read_text() == '{"mine": true}\n'


def test_a_video_that_cannot_be_decoded_is_refused_naming_its_row(tmp_path, capsys):
    """The videos pass the CSV checks (they exist) but v0 is no video: refused when its grid
    is made, naming the ratings file and the row; no model, no side file."""
    err = _bad(tmp_path, capsys, _rows(8), names="row 2")
    assert "r.csv" in err and "v0.mp4" in err
    assert not (tmp_path / "m.json").exists() and not (tmp_path / "m.weights.csv").exists()


def test_a_foreign_file_in_the_grid_cache_is_refused_and_kept(tmp_path, capsys):
    from simulator.media.gridfile import content_hash

    (tmp_path / "v0.mp4").write_bytes(b"not decoded before the checks")
    cache = tmp_path / "m.grids"
    cache.mkdir()
    name = content_hash(tmp_path / "v0.mp4").removeprefix("sha256:")[:20] + ".npz"
    (cache / name).write_bytes(b"someone's file")
    err = _bad(tmp_path, capsys, _rows(8), names="not the sphere grid of")
    assert (cache / name).read_bytes() == b"someone's file" and "row 2" in err
