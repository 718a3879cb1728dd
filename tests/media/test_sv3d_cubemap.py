"""An EAC file tagged with the Spherical Video V2 ``sv3d`` cubemap box (``cbmp``, as YouTube
and 360 cameras tag it) is read as ``eac`` without ``--projection``."""

from __future__ import annotations

import numpy as np
import pytest
from media_helpers import noise_frames, with_pose, write_clip
from PIL import Image

from simulator.cli import main
from simulator.media.spherical import parse_report, read_spherical


@pytest.mark.parametrize(
    ("line", "projection", "pose"),
    [
        ("Spherical Mapping: cubemap [pad 0] ", "eac", None),
        ("Spherical Mapping: cubemap (10.000000/-5.000000/0.000000) [pad 0] ", "eac", [10, -5, 0]),
        ("Spherical Mapping: equirectangular (30.000000/0.000000/0.000000) ", "equirect", [30, 0, 0]),
        ("Spherical Mapping: equirectangular \n  Stream #0:1: Audio: aac 1/2/3", "equirect", None),
    ],
)
def test_parse_report_reads_cubemap_and_pose(line, projection, pose):
    md = parse_report(f"    Side data:\n      {line}\n")
    assert md["projection"] == projection and md["orientation_deg"] == pose


def test_cbmp_tagged_file_works_without_projection(tmp_path, capsys):
    write_clip(tmp_path / "c.mp4", noise_frames(3, size=(96, 64)), fps=10)
    with_pose(tmp_path / "c.mp4", tmp_path / "eac.mp4", 0.0, projection="cbmp")
    assert read_spherical(str(tmp_path / "eac.mp4"))["projection"] == "eac"
    view = ["viewport", "--yaw", "20", "--pitch", "10", "--size", "32x32"]
    assert main([view[0], str(tmp_path / "eac.mp4"), *view[1:], "-o", str(tmp_path / "a.png")]) == 0
    assert main([view[0], str(tmp_path / "c.mp4"), *view[1:], "-o", str(tmp_path / "b.png"),
                 "--projection", "eac"]) == 0  # fmt: skip
    a, b = (np.asarray(Image.open(tmp_path / n)) for n in ("a.png", "b.png"))
    assert np.array_equal(a, b)  # the tag read as the option says
