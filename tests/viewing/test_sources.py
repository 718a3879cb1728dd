"""Every source a lab shoots through the CLI: projections, stills as clips, URLs, bad input."""

from __future__ import annotations

import itertools
import json

import numpy as np
import pytest
from PIL import Image

from simulator.cli import main
from simulator.media.source import Source
from simulator.media.video import iter_frames
from simulator.sphere.geometry import equirect_pixel_lonlat, lonlat_to_dir
from simulator.testing.reference import v360_convert
from simulator.traces.path import save_headpath_csv, synth


def _smooth(w=256, h=128):
    lon, lat = equirect_pixel_lonlat(w, h)
    d = lonlat_to_dir(lon[None, :], lat[:, None])
    ch = [d[..., 0] * 0.8 + d[..., 1] * 0.3, d[..., 2] * 0.9 - d[..., 0] * d[..., 1], d[..., 1]]
    return np.stack([np.clip(127.5 + 120 * c, 0, 255) for c in ch], -1).astype(np.uint8)


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    tmp_path = tmp_path_factory.mktemp("sources")
    E = _smooth()
    Image.fromarray(E).save(tmp_path / "e.png")
    Image.fromarray(v360_convert(E, "eac", (192, 128))).save(tmp_path / "eac.png")
    Image.fromarray(v360_convert(E, "hequirect", (128, 128))).save(tmp_path / "h.png")
    save_headpath_csv(tmp_path / "p.csv", synth("sweep", 3.0, rate_hz=30.0))
    return tmp_path


def test_viewport_of_a_projection_matches_the_equirect(files):
    for src, extra in (("e.png", []), ("eac.png", ["--projection", "eac"])):
        args = ["viewport", str(files / src), "-o", str(files / f"{src}.v.png"), "--yaw", "30"]
        assert main([*args, "--pitch", "20", "--size", "64x64", *extra]) == 0
    a, b = (np.asarray(Image.open(files / f"{s}.v.png"), float) for s in ("e.png", "eac.png"))
    assert 10 * np.log10(255**2 / ((a - b) ** 2).mean()) > 35


def test_render_and_frames_take_a_still_as_a_clip(ctx, files):
    out = files / "r"
    common = ["--opacity", "0.5", "--eye-size", "32x32", "--no-progress"]
    assert main(["render", str(files / "e.png"), str(files / "p.csv"), "-o", str(out), *common,
                 "--seconds", "1", "--fps", "4"]) == 0  # fmt: skip
    drawn = list(iter_frames(out / "left.mp4"))
    assert len(drawn) == 4
    # uploaded once, drawn at every pose: the sweep turns the view from frame to frame
    assert min(np.abs(a.astype(int) - b).mean() for a, b in itertools.pairwise(drawn)) > 2
    src = Source.open(files / "e.png", still=(1.0, 4.0))
    made = list(src.eye_frames())
    assert len(made) == 4 and all(m is made[0] for m in made)  # one decode, no copy per frame
    assert not made[0][0].flags.writeable
    s = json.loads((out / "summary.json").read_text())
    assert s["fps"] == 4 and s["frames_written"] == 4
    fr = files / "f"
    assert main(["frames", str(files / "h.png"), str(files / "p.csv"), "-o", str(fr), *common,
                 "--at", "0.5,1.5", "--projection", "hequirect", "--right", str(files / "h.png"),
                 "--seconds", "2"]) == 0  # fmt: skip
    idx = json.loads((fr / "frames.json").read_text())
    assert idx["projection"] == "hequirect" and len(idx["frames"]) == 4  # 2 moments x 2 eyes
    img = np.asarray(Image.open(fr / idx["frames"][0]["file"]))
    assert img.mean() > 20  # the front half is covered: the view is not black


@pytest.mark.parametrize(
    "args,word",
    [
        (["render", "{d}/e.png", "{d}/p.csv", "-o", "{d}/o", "--opacity", "0.5", "--seconds", "0"],
         "--seconds must be > 0"),
        (["preprocess", "{d}/e.png", "-o", "{d}/g.npz"], "still image"),
        (["viewport", "{d}/e.png", "-o", "{d}/v.png", "--yaw", "0", "--pitch", "0",
          "--projection", "dfisheye", "--lens-fov", "400"], "--lens-fov must be in (180, 360)"),
        (["viewport", "{d}/h.png", "-o", "{d}/v.png", "--yaw", "0", "--pitch", "0",
          "--projection", "c3x2"], "--projection c3x2: a c3x2 frame is 3 x 2 square faces"),
        (["viewport", "http://example.org/x.mp4", "-o", "{d}/v.png", "--yaw", "0", "--pitch", "0"],
         "a URL; vimsim reads local video files only: download it first"),
        (["frames", "{d}/e.png", "{d}/p.csv", "-o", "{d}/o", "--at", "1", "--opacity", "0.5",
          "--right", "{d}/eac.png"], "expected an equirect"),
    ],
)  # fmt: skip
def test_bad_source_input_one_line_exit_2_nothing_written(files, capsys, args, word):
    before = sorted(p.name for p in files.iterdir())
    assert main([a.replace("{d}", str(files)) for a in args]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and word in err[0], err
    assert sorted(p.name for p in files.iterdir()) == before


def _ffmpeg(*args):
    import subprocess

    from simulator.testing.reference import ffmpeg_exe

    subprocess.run([ffmpeg_exe(), "-v", "error", "-y", *args], check=True)


def test_spherical_metadata_gives_the_layout_and_an_option_wins_with_a_note(tmp_path, capsys):
    from simulator.media.source import Source
    from simulator.media.spherical import parse_report

    p = tmp_path / "sbs.mkv"
    _ffmpeg("-f", "lavfi", "-i", "testsrc2=size=256x128:rate=10", "-t", "0.3", "-c:v", "libx264",
            "-metadata:s:v:0", "stereo_mode=left_right", str(p))  # fmt: skip
    s = Source.open(p)
    assert (
        s.layout == "side-by-side"
        and s.settings()["spherical_metadata"]["layout"] == "side-by-side"
    )
    args = ["viewport", str(p), "-o", str(tmp_path / "v.png"), "--yaw", "0", "--pitch", "0"]
    assert main([*args, "--layout", "mono", "--size", "32x32"]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "says layout side-by-side; --layout mono wins" in err[0]
    # what FFmpeg reports for sv3d / st3d boxes (MP4)
    md = parse_report("    Side data:\n      spherical: half equirectangular (15.0/-2.5/0.0)\n"
                      "      stereo3d: side by side, view: packed")  # fmt: skip
    assert md["projection"] == "hequirect" and md["layout"] == "side-by-side"
    assert md["orientation_deg"] == [15.0, -2.5, 0.0]


@pytest.mark.parametrize(
    "name, codec",
    [
        ("h10.mp4", ["-c:v", "libx265", "-x265-params", "log-level=error"]),  # HEVC Main10
        ("vp9.webm", ["-c:v", "libvpx-vp9", "-profile:v", "2"]),  # VP9 profile 2
        ("av1.mp4", ["-c:v", "libaom-av1", "-cpu-used", "8"]),  # AV1 10-bit
    ],
)
def test_10bit_sources_decode_and_the_summary_records_it(ctx, tmp_path, name, codec):
    p = tmp_path / name
    _ffmpeg("-f", "lavfi", "-i", "testsrc2=size=128x64:rate=10", "-t", "0.5", *codec,
            "-pix_fmt", "yuv420p10le", str(p))  # fmt: skip
    save_headpath_csv(tmp_path / "p.csv", synth("static", 1.0, rate_hz=30.0))
    out = tmp_path / "r"
    assert main(["render", str(p), str(tmp_path / "p.csv"), "-o", str(out), "--opacity", "0.5",
                 "--eye-size", "32x32", "--no-progress"]) == 0  # fmt: skip
    s = json.loads((out / "summary.json").read_text())
    assert s["source"]["bit_depth"] == 10 and s["source"]["pix_fmt"] == "yuv420p10le"
    assert s["frames_written"] == 5
