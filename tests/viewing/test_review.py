"""render --review: the frustum outline (checked against a brute-force mask), review.mp4, sheet.png."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from simulator.core.errors import InputError
from simulator.sphere.geometry import equirect_pixel_lonlat, head_rotation, lonlat_to_dir
from simulator.viewing.review import frustum_outline_xy

W, H = 360, 180


def _inside_mask(yaw, pitch, roll, hfov, vfov):
    """Brute force: equirect pixels whose ray, taken into the head frame, is inside the frustum."""
    lon, lat = equirect_pixel_lonlat(W, H)
    d = lonlat_to_dir(lon[None, :], lat[:, None]).reshape(-1, 3)
    h = head_rotation(yaw, pitch, roll).inv().apply(d)
    tx, ty = math.tan(math.radians(hfov / 2)), math.tan(math.radians(vfov / 2))
    z = h[:, 2]
    ok = (z > 0) & (np.abs(h[:, 0]) <= tx * z) & (np.abs(h[:, 1]) <= ty * z)
    return ok.reshape(H, W)


@pytest.mark.parametrize(
    "pose",
    [(0, 0, 0, 90, 90), (170, 10, 20, 107, 107), (-30, 80, 0, 100, 90), (0, -90, 0, 120, 120)],
)
def test_outline_lies_on_the_brute_force_frustum_edge(pose):
    *ang, hf, vf = pose
    mask = _inside_mask(*ang, hf, vf)
    parts = frustum_outline_xy(*ang, hf, vf, W, H, per_edge=200)
    pts = np.concatenate(parts)
    assert np.all((pts[:, 0] >= 0) & (pts[:, 0] <= W) & (pts[:, 1] >= 0) & (pts[:, 1] <= H))
    # each outline point has inside and outside pixels within 2 px (wrapping in x)
    on_edge = 0
    for x, y in pts[::5]:
        xs = np.arange(int(x) - 2, int(x) + 3) % W
        ys = np.clip(np.arange(int(y) - 2, int(y) + 3), 0, H - 1)
        win = mask[np.ix_(ys, xs)]
        on_edge += bool(win.any() and not win.all())
    assert on_edge >= 0.95 * len(pts[::5])


def test_outline_analytic_seam_and_pole():
    parts = frustum_outline_xy(0, 0, 0, 90, 90, W, H)
    pts = np.concatenate(parts)
    assert len(parts) == 1
    assert pts[:, 0].min() == pytest.approx(135, abs=0.01)  # lon -45 at the equator
    assert pts[:, 0].max() == pytest.approx(225, abs=0.6)
    assert pts[:, 1].min() == pytest.approx(45, abs=0.01)  # lat 45 at the top centre
    seam = frustum_outline_xy(180, 0, 0, 90, 90, W, H)
    assert len(seam) >= 2  # cut at +-180, no stroke across the frame
    for p in seam:
        assert np.abs(np.diff(p[:, 0])).max() < W / 4
    pole = np.concatenate(frustum_outline_xy(0, 90, 0, 100, 100, W, H))
    assert np.ptp(pole[:, 0]) > 0.95 * W and pole[:, 1].max() < H / 2  # around the north pole


@pytest.mark.gl
def test_render_review_writes_video_and_sheet(tmp_path):
    from simulator.render import create_context

    try:
        create_context()
    except InputError as e:
        pytest.skip(f"headless EGL absent ({e})")
    from simulator.cli import main
    from simulator.media.video import VideoWriter, iter_frames, probe

    vid = tmp_path / "v.mp4"
    with VideoWriter(vid, 10, (256, 128), preset="ultrafast") as w:
        for i in range(8):
            w.write(np.full((128, 256, 3), 40 + 10 * i, np.uint8))
    p = tmp_path / "p.csv"
    p.write_text("time_s,yaw_deg,pitch_deg,roll_deg\n0,0,0,0\n1,90,0,0\n")
    out = tmp_path / "o"
    argv = ["render", str(vid), str(p), "-o", str(out), "--eye-size", "32x32", "--no-progress",
            "--opacity", "0.5", "--review", "--start", "0.2"]  # fmt: skip
    assert main(argv) == 0
    info = probe(out / "review.mp4")
    assert info.n_frames == 6 and (info.width, info.height) == (1080, 480)
    first = next(iter(iter_frames(out / "review.mp4")))
    pano = first[:360, :720].astype(int)
    yellow = (pano[..., 0] > 200) & (pano[..., 1] > 170) & (pano[..., 2] < 90)
    _, xs = np.nonzero(yellow)
    # the outline of a 107 deg view at yaw 18 (t = 0.2 s): around x = 360 + 18 * 2
    assert yellow.sum() > 500 and abs(np.median(xs) - (360 + 36)) < 40
    from PIL import Image

    with Image.open(out / "sheet.png") as im:
        assert im.size[0] >= 240 and im.size[1] >= 284
    s = json.loads((out / "summary.json").read_text())
    assert s["review"] == ["review.mp4", "sheet.png"]
