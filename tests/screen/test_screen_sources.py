"""vimsim screen of a VR180 video (side-by-side half equirect): --projection as every command
takes it; the thumbnails show the converted view and the sphere's flow is the covered
part's."""

from __future__ import annotations

import csv
import subprocess

import numpy as np
from PIL import Image

from simulator.cli import main
from simulator.media.source import Source
from simulator.sphere.geometry import extract_view
from simulator.testing.reference import ffmpeg_exe


def test_screen_of_a_vr180_video(tmp_path, capsys):
    assert main(["synth", str(tmp_path / "eq.mp4"), "--scene", "forward", "--seconds", "1.5",
                 "--fps", "10", "--size", "256x128"]) == 0  # fmt: skip
    subprocess.run([ffmpeg_exe(), "-v", "error", "-y", "-i", str(tmp_path / "eq.mp4"), "-vf",
                    "v360=e:hequirect:w=128:h=128,split[a][b];[a][b]hstack", "-c:v", "libx264",
                    "-crf", "12", str(tmp_path / "vr.mp4")], check=True)  # fmt: skip
    out = tmp_path / "out"
    assert main(["screen", str(tmp_path / "vr.mp4"), "-o", str(out), "--viewers", "3",
                 "--projection", "hequirect", "--layout", "side-by-side", "--no-progress",
                 "--cache-dir", str(tmp_path / "cache")]) == 0  # fmt: skip
    folder = out / "screen" / "vr"
    with open(folder / "moments.csv", newline="") as f:
        mom = list(csv.DictReader(f))
    src = Source.open(tmp_path / "vr.mp4", projection="hequirect", layout="side-by-side")
    ref = list(src.frames(fmt="rgb24"))
    m = mom[0]
    thumb = np.asarray(Image.open(folder / m["thumbnail"]).convert("RGB"))[:240]
    want = extract_view(ref[int(m["frame"])], float(m["yaw_deg"]), float(m["pitch_deg"]), 0.0,
                        hfov_deg=107.0, vfov_deg=107.0, size=(240, 240))  # fmt: skip
    np.testing.assert_array_equal(thumb, want)
    with open(folder / "sphere_flow.csv", newline="") as f:
        sphere = np.array([float(r["sphere_mean_dps"]) for r in csv.DictReader(f)])
    # the covered half's mean: about the equirect source's whole-sphere mean, not half of it
    capsys.readouterr()
    assert main(["screen", str(tmp_path / "eq.mp4"), "-o", str(tmp_path / "eqout"), "--viewers",
                 "3", "--cache-dir", str(tmp_path / "cache")]) == 0  # fmt: skip
    err = capsys.readouterr().err
    assert "task/s" not in err and "%|" not in err, err  # no progress bar off a terminal
    with open(tmp_path / "eqout" / "screen" / "eq" / "sphere_flow.csv", newline="") as f:
        whole = np.array([float(r["sphere_mean_dps"]) for r in csv.DictReader(f)])
    assert 0.7 < np.median(sphere[1:]) / np.median(whole[1:]) < 1.4, (sphere, whole)
