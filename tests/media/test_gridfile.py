"""Grid file: round trip, refusal of foreign/old files, and video matching."""

from __future__ import annotations

import json

import numpy as np
import pytest

from simulator.core.errors import InputError
from simulator.media.gridfile import VERSION, content_hash, load_grid, save_grid
from simulator.media.video import MediaInfo
from simulator.sphere.windows import grid_preset


def _meta(video_path, n=5, **video):
    v = {
        "path": str(video_path),
        "width": 64,
        "height": 32,
        "sar": 1.0,
        "n_frames": n,
        "content_hash": content_hash(video_path),
    }
    v.update(video)
    return {
        "fps": 30.0,
        "n_frames": n,
        "flow": {"method": "dis"},
        "layout": "mono",
        "eye": "left",
        "video": v,
        "start_frame": 0,
        "end_frame": n,
    }


@pytest.fixture()
def video(tmp_path):
    p = tmp_path / "v.mp4"
    p.write_bytes(b"pretend video bytes")
    return p


def test_round_trip(tmp_path, video):
    g = grid_preset("paper-198", size=(32, 32))
    a = np.random.default_rng(0).random((5, 11, 18)).astype(np.float32)
    save_grid(tmp_path / "g.npz", a, 2 * a, g, _meta(video))
    G = load_grid(tmp_path / "g.npz")
    np.testing.assert_array_equal(G.pof_dps, a)
    np.testing.assert_array_equal(G.pof_px, 2 * a)
    assert G.grid == g
    assert G.fps == 30.0 and G.n_frames == 5
    assert sorted(p.name for p in tmp_path.iterdir()) == ["g.npz", "v.mp4"]  # no temp left
    np.testing.assert_allclose(G.frame_times_s(), np.arange(5) / 30.0)


def test_refuses_foreign_and_old_files(tmp_path, video):
    np.savez(tmp_path / "other.npz", x=np.zeros(3))
    with pytest.raises(InputError, match="not a vimsim grid"):
        load_grid(tmp_path / "other.npz")
    (tmp_path / "text.npz").write_text("hello")
    with pytest.raises(InputError, match="not a vimsim grid"):
        load_grid(tmp_path / "text.npz")
    g = grid_preset("default", size=(16, 16))
    a = np.ones((2, 11, 24), np.float32)
    save_grid(tmp_path / "g.npz", a, a, g, _meta(video, n=2))
    z = dict(np.load(tmp_path / "g.npz", allow_pickle=False))
    m = json.loads(str(z["meta"]))
    m["version"] = VERSION + 1
    z["meta"] = np.array(json.dumps(m))
    np.savez(tmp_path / "new.npz", **z)
    with pytest.raises(InputError, match="version"):
        load_grid(tmp_path / "new.npz")


def test_check_video(tmp_path, video):
    g = grid_preset("default", size=(16, 16))
    a = np.ones((5, 11, 24), np.float32)
    save_grid(tmp_path / "g.npz", a, a, g, _meta(video))
    G = load_grid(tmp_path / "g.npz")
    ok = MediaInfo(str(video), 64, 32, 1.0, 30.0, 5, True, "h264")
    G.check_video(ok)  # same video: no error
    with pytest.raises(InputError, match="64x32"):
        G.check_video(MediaInfo(str(video), 128, 64, 1.0, 30.0, 5, True, "h264"))
    with pytest.raises(InputError, match="fps"):
        G.check_video(MediaInfo(str(video), 64, 32, 1.0, 25.0, 5, True, "h264"))
    other = tmp_path / "other.mp4"
    other.write_bytes(b"another video, same size")
    with pytest.raises(InputError, match="content hash"):
        G.check_video(MediaInfo(str(other), 64, 32, 1.0, 30.0, 5, True, "h264"))
    # a grid of frames 0..3 of a 10-frame video cannot drive a whole-video render
    save_grid(
        tmp_path / "part.npz", a[:3], a[:3], g, dict(_meta(video, n=3, n_frames=10), end_frame=3)
    )
    with pytest.raises(InputError, match="--start/--end"):
        load_grid(tmp_path / "part.npz").check_video(
            MediaInfo(str(video), 64, 32, 1.0, 30.0, 10, True, "h264")
        )


def test_text_file_is_not_a_grid(tmp_path):
    p = tmp_path / "path.csv"
    p.write_text("time_s,yaw_deg,pitch_deg,roll_deg\n0,0,0,0\n")
    with pytest.raises(InputError, match=r"not a vimsim grid file \(expected a \.npz"):
        load_grid(p)
