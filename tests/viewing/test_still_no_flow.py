"""A still image has no flow: its review says "still image: no flow", not "EPOF nan"."""

from __future__ import annotations

import numpy as np

from simulator.cli import main
from simulator.traces.path import save_headpath_csv, synth
from simulator.viewing import job as job_module
from simulator.viewing.review import STILL_NO_FLOW, ReviewWriter


def _writer(epof, opacity, no_flow):
    w = object.__new__(ReviewWriter)  # only what _numbers reads
    w.epof, w.op, w.opacity_used, w.no_flow = np.asarray(epof), np.asarray(opacity), True, no_flow
    return w


def test_numbers_say_why_there_is_no_flow():
    w = _writer([np.nan, 12.34], [0.5, 0.25], STILL_NO_FLOW)
    assert w._numbers(0) == "still image: no flow  opacity 0.50"
    assert w._numbers(1) == "EPOF 12.3 deg/s  opacity 0.25"
    assert "nan" not in _writer([np.nan], [np.nan], STILL_NO_FLOW)._numbers(0)


def test_render_of_a_still_reviews_without_nan(tmp_path, monkeypatch):
    from PIL import Image

    rng = np.random.default_rng(0)
    Image.fromarray(rng.integers(0, 255, (64, 128, 3), dtype=np.uint8)).save(tmp_path / "pano.png")
    save_headpath_csv(tmp_path / "p.csv", synth("static", 1.0, rate_hz=30.0))
    seen = []

    def recording(*a, **kw):
        seen.append(kw.get("no_flow"))
        return ReviewWriter(*a, **kw)

    monkeypatch.setattr(job_module, "ReviewWriter", recording)
    assert main(["render", str(tmp_path / "pano.png"), str(tmp_path / "p.csv"), "-o",
                 str(tmp_path / "r"), "--eye-size", "32x32", "--seconds", "0.6", "--fps", "5",
                 "--opacity", "0.5", "--review", "--no-progress"]) == 0  # fmt: skip
    assert seen == [STILL_NO_FLOW]
    assert (tmp_path / "r" / "sheet.png").is_file()
