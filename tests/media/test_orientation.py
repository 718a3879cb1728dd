"""The initial orientation of a file's spherical metadata (sv3d ``prhd``) is applied to every view: metadata yaw 90 = head yaw 90."""

from __future__ import annotations

import json

import numpy as np
import pytest
from media_helpers import with_pose
from PIL import Image

from simulator.cli import main
from simulator.epof.viewing import read_epof_csv
from simulator.media.source import Source
from simulator.media.spherical import view_angles_deg
from simulator.traces.path import HeadPath, save_headpath_csv


@pytest.fixture(scope="module")
def clips(tmp_path_factory):
    d = tmp_path_factory.mktemp("pose")
    assert main(["synth", str(d / "plain.mp4"), "--scene", "forward", "--seconds", "0.4", "--fps",
                 "30", "--size", "128x64"]) == 0  # fmt: skip
    with_pose(d / "plain.mp4", d / "yaw90.mp4", 90.0)
    with_pose(d / "plain.mp4", d / "tilted.mp4", 30.0, 20.0, -10.0)
    return d


def test_ffmpeg_reports_the_pose_and_the_source_applies_it_or_not(clips, capsys):
    s = Source.open(clips / "yaw90.mp4")
    assert s.metadata["orientation_deg"] == [90.0, 0.0, 0.0] and s.projection == "equirect"
    assert s.orientation_deg == (90.0, 0.0, 0.0) and s.settings()["orientation_deg"] == [90, 0, 0]
    assert any("initial orientation" in n for n in s.notes)
    off = Source.open(clips / "yaw90.mp4", orientation=False)
    assert off.orientation_deg is None and off.settings()["orientation_ignored"] is True
    assert Source.open(clips / "plain.mp4").settings()["orientation_ignored"] is False
    t = Source.open(clips / "tilted.mp4").orientation_deg
    assert np.allclose(t, (30.0, 20.0, -10.0), atol=1e-3)


def test_view_angles_compose_pose_then_head():
    y, p, r = view_angles_deg((90.0, 0.0, 0.0), [0.0, 100.0], [0.0, 20.0], [0.0, 5.0])
    assert np.allclose(y, [90.0, -170.0]) and np.allclose(p, [0.0, 20.0]) and np.allclose(r, [0, 5])
    # a pitched pose: head yaw 0 looks up by the pose's pitch, then turns about the pose's up
    y, p, r = view_angles_deg((0.0, 30.0, 0.0), 0.0, 0.0, 0.0)
    assert np.allclose([y, p, r], [0.0, 30.0, 0.0])
    assert all(np.array_equal(a, b) for a, b in zip(view_angles_deg(None, 1.0, 2.0, 3.0), (1, 2, 3)))


def _png(path) -> np.ndarray:
    return np.asarray(Image.open(path), float)


@pytest.mark.parametrize(
    "file,head,plain",
    [("yaw90.mp4", (10, 20, 0), (100, 20, 0)), ("tilted.mp4", (0, 0, 0), (30, 20, -10))],
)  # fmt: skip
def test_viewport_metadata_pose_equals_head_pose(clips, tmp_path, file, head, plain):
    def view(src, angles, name, extra=()):
        y, p, r = (str(v) for v in angles)
        assert main(["viewport", str(clips / src), "-o", str(tmp_path / name), "--yaw", y,
                     "--pitch", p, "--roll", r, "--size", "48x48", *extra]) == 0  # fmt: skip
        return _png(tmp_path / name)

    a, b = view(file, head, "a.png"), view("plain.mp4", plain, "b.png")
    assert np.abs(a - b).max() <= 1.0  # the same view (Euler round trip: float rounding)
    c = view(file, head, "c.png", ["--ignore-orientation"])
    assert np.abs(c - view("plain.mp4", head, "d.png")).max() == 0
    assert np.abs(a - c).mean() > 5  # the pose changes the view


def test_epof_and_render_apply_it_and_record_it(ctx, clips, tmp_path):
    hp0 = HeadPath.from_angles_deg([0.0, 1.0], [0.0, 0.0], [0.0, 0.0], [0.0, 0.0])
    hp90 = HeadPath.from_angles_deg([0.0, 1.0], [90.0, 90.0], [0.0, 0.0], [0.0, 0.0])
    save_headpath_csv(tmp_path / "p0.csv", hp0)
    save_headpath_csv(tmp_path / "p90.csv", hp90)
    rows = {}
    for src, path in (("yaw90.mp4", "p0.csv"), ("plain.mp4", "p90.csv"), ("plain.mp4", "p0.csv")):
        g, key = tmp_path / f"{src}.npz", f"{src}-{path}"
        if not g.exists():
            assert main(["preprocess", str(clips / src), "-o", str(g), "--method", "sphere",
                         "--cell", "10", "--no-progress"]) == 0  # fmt: skip
        assert main(["epof", str(g), str(tmp_path / path), "-o", str(tmp_path / f"{key}.csv")]) == 0
        rows[key] = read_epof_csv(tmp_path / f"{key}.csv")
        out = tmp_path / key
        assert main(["render", str(clips / src), str(tmp_path / path), "-o", str(out), "--grid",
                     str(g), "--eye-size", "32x32", "--no-progress", "--no-audio"]) == 0  # fmt: skip
        rows[key + "r"] = read_epof_csv(out / "epof.csv")
        rows[key + "s"] = json.loads((out / "summary.json").read_text())
    a, b, c = rows["yaw90.mp4-p0.csv"], rows["plain.mp4-p90.csv"], rows["plain.mp4-p0.csv"]
    assert np.allclose(a.epof_dps, b.epof_dps) and not np.allclose(a.epof_dps, c.epof_dps, rtol=0.05)
    assert np.allclose(a.yaw_deg, 0.0)  # the head's own angles are recorded
    ra, rb = rows["yaw90.mp4-p0.csvr"], rows["plain.mp4-p90.csvr"]
    assert np.allclose(ra.epof_dps, rb.epof_dps) and np.allclose(ra.yaw_deg, 0.0)
    assert rows["yaw90.mp4-p0.csvs"]["source"]["orientation_deg"] == [90.0, 0.0, 0.0]
    fa, fb, fc = (_frames(tmp_path / k / "left.mp4") for k in ("yaw90.mp4-p0.csv",
                  "plain.mp4-p90.csv", "plain.mp4-p0.csv"))  # fmt: skip
    assert np.abs(fa - fb).max() <= 2 < np.abs(fa - fc).mean()  # the eye sees yaw 90


def _frames(path) -> np.ndarray:
    from simulator.media.video import iter_frames

    return np.stack([np.array(f, float) for f in iter_frames(path)])
