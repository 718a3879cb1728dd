"""The report tells each viewing's own mitigation: its replay draws the viewing's mitigation
and opacity (a ``none`` viewing has no grains, a ``grf`` one has them), the viewings table
has mitigation, opacity rule, mean opacity and visible flow, the summary a condition x
video table."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from simulator.cli import main
from simulator.report.replay import replay_settings
from simulator.traces.path import save_headpath_csv, synth

EYE = (160, 120)


@pytest.fixture(scope="module")
def study(tmp_path_factory) -> Path:
    """One video, one trace seen twice: ``NR`` (mitigation none) and ``GR`` (grains at a
    fixed opacity 1, rendered); the study's [render] table says grf."""
    from simulator.synth import SynthConfig, synthesize

    d = tmp_path_factory.mktemp("mit")
    synthesize(SynthConfig("coaster", seconds=1.5, fps=10, size=(256, 128)), d / "clip.mp4")
    save_headpath_csv(d / "P01.csv", synth("look-around", 2.0, rate_hz=30, seed=1))
    (d / "study.toml").write_text(f"""
[study]
name = "mit"
[[videos]]
id = "clip"
path = "clip.mp4"
method = "sphere"
window_size = 64
[[viewings]]
video = "clip"
trace = "P01.csv"
participant = "P01"
condition = "NR"
mitigation = "none"
[[viewings]]
video = "clip"
trace = "P01.csv"
participant = "P01"
condition = "GR"
opacity = 1.0
render = true
[render]
eye_size = "{EYE[0]}x{EYE[1]}"
hfov = 100
vfov = 80
mitigation = "grf"
""")
    assert main(["study", str(d / "study.toml"), "-o", str(d / "out"), "--cache-dir",
                 str(d / "cache"), "--no-progress"]) == 0  # fmt: skip
    return d / "out"


def _rows(out: Path) -> dict[str, dict]:
    with open(out / "viewings.csv", newline="") as f:
        return {r["viewing"]: r for r in csv.DictReader(f)}


def test_viewings_table_and_summary_name_each_mitigation(study):
    rows = _rows(study)
    nr, gr = rows["clip-P01-NR"], rows["clip-P01-GR"]
    assert (nr["mitigation"], gr["mitigation"]) == ("none", "grf")
    assert gr["opacity_rule"] == "fixed 1" and nr["opacity_rule"] not in ("", "fixed 1")
    assert nr["visible_flow_mean_dps"] == ""  # not rendered
    vis = float(gr["visible_flow_mean_dps"])
    assert 0.0 <= vis < float(gr["epof_mean_dps"])  # grains at full opacity hide some flow
    summary = json.loads((study / "render" / "clip-P01-GR" / "summary.json").read_text())
    assert vis == pytest.approx(summary["visible_flow"]["visible_flow_dps_mean"], rel=1e-6)
    report = study / "report"
    table = (report / "viewings.html").read_text()
    for col in ("mitigation", "opacity_rule", "opacity_mean", "visible_flow_mean_dps"):
        assert f"<th>{col}</th>" in table
    assert 'data-filter="mitigation"' in table
    index = (report / "index.html").read_text()
    assert "Conditions x videos" in index
    for cond, mit in (("NR", "none"), ("GR", "grf")):
        assert f'<tr><td>{cond}</td><td><a href="video-clip.html">clip</a></td>' in index
        assert f"<td>1 / 1</td><td>{mit}</td>" in index


def test_replay_settings_follow_the_view():
    base = {"grid": True}
    assert replay_settings({"view": {**base, "mitigation": "none"}})["kind"] == "none"
    assert replay_settings({"view": {**base, "grf": "off"}})["kind"] == "none"
    assert replay_settings({"view": {**base, "mitigation": "grf+vignette", "grf": "off"}})[
        "kind"] == "vignette"  # fmt: skip
    s = replay_settings({"view": {**base, "mitigation": "local-grf", "opacity": 0.4,
                                  "grain_size": 2.0, "seed": 7}})  # fmt: skip
    assert s["kind"] == "grf" and "local-grf" in s["note"] and s["opacity"] == 0.4
    assert (s["grf"]["grain_deg"], s["grf"]["seed"]) == (2.0, 7)
    assert replay_settings({"view": base})["opacity"] is None  # the EPOF CSV's


def _dark_share(img: np.ndarray, ref: np.ndarray) -> float:
    """Share of pixels much darker than the plain view (a grain, black, over the video)."""
    d = ref.astype(np.int16).sum(axis=2) - img.astype(np.int16).sum(axis=2)
    return float(np.mean(d > 150))


@pytest.mark.browser
def test_replay_draws_each_viewings_own_mitigation(browser, study, tmp_path):
    # Times where the study's EPOF opacity is high: grains would show there if drawn.
    from simulator.epof.viewing import read_epof_csv

    e = read_epof_csv(study / "epof" / "clip-P01-NR.csv")
    top = np.argsort(-np.asarray(e.opacity))[:2]
    assert float(np.min(np.asarray(e.opacity)[top])) >= 0.5, e.opacity
    times = sorted(round(float(e.time_s[i]), 3) for i in top)
    fdir = tmp_path / "plain"
    assert main(["frames", str(study / "report" / "media" / "clip.mp4"),
                 str(study.parent / "P01.csv"), "-o", str(fdir), "--at",
                 ",".join(map(str, times)), "--eye-size", f"{EYE[0]}x{EYE[1]}", "--hfov",
                 "100", "--vfov", "80", "--grf", "off", "--no-progress"]) == 0  # fmt: skip
    plain = [np.asarray(Image.open(f).convert("RGB")) for f in sorted(fdir.glob("*.png"))]
    none = browser.replay_at(study / "report", "viewing-clip-P01-NR.html", times)
    grf = browser.replay_at(study / "report", "viewing-clip-P01-GR.html", times)
    shares = [(_dark_share(n, p), _dark_share(g, p)) for n, g, p in zip(none, grf, plain)]
    print(f"\nshare of grain pixels (none, grf) per time: {shares}")
    assert len(shares) == len(times)
    assert all(n < 0.002 and g > 0.05 for n, g in shares), shares
