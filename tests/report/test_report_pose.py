"""The report's replay of a video whose spherical metadata carries an initial orientation
(sv3d ``prhd``): the head paths are vimsim's (head 0/0/0 looks at the pose), so the replay
draws the browser copy (the frame as stored) at the view's angles, as ``vimsim frames`` of
the source does."""

from __future__ import annotations

import numpy as np
import pytest
from media_helpers import with_pose
from PIL import Image

from simulator.cli import main
from simulator.testing.reference import psnr
from simulator.traces.path import save_headpath_csv, synth

EYE = (160, 120)


@pytest.mark.browser
def test_replay_of_a_posed_video_matches_vimsim_frames(browser, tmp_path):
    assert main(["synth", str(tmp_path / "plain.mp4"), "--scene", "coaster", "--seconds", "2",
                 "--fps", "10", "--size", "256x128"]) == 0  # fmt: skip
    with_pose(tmp_path / "plain.mp4", tmp_path / "posed.mp4", 100.0, 15.0, 0.0)
    save_headpath_csv(tmp_path / "P01.csv", synth("look-around", 2.5, rate_hz=30, seed=3))
    (tmp_path / "s.toml").write_text(f"""
[study]
name = "pose"
[[videos]]
id = "posed"
path = "posed.mp4"
[[viewings]]
video = "posed"
trace = "P01.csv"
participant = "P01"
condition = "GR"
[render]
eye_size = "{EYE[0]}x{EYE[1]}"
hfov = 100
vfov = 80
""")
    out = tmp_path / "out"
    assert main(["study", str(tmp_path / "s.toml"), "-o", str(out), "--no-progress"]) == 0
    times = [0.35, 1.05, 1.75]
    refs = {}
    for name, extra in (("pose", []), ("nopose", ["--ignore-orientation"])):
        fdir = tmp_path / name
        assert main(["frames", str(tmp_path / "posed.mp4"), str(tmp_path / "P01.csv"), "-o",
                     str(fdir), "--at", ",".join(map(str, times)), "--eye-size",
                     f"{EYE[0]}x{EYE[1]}", "--hfov", "100", "--vfov", "80", "--opacity",
                     str(out / "epof" / "posed-P01-GR.csv"), "--grf", "on", "--no-progress",
                     *extra]) == 0  # fmt: skip
        refs[name] = [np.asarray(Image.open(f).convert("RGB")) for f in sorted(fdir.glob("*.png"))]
    got = browser.replay_at(out / "report", "viewing-posed-P01-GR.html", times)
    scores = [(psnr(g, a), psnr(g, b)) for g, a, b in zip(got, refs["pose"], refs["nopose"])]
    print(f"\nreplay vs vimsim frames with / without the pose (PSNR dB): {scores}")
    assert len(scores) == len(times)
    assert all(ok >= 30.0 and ok > off + 8 for ok, off in scores), scores
