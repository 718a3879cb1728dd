"""``vimsim viewport``: outputs and every kind of bad input (exit 2, one line, no file)."""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

from simulator.cli import main
from simulator.sphere import geometry


@pytest.fixture()
def pano(tmp_path):
    """A 256x128 mono equirect PNG with a smooth pattern."""
    lon, lat = geometry.equirect_pixel_lonlat(256, 128)
    img = np.stack(
        [
            127 + 100 * np.sin(3 * lon)[None, :] * np.cos(lat)[:, None],
            127 + 100 * np.sin(2 * lat)[:, None] * np.ones((1, 256)),
            np.full((128, 256), 60.0),
        ],
        axis=-1,
    ).astype(np.uint8)
    p = tmp_path / "pano.png"
    Image.fromarray(img).save(p)
    return p, img


def _run(capsys, argv):
    """Exit status and stderr; argparse usage errors exit via SystemExit(2)."""
    try:
        rc = main(argv)
    except SystemExit as e:
        rc = e.code
    return rc, capsys.readouterr().err


def test_writes_view_equal_to_extract_view(pano, tmp_path, capsys):
    src, img = pano
    out = tmp_path / "v.png"
    rc, err = _run(capsys, ["viewport", str(src), "-o", str(out), "--yaw", "30", "--pitch", "-10",
                            "--roll", "5", "--hfov", "90", "--vfov", "60", "--size", "64x48"])  # fmt: skip
    assert rc == 0 and err == ""
    got = np.asarray(Image.open(out))
    want = geometry.extract_view(img, 30, -10, 5, hfov_deg=90, vfov_deg=60, size=(64, 48))
    assert got.shape == (48, 64, 3)
    assert np.array_equal(got, want)
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []  # no temp left


def test_default_size_and_stereo_eye(tmp_path, capsys):
    rng = np.random.default_rng(3)
    top = (rng.random((64, 128, 3)) * 255).astype(np.uint8)
    bottom = 255 - top
    src = tmp_path / "tb.png"
    Image.fromarray(np.concatenate([top, bottom])).save(src)  # 128x128: top-bottom stereo
    outs = {}
    for eye in ("left", "right"):
        out = tmp_path / f"{eye}.png"
        rc, _ = _run(capsys, ["viewport", str(src), "-o", str(out), "--yaw", "0", "--pitch", "0",
                              "--layout", "top-bottom", "--eye", eye, "--fov", "60"])  # fmt: skip
        assert rc == 0
        outs[eye] = np.asarray(Image.open(out))
    assert outs["left"].shape == (512, 512, 3)  # default preview size
    want = geometry.extract_view(top, 0, 0, hfov_deg=60, size=(512, 512))
    assert np.array_equal(outs["left"], want)  # left eye = top half
    assert not np.array_equal(outs["left"], outs["right"])


def test_video_frame(real_dir, tmp_path, capsys):
    out = tmp_path / "f.png"
    src = real_dir / "equirect" / "threejs" / "pano.mp4"  # 1920x1080 stored, SAR 9:8 = 2:1
    rc, err = _run(capsys, ["viewport", str(src), "-o", str(out), "--yaw", "-90", "--pitch", "0",
                            "--frame", "3", "--size", "32x32"])  # fmt: skip
    assert rc == 0, err
    assert np.asarray(Image.open(out)).shape == (32, 32, 3)


def _bad(capsys, tmp_path, argv, pattern):
    out = tmp_path / "bad.png"
    rc, err = _run(capsys, ["viewport", *argv[:1], "-o", str(out), *argv[1:]])
    assert rc == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and pattern in lines[0], err
    assert not out.exists()
    assert list(tmp_path.glob(".bad*")) == []
    return lines[0]


def test_bad_inputs(pano, tmp_path, capsys):
    src, _ = pano
    yp = ["--yaw", "0", "--pitch", "0"]
    line = _bad(capsys, tmp_path, [str(tmp_path / "missing.jpg"), *yp], "not found")
    assert "missing.jpg" in line
    junk = tmp_path / "junk.png"
    junk.write_bytes(b"this is not an image")
    assert "junk.png" in _bad(capsys, tmp_path, [str(junk), *yp], "not a readable")
    txt = tmp_path / "notes.txt"
    txt.write_text("hello\n")
    assert "notes.txt" in _bad(capsys, tmp_path, [str(txt), *yp], "not a readable")
    wide = tmp_path / "wide.png"
    Image.fromarray(np.zeros((90, 160, 3), np.uint8)).save(wide)  # 16:9
    assert "wide.png" in _bad(capsys, tmp_path, [str(wide), *yp], "2:1")
    four = tmp_path / "four.png"
    Image.fromarray(np.zeros((64, 256, 3), np.uint8)).save(four)  # 4:1 is not top-bottom
    assert "four.png" in _bad(
        capsys, tmp_path, [str(four), *yp, "--layout", "top-bottom"], "layout top-bottom"
    )
    odd = tmp_path / "odd.png"
    Image.fromarray(np.zeros((129, 256, 3), np.uint8)).save(odd)
    assert "odd.png" in _bad(
        capsys, tmp_path, [str(odd), *yp, "--layout", "top-bottom"], "even height"
    )
    _bad(capsys, tmp_path, [str(src), *yp, "--fov", "180"], "FOV must be degrees in (0, 180)")
    _bad(capsys, tmp_path, [str(src), *yp, "--fov", "0"], "FOV must be degrees in (0, 180)")
    _bad(capsys, tmp_path, [str(src), *yp, "--hfov", "-5", "--vfov", "90"], "FOV must be")
    _bad(capsys, tmp_path, [str(src), *yp, "--vfov", "90"], "--vfov needs --hfov")
    _bad(
        capsys,
        tmp_path,
        [str(src), *yp, "--fov", "90", "--hfov", "90", "--vfov", "90"],
        "give only one of --fov, --hfov/--vfov",
    )
    _bad(capsys, tmp_path, [str(src), *yp, "--size", "640"], "WxH")
    _bad(capsys, tmp_path, [str(src), *yp, "--size", "0x10"], "size must be")
    _bad(capsys, tmp_path, [str(src), *yp, "--frame", "1"], "only frame 0")
    _bad(capsys, tmp_path, [str(src), "--yaw", "abc", "--pitch", "0"], "angle in degrees")
    _bad(capsys, tmp_path, [str(src), "--yaw", "nan", "--pitch", "0"], "finite angle")


def test_bad_output_dir(pano, tmp_path, capsys):
    src, _ = pano
    out = tmp_path / "no" / "such" / "dir.png"
    rc, err = _run(capsys, ["viewport", str(src), "-o", str(out), "--yaw", "0", "--pitch", "0"])
    assert rc == 2 and "does not exist" in err and len(err.strip().splitlines()) == 1
