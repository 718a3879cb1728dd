"""Stereo eye order from the file's metadata: Matroska's ``bottom_top`` / ``right_left``
(FFmpeg's "(inverted)" stereo3d flag) store the right eye first; each eye is then read
from its own half, with a note, and outputs record the order."""

from __future__ import annotations

import subprocess

import numpy as np
import pytest
from media_helpers import write_clip

from simulator.cli import main
from simulator.media.source import Source
from simulator.media.spherical import parse_report
from simulator.testing.reference import ffmpeg_exe


def _stereo(tmp_path, mode: str, size=(256, 128)):
    """A stereo clip whose right eye is bright (200) and left eye dark (40), stored right
    eye first, tagged with Matroska's ``stereo_mode``."""
    w, h = size
    f = np.full((h, w, 3), 40, np.uint8)
    if mode == "bottom_top":
        f[: h // 2] = 200  # right eye on top
    else:
        f[:, : w // 2] = 200  # right eye on the left
    plain = write_clip(tmp_path / f"{mode}.mp4", [f] * 3, 10.0)
    out = tmp_path / f"{mode}.mkv"
    subprocess.run([ffmpeg_exe(), "-v", "error", "-y", "-i", str(plain), "-c", "copy",
                    "-metadata:s:v", f"stereo_mode={mode}", str(out)], check=True)  # fmt: skip
    return out


def test_ffmpeg_report_inverted_flag_is_read():
    text = "Side data:\n      Stereo 3D: top and bottom, view: packed, primary eye: none (inverted)\n"
    assert parse_report(text)["layout"] == "top-bottom"
    assert parse_report(text)["eye_order"] == "right-first"
    plain = "Side data:\n      Stereo 3D: side by side, view: packed, primary eye: none\n"
    assert parse_report(plain)["eye_order"] == "left-first"
    assert parse_report("")["eye_order"] is None


@pytest.mark.parametrize("mode, layout", [("bottom_top", "top-bottom"), ("right_left", "side-by-side")])
def test_right_eye_first_is_read_from_its_own_half(tmp_path, mode, layout):
    src = Source.open(_stereo(tmp_path, mode, (256, 128)))  # squeezed eyes: the frame 2:1
    assert src.layout == layout and src.right_first
    assert src.settings()["eye_order"] == "right-first"
    assert any("right eye first" in n for n in src.notes)
    left = src.read(0, eye="left")
    right = src.read(0, eye="right")
    assert abs(float(left.mean()) - 40) < 6 and abs(float(right.mean()) - 200) < 6
    # an explicit other layout ignores the file's order (the frame is 2:1: mono fits too)
    other = Source.open(src.path, layout="mono")
    assert not other.right_first and other.settings()["eye_order"] is None


def test_viewport_cli_shows_the_left_eye(tmp_path):
    from PIL import Image

    p = _stereo(tmp_path, "bottom_top")
    assert main(["viewport", str(p), "-o", str(tmp_path / "v.png"), "--yaw", "0", "--pitch", "0",
                 "--size", "32x32"]) == 0  # fmt: skip
    v = np.asarray(Image.open(tmp_path / "v.png"), float)
    assert abs(v.mean() - 40) < 8  # the dark left eye, stored in the bottom half
