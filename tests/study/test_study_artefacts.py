"""A study whose video has a hard cut: the cut's frames are left out of its provocative moments."""

from __future__ import annotations

import json

import numpy as np
import pytest
from media_helpers import cut_clip as make_cut_clip

from simulator.cli import main


@pytest.fixture(scope="module")
def cut_clip(tmp_path_factory):
    """A calm rotating clip with a hard cut at frame 10 to a slow walk through another scene
    (as tests/screen, but calm on both sides: the cut's own frame is the hottest)."""
    from simulator.synth import SynthConfig, synthesize

    d = tmp_path_factory.mktemp("cutstudy")
    synthesize(
        SynthConfig("rotate", seconds=2.0, fps=10, size=(128, 64), omega_dps=3.0), d / "calm.mp4"
    )
    synthesize(SynthConfig("forward", seconds=2.0, fps=10, size=(128, 64), speed_mps=0.05),
               d / "ride.mp4")  # fmt: skip
    return make_cut_clip(d / "calm.mp4", d / "ride.mp4", d / "cut.mp4")


def test_provocative_moments_exclude_rows():
    from simulator.study.outputs import provocative_moments

    m = np.ones((20, 4))
    m[10, 2] = 100.0  # the cut: by far the largest
    yaw = np.array([-135.0, -45.0, 45.0, 135.0])
    assert provocative_moments(m, yaw, 10.0, n=1)[0]["frame"] == 10
    bad = np.zeros(20, bool)
    bad[10] = True
    got = provocative_moments(m, yaw, 10.0, n=100, exclude=bad)
    assert got and all(mo["frame"] != 10 for mo in got)
    assert len(got) <= 19 * 4  # never an excluded (-inf) entry as a filler
    assert provocative_moments(m, yaw, 10.0, exclude=np.ones(20, bool)) == []


def test_study_moments_leave_out_artefacts(cut_clip, tmp_path):
    m = tmp_path / "s.toml"
    m.write_text(f'[[videos]]\nid = "cut"\npath = "{cut_clip}"\nmethod = "sphere"\n\n'
                 '[[viewings]]\nvideo = "cut"\nviewers = { n = 2, seed = 3 }\n')  # fmt: skip
    out = tmp_path / "o"  # artefacts detected by default (issue 37)
    assert main(["study", str(m), "-o", str(out), "--cache-dir", str(tmp_path / "c"),
                 "--workers", "1", "--no-progress"]) == 0  # fmt: skip
    s = json.loads((out / "study.json").read_text())
    made = s["outputs"]["videos"]["cut"]
    assert made["artefact_frames_left_out"] >= 1 and made["artefact_kinds"].get("cut") == 1
    rows = (out / "videos" / "cut" / "moments.csv").read_text().splitlines()
    frames = [int(r.split(",")[2]) for r in rows[1:]]
    assert frames and 10 not in frames  # the cut (the hottest frame) never ranked
    # The report's video page says how many frames were left out (vimsim report).
    assert main(["report", str(out)]) == 0
    page = next((out / "report").glob("video*cut*.html")).read_text()
    assert "frames left out as artefacts (cut: 1)" in page
    # The summary names the opacity rule: the default, absolute (issue 37).
    assert "GRF opacity rule absolute 5-30 deg/s" in (out / "report" / "index.html").read_text()
    # --no-artefacts: every frame kept (the cached grid reused), the cut ranked again.
    off = tmp_path / "off"
    assert main(["study", str(m), "-o", str(off), "--cache-dir", str(tmp_path / "c"),
                 "--workers", "1", "--no-progress", "--no-report", "--no-artefacts"]) == 0  # fmt: skip
    s = json.loads((off / "study.json").read_text())
    assert s["outputs"]["videos"]["cut"]["artefact_frames_left_out"] == 0
    lines = next((off / "epof").glob("*.csv")).read_text().splitlines()
    header = next(ln for ln in lines if ln[:1] != "#")
    assert "artefact" not in header
    rows = (off / "videos" / "cut" / "moments.csv").read_text().splitlines()
    assert 10 in [int(r.split(",")[2]) for r in rows[1:]]
