"""A study of sources that are not equirect (VR180 side by side, EAC) and of a
variable-rate video: the per-video thumbnails and the report's browser copy see each
video as every vimsim command does (converted to equirect, frames at their times)."""

from __future__ import annotations

import json
import subprocess

import numpy as np
import pytest
from PIL import Image

from simulator.cli import main
from simulator.media.source import Source
from simulator.media.video import probe
from simulator.sphere.geometry import extract_view
from simulator.testing.reference import ffmpeg_exe, psnr
from simulator.traces.path import save_headpath_csv, synth


def _ff(*args) -> None:
    subprocess.run([ffmpeg_exe(), "-v", "error", "-y", *map(str, args)], check=True)


@pytest.fixture(scope="module")
def proj_study(tmp_path_factory):
    d = tmp_path_factory.mktemp("projstudy")
    assert main(["synth", str(d / "eq.mp4"), "--scene", "coaster", "--seconds", "1.5", "--fps",
                 "10", "--size", "256x128"]) == 0  # fmt: skip
    _ff("-i", d / "eq.mp4", "-vf", "v360=e:hequirect:w=128:h=128,split[a][b];[a][b]hstack",
        "-c:v", "libx264", "-crf", "12", d / "vr180.mp4")  # fmt: skip
    _ff("-i", d / "eq.mp4", "-vf", "v360=e:eac:w=192:h=128", "-c:v", "libx264", "-crf", "12",
        d / "eac.mp4")  # fmt: skip
    save_headpath_csv(d / "P01.csv", synth("look-around", 2.0, rate_hz=30, seed=1))
    (d / "s.toml").write_text("""
[study]
name = "proj"
[[videos]]
id = "vr"
path = "vr180.mp4"
projection = "hequirect"
layout = "side-by-side"
[[videos]]
id = "cube"
path = "eac.mp4"
projection = "eac"
[[viewings]]
video = "vr"
trace = "P01.csv"
participant = "P01"
condition = "GR"
[[viewings]]
video = "cube"
trace = "P01.csv"
participant = "P01"
condition = "GR"
""")
    return d


def test_study_of_projections_makes_thumbnails_and_equirect_browser_copies(proj_study, capsys):
    d = proj_study
    assert main(["study", str(d / "s.toml"), "-o", str(d / "out"), "--no-progress"]) == 0
    err = capsys.readouterr().err
    assert "expected an equirectangular" not in err, err  # the plots and copies were made
    for vid, path, kw in (("vr", "vr180.mp4", {"projection": "hequirect", "layout": "side-by-side"}),
                          ("cube", "eac.mp4", {"projection": "eac"})):  # fmt: skip
        src = Source.open(d / path, **kw)
        ref = list(src.frames(fmt="rgb24"))  # the equirect working frames
        # thumbnails: the viewport of the moment's frame of the converted video
        mom = (d / "out" / "videos" / vid / "moments.csv").read_text().splitlines()
        head = mom[0].split(",")
        row = dict(zip(head, mom[1].split(",")))
        thumb = np.asarray(Image.open(d / "out" / "videos" / vid / row["thumbnail"]))
        want = extract_view(ref[int(row["frame"])], float(row["yaw_deg"]), float(row["pitch_deg"]),
                            0.0, hfov_deg=107.0, vfov_deg=107.0, size=thumb.shape[1::-1])  # fmt: skip
        np.testing.assert_array_equal(thumb, want)
        # the browser copy: the converted equirect, 2:1, frame for frame
        copy = d / "out" / "report" / "media" / f"{vid}.mp4"
        info = probe(copy)
        assert (info.width, info.height) == ref[0].shape[1::-1] and info.width == 2 * info.height
        got = list(Source.open(copy).frames(fmt="rgb24"))
        assert len(got) == len(ref)
        scores = [psnr(g, r) for g, r in zip(got, ref)]
        assert min(scores) > 30, (vid, scores)  # x264 crf 18 of a sharp synthetic scene
        # not the stored layout stretched to 2:1 (what the replay drew before)
        raw = Source.open(d / path, **kw).frames(fmt="rgb24", convert=False)
        stretched = np.asarray(Image.fromarray(next(raw)).resize(got[0].shape[1::-1]))
        assert psnr(got[0], stretched) < scores[0] - 8, (vid, psnr(got[0], stretched))
    man = json.loads((d / "out" / "report" / ".vimsim-report.json").read_text())
    assert all("re-encoded" in c["copy"]["how"] for c in man["copies"].values())


def test_thumbnail_frames_of_a_variable_rate_video_are_found_by_their_times(tmp_path):
    """Frame i of a variable-rate video is not at i / fps (nor at i over the average
    rate): the seek for a moment's frame goes by the frame times (frames 2-4 and 15-16
    dropped, timestamps kept)."""
    assert main(["synth", str(tmp_path / "c.mp4"), "--scene", "coaster", "--seconds", "3", "--fps",
                 "10", "--size", "128x64"]) == 0  # fmt: skip
    _ff("-i", tmp_path / "c.mp4", "-vf", "select='not(between(n\\,2\\,4)+between(n\\,15\\,16))'", "-fps_mode", "vfr",
        "-c:v", "libx264", "-crf", "10", "-g", "4", tmp_path / "vfr.mp4")  # fmt: skip
    src = Source.open(tmp_path / "vfr.mp4")
    assert src.info.variable_rate
    ref = list(src.frames(fmt="rgb24"))
    want = [1, 3, 7, 12, 18, 24]
    got = dict(src.frames_at(want))
    assert sorted(got) == want
    for f in want:
        np.testing.assert_array_equal(got[f], ref[f])
    # the screen's moments are timed by their frames' timestamps too
    out = tmp_path / "scr"
    assert main(["screen", str(tmp_path / "vfr.mp4"), "-o", str(out), "--viewers", "2",
                 "--no-progress", "--cache-dir", str(tmp_path / "cache")]) == 0  # fmt: skip
    rows = (out / "screen" / "vfr" / "moments.csv").read_text().splitlines()
    head = rows[0].split(",")
    times = src.info.times_s()
    for line in rows[1:]:
        r = dict(zip(head, line.split(",")))
        assert float(r["time_s"]) == pytest.approx(times[int(r["frame"])], abs=1e-6), r


def test_a_still_in_a_study_fails_its_viewings_with_one_line_each(tmp_path, capsys):
    """A still is no video for a study (render and frames take stills as clips): its
    viewings fail naming the file, the study finishes the rest, each line names the video once."""
    from simulator.synth import SynthConfig, synthesize

    Image.fromarray(np.full((64, 128, 3), 90, np.uint8)).save(tmp_path / "pano.png")
    synthesize(SynthConfig("rotate", seconds=1.0, fps=10, size=(128, 64)), tmp_path / "v.mp4")
    save_headpath_csv(tmp_path / "P01.csv", synth("static", 1.5, rate_hz=30))
    (tmp_path / "s.toml").write_text("""
[study]
name = "still"
[[videos]]
id = "pano"
path = "pano.png"
[[videos]]
id = "clip"
path = "v.mp4"
[[viewings]]
video = "pano"
trace = "P01.csv"
participant = "P01"
condition = "GR"
[[viewings]]
video = "clip"
trace = "P01.csv"
participant = "P01"
condition = "GR"
""")
    rc = main(["study", str(tmp_path / "s.toml"), "-o", str(tmp_path / "out"), "--no-progress"])
    assert rc == 3  # some viewings failed
    err = capsys.readouterr().err
    assert "is a still image" in err and "pano.png" in err
    assert "video pano: video pano" not in err
    rows = (tmp_path / "out" / "viewings.csv").read_text()
    assert "clip-P01-GR" in rows and ",ok," in rows
