"""The report's replay of a video stream that starts after its container's start (1 s after
its audio, as a real 4K HEVC clip here does): the EPOF rows and head paths are on the
player's clock, so the replay must show the frame of that clock, whether the browser copy
is the source itself (H.264 MP4: it keeps its timestamps) or a re-encoding (another codec:
it starts at 0, and the page says by how much to shift it)."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import imageio_ffmpeg
import numpy as np
import pytest
from PIL import Image

from simulator.cli import main
from simulator.media.video import probe
from simulator.testing.reference import psnr
from simulator.traces.path import save_headpath_csv, synth

EYE = (160, 120)
LATE_S = 1.0
CODECS = {"h264": ["-c:v", "libx264", "-pix_fmt", "yuv420p"], "mpeg4": ["-c:v", "mpeg4", "-q:v", "2"]}


def _ff(*args) -> None:
    subprocess.run([imageio_ffmpeg.get_ffmpeg_exe(), "-v", "error", "-y", *map(str, args)],
                   check=True)  # fmt: skip


@pytest.fixture(scope="module")
def late_study(tmp_path_factory) -> Path:
    from simulator.synth import SynthConfig, synthesize

    d = tmp_path_factory.mktemp("late")
    synthesize(SynthConfig("coaster", seconds=3.0, fps=10, size=(256, 128)), d / "full.mp4")
    for name, codec in CODECS.items():
        # the video encoded with 1 s of silence before it: its first frame at 1.0 s
        _ff("-i", d / "full.mp4", "-f", "lavfi", "-t", "4", "-i", "anullsrc=r=8000:cl=mono",
            *codec, "-an", d / f"v-{name}.mp4")  # fmt: skip
        _ff("-i", d / f"v-{name}.mp4", "-itsoffset", LATE_S, "-i", d / f"v-{name}.mp4", "-f",
            "lavfi", "-t", "4", "-i", "anullsrc=r=8000:cl=mono", "-map", "1:v", "-map", "2:a",
            "-c:v", "copy", "-c:a", "aac", d / f"{name}.mp4")  # fmt: skip
        assert probe(d / f"{name}.mp4").times_s([0])[0] == pytest.approx(LATE_S, abs=0.02)
    save_headpath_csv(d / "P01.csv", synth("look-around", 4.5, rate_hz=30, seed=0))
    videos = "".join(f"""
[[videos]]
id = "{n}"
path = "{n}.mp4"
method = "sphere"
window_size = 64
[[viewings]]
video = "{n}"
trace = "P01.csv"
participant = "P01"
condition = "GR"
""" for n in CODECS)  # fmt: skip
    (d / "study.toml").write_text(f"""
[study]
name = "late"
{videos}
[render]
eye_size = "{EYE[0]}x{EYE[1]}"
hfov = 100
vfov = 80
""")
    assert main(["study", str(d / "study.toml"), "-o", str(d / "out"), "--cache-dir",
                 str(d / "cache"), "--no-progress"]) == 0  # fmt: skip
    return d


def test_browser_copy_says_where_a_late_source_starts(late_study):
    copies = json.loads((late_study / "out" / "report" / ".vimsim-report.json").read_text())["copies"]
    assert "copy of the source" in copies["h264"]["copy"]["how"]
    assert copies["h264"]["copy"]["start_s"] == 0.0
    assert "re-encoded" in copies["mpeg4"]["copy"]["how"]
    assert copies["mpeg4"]["copy"]["start_s"] == pytest.approx(LATE_S, abs=0.02)
    # the re-encoding itself starts at 0; its page carries the shift
    assert probe(late_study / "out" / "report" / "media" / "mpeg4.mp4").times_s([0])[0] == 0.0
    page = (late_study / "out" / "report" / "viewing-mpeg4-P01-GR.html").read_text()
    assert '"media_start_s":1.0' in page.replace(" ", "")


@pytest.mark.browser
def test_replay_of_a_late_source_shows_the_frame_of_the_players_clock(browser, late_study, tmp_path):
    """Replay after a seek vs ``vimsim frames`` of the *source* at the same times (the
    player's clock); a replay one second off (the copy's own clock) would show frames 10
    apart of a moving scene, far below the bar (checked against the source at t - 1 s)."""
    report = late_study / "out" / "report"
    times = [1.25, 2.05, 2.85]
    got = {name: browser.replay_at(report, f"viewing-{name}-P01-GR.html", times)
           for name in CODECS}  # fmt: skip
    for name in CODECS:
        src = late_study / f"{name}.mp4"
        epof = late_study / "out" / "epof" / f"{name}-P01-GR.csv"
        refs = {}
        for shift in (0.0, LATE_S):  # LATE_S: the copy's own clock, the replay without the shift
            fdir = tmp_path / f"{name}{shift:g}"
            assert main(["frames", str(src), str(late_study / "P01.csv"), "-o", str(fdir), "--at",
                         ",".join(f"{t + shift:g}" for t in times), "--eye-size",
                         f"{EYE[0]}x{EYE[1]}", "--hfov", "100", "--vfov", "80", "--opacity",
                         str(epof), "--grf", "on", "--no-progress"]) == 0  # fmt: skip
            refs[shift] = [np.asarray(Image.open(f).convert("RGB")) for f in sorted(fdir.glob("*.png"))]
        scores = [(psnr(g, r), psnr(g, w))
                  for g, r, w in zip(got[name], refs[0.0], refs[LATE_S])]  # fmt: skip
        print(f"\n{name}: replay vs the source's frame, and vs the frame 1 s later (PSNR dB): {scores}")
        assert len(scores) == len(times)
        assert all(ok >= 30.0 and off < 25.0 for ok, off in scores), (name, scores)
