"""The web export's example.html plays the grid's real video over loopback (a video frame on
the sphere, not a grey scene); the CLI copies the grid's own video in by default."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from browser_support import data_url_image
from PIL import Image

from simulator.cli import main


@pytest.fixture(scope="module")
def export(tmp_path_factory):
    from simulator.synth import SynthConfig, synthesize

    d = tmp_path_factory.mktemp("webvid")
    synthesize(SynthConfig("coaster", seconds=1.0, fps=10, size=(256, 128)), d / "clip.mp4")
    assert main(["preprocess", str(d / "clip.mp4"), "-o", str(d / "g.npz"), "--method", "sphere",
                 "--window-size", "32", "--no-progress"]) == 0  # fmt: skip
    assert main(["export", str(d / "g.npz"), "-o", str(d / "web"), "--format", "web"]) == 0
    return d


def test_cli_copies_the_grids_video(export, tmp_path, capsys):
    web = export / "web"
    m = json.loads((web / "vimsim_web.json").read_text())
    assert m["video"] == "video.mp4"
    assert (web / "video.mp4").read_bytes() == (export / "clip.mp4").read_bytes()
    # --video naming another video than the grid's: refused, one line, nothing written.
    other = tmp_path / "other.mp4"
    from simulator.synth import SynthConfig, synthesize

    synthesize(SynthConfig("coaster", seconds=0.5, fps=10, size=(256, 128)), other)
    capsys.readouterr()
    assert main(["export", str(export / "g.npz"), "-o", str(tmp_path / "w"), "--format", "web",
                 "--video", str(other)]) == 2  # fmt: skip
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "other" in err and not (tmp_path / "w").exists()
    assert main(["export", str(export / "g.npz"), "-o", str(tmp_path / "u"), "--video",
                 str(other)]) == 2  # fmt: skip
    assert "--format web" in capsys.readouterr().err


@pytest.mark.browser
def test_example_plays_the_real_video(browser, export, tmp_path):
    got = browser.run_served(
        export / "web",
        "example.html",
        """
        for (let i = 0; i < 600 && !(window.vimsimExample && window.vimsimExample.ready); i++) {
          const n = document.getElementById('note').textContent;
          if (n) return {note: n};
          await new Promise((r) => setTimeout(r, 50));
        }
        const ex = window.vimsimExample;
        await ex.seek(0.55);
        return {png: ex.canvas.toDataURL('image/png'), drawn: ex.drawn, video: !!ex.video,
                videoNote: document.getElementById('videonote').textContent};""",
    )
    assert "png" in got, got
    img = data_url_image(got["png"]).astype(np.int16)
    grey = np.all(np.abs(img - 120) <= 2, axis=2).mean()  # the page's clear colour, 0.47
    print(f"\nexample.html: std {img.std():.1f}, grey share {grey:.3f}")
    assert got["video"] and got["videoNote"] == "" and got["drawn"] >= 2
    assert img.std() > 10 and grey < 0.05, (img.std(), grey)
    # The frame drawn is the video's frame at 0.55 s (frame 5 at 10 fps), as vimsim viewport
    # draws it: compared inside the grains' clear centre (18 deg: 87 px at this focal length).
    vfov = 2 * math.degrees(math.atan(math.tan(math.radians(50)) * 360 / 640))
    ref_png = tmp_path / "ref.png"
    assert main(["viewport", str(export / "clip.mp4"), "-o", str(ref_png), "--frame", "5",
                 "--yaw", "0", "--pitch", "0", "--hfov", "100", "--vfov", f"{vfov:.6f}",
                 "--size", "640x360"]) == 0  # fmt: skip
    ref = np.asarray(Image.open(ref_png).convert("L"), np.float64)
    c = (slice(120, 240), slice(260, 380))
    mad = float(np.abs(ref[c] - img.mean(axis=2)[c]).mean())
    corr = float(np.corrcoef(ref[c].ravel(), img.mean(axis=2)[c].ravel())[0, 1])
    print(f"centre vs vimsim viewport of frame 5: correlation {corr:.3f}, MAD {mad:.1f}")
    assert corr > 0.9 and mad < 10, (corr, mad)
