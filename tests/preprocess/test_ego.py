"""The camera's rotation from the video (simulator/preprocess/ego.py): the robust fit, the sphere-mode estimator and the grid file's per-frame rotation."""

from __future__ import annotations

import itertools

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from simulator.media.gridfile import load_grid
from simulator.preprocess import FieldEstimator, SphereConfig, preprocess_sphere
from simulator.preprocess.ego import fit_rotation
from simulator.sphere.cells import CellGrid
from simulator.sphere.geometry import head_rotation, lonlat_to_dir
from simulator.sphere.windows import grid_preset
from simulator.synth import SynthConfig, make_scene


def _cells(cell=9.0):
    cells = CellGrid(cell)
    lon, lat = cells.centres_lonlat()
    d = lonlat_to_dir(*np.meshgrid(lon, lat)).reshape(-1, 3)
    return d, cells.solid_angles().reshape(-1)


def _model(d, w, t, depth):
    """Rotation vectors of cells under content rotation w and translation t at depth."""
    pw = w[None] - (d @ w)[:, None] * d
    return pw + np.cross(d, t[None]) / depth[:, None]


def test_fit_recovers_rotation_under_parallax_and_movers():
    """Rotation + translation with any depths (the epipolar constraint removes the
    parallax), 15 % of cells moving on their own: the rotation comes back within 1 %."""
    rng = np.random.default_rng(1)
    d, sa = _cells()
    w = np.radians([2.0, -5.0, 1.0])
    t = np.array([0.3, 0.0, 1.0]) * 0.05
    depth = rng.uniform(0.8, 6.0, len(d))
    c = _model(d, w, t, depth)
    movers = rng.random(len(d)) < 0.15
    c[movers] += rng.normal(0, 0.05, (movers.sum(), 3))
    c += rng.normal(0, 2e-4, c.shape)
    fit = fit_rotation(c, d, sa)
    assert np.linalg.norm(fit.w - w) < 0.01 * np.linalg.norm(w)
    assert abs(abs(fit.t @ t) / np.linalg.norm(t) - 1) < 0.01  # the heading, up to sign
    assert 0.75 < fit.confidence <= 1.0
    # a pure-rotation fit is dragged by the same parallax: the constraint matters
    plain = fit_rotation(c, d, sa, translation=False)
    assert np.linalg.norm(plain.w - w) > 3 * np.linalg.norm(fit.w - w)
    # still camera: zero
    still = fit_rotation(rng.normal(0, 1e-4, c.shape), d, sa)
    assert np.degrees(np.linalg.norm(still.w)) * 30 < 0.05


def _pano_frames(n, omega_dps, axis, fps=30.0, mover=False):
    sc = make_scene(
        SynthConfig(scene="rotate", size=(512, 256), axis=axis, omega_dps=omega_dps, fps=fps)
    )
    frames = [cv2.cvtColor(sc.render(k / fps), cv2.COLOR_RGB2GRAY) for k in range(n)]
    if mover:  # a textured patch (~6 % of the frame) racing right at 12 px/frame
        rng = np.random.default_rng(0)
        patch = cv2.resize(rng.integers(0, 256, (12, 24), np.uint8), (96, 48), cv2.INTER_CUBIC)
        for k, f in enumerate(frames):
            x = 200 + 12 * k
            f[110:158, x : x + 96] = patch
    return frames


@pytest.mark.parametrize("mover", [False, True])
def test_estimator_angular_velocity_of_a_rotating_panorama(mover):
    """The rotate scene turns the camera at 90 deg/s about an oblique axis: the
    estimated camera angular velocity (world frame) is the truth within 2 %, also with
    an independently moving patch; the translational field is near zero."""
    fps, omega, axis = 30.0, 90.0, np.array([0.3, 0.8, 0.2])
    frames = _pano_frames(3, omega, axis, fps, mover)
    est = FieldEstimator((512, 256), fps, SphereConfig())
    tiles = [est.tiles(f) for f in frames]
    truth = -axis / np.linalg.norm(axis) * omega  # rotate scene: camera R(t) = rotvec(-a w t)
    for a, b in itertools.pairwise(tiles):
        p = est.parts(a, b)
        assert np.linalg.norm(p.omega_dps - truth) < 0.02 * omega, p.omega_dps
        assert p.confidence > 0.6
        assert p.trans.shape == p.field.shape == (45, 90)
        assert np.median(p.trans) < 0.1 * np.median(p.field)
    still = est.parts(tiles[0], tiles[0])
    assert np.linalg.norm(still.omega_dps) < 0.5 and still.confidence > 0.9


def test_rotation_truth_convention():
    """Yaw right = +y, pitch up = -x, roll right-ear-down = -z in the world frame."""
    for ypr, axis in (((10, 0, 0), [0, 1, 0]), ((0, 10, 0), [-1, 0, 0]), ((0, 0, 10), [0, 0, -1])):
        rv = head_rotation(*ypr).as_rotvec()
        assert np.allclose(rv / np.linalg.norm(rv), axis, atol=1e-9)
    assert Rotation.identity().magnitude() == 0


def test_grid_records_the_rotation_per_frame(tmp_path):
    from simulator.media.video import VideoWriter

    frames = _pano_frames(4, 60.0, (0, 1, 0))
    vid = tmp_path / "rot.mp4"
    with VideoWriter(vid, 30.0, (512, 256)) as vw:
        for fr in frames:
            vw.write(np.repeat(fr[..., None], 3, axis=2))
    g = load_grid(preprocess_sphere(vid, tmp_path / "g.npz", grid=grid_preset("default")))
    om = g.extras["ego_omega_dps"]
    assert om.shape == (4, 3) and g.extras["ego_confidence"].shape == (4,)
    assert np.allclose(om[0], om[1])  # frame 0 repeats frame 1
    assert np.all(np.abs(om[1:, 1] + 60.0) < 3.0)  # axis +y, camera turns at -60 deg/s (H.264)
    assert g.field_trans_dps is not None and g.field_trans_dps.shape == g.field_dps.shape
    assert "ego" in g.meta


def test_ego_command_video_and_grid(tmp_path, capsys):
    """vimsim ego on a video and on its sphere-mode grid give the same CSV; the yaw rate of
    the rotate scene turning the camera about -y at 60 deg/s is -60 (turning left)."""
    from simulator.cli import main
    from simulator.media.video import VideoWriter

    frames = _pano_frames(4, 60.0, (0, 1, 0))
    vid = tmp_path / "rot.mp4"
    with VideoWriter(vid, 30.0, (512, 256)) as vw:
        for fr in frames:
            vw.write(np.repeat(fr[..., None], 3, axis=2))
    assert main(["ego", str(vid), "-o", str(tmp_path / "e.csv"), "--no-progress"]) == 0
    lines = (tmp_path / "e.csv").read_text().splitlines()
    assert lines[0].startswith("frame,time_s,omega_x_dps,omega_y_dps,omega_z_dps,yaw_rate_dps")
    rows = np.array([[float(v) for v in ln.split(",")] for ln in lines[1:]])
    assert rows.shape == (4, 10)
    assert np.all(np.abs(rows[1:, 5] + 60.0) < 3.0) and np.all(np.abs(rows[1:, 6:8]) < 1.5)
    g = preprocess_sphere(vid, tmp_path / "g.npz", grid=grid_preset("default"))
    assert main(["ego", str(g), "-o", str(tmp_path / "g.csv")]) == 0
    assert (tmp_path / "g.csv").read_text().splitlines()[0] == lines[0]
    capsys.readouterr()
    assert main(["ego", str(tmp_path / "nope.mp4"), "-o", str(tmp_path / "x.csv")]) == 2
    err = capsys.readouterr().err.strip()
    assert "nope.mp4" in err and "\n" not in err and not (tmp_path / "x.csv").exists()


def test_ego_of_a_variable_rate_video_and_its_grid_give_the_frame_times(tmp_path):
    """vimsim ego of a variable-rate video (every third frame dropped) and of its grid: both
    CSVs time each row by the frame's timestamp, not frame / fps."""
    import subprocess

    from simulator.cli import main
    from simulator.media.video import probe
    from simulator.testing.reference import ffmpeg_exe

    assert main(["synth", str(tmp_path / "r.mp4"), "--scene", "rotate", "--seconds", "1",
                 "--fps", "30", "--size", "128x64"]) == 0  # fmt: skip
    subprocess.run([ffmpeg_exe(), "-v", "error", "-y", "-i", str(tmp_path / "r.mp4"), "-vf",
                    "select='not(eq(mod(n\\,3)\\,2))'", "-fps_mode", "vfr", "-c:v", "libx264",
                    "-crf", "10", str(tmp_path / "vfr.mp4")], check=True)  # fmt: skip
    truth = probe(tmp_path / "vfr.mp4").times_s()
    assert main(["ego", str(tmp_path / "vfr.mp4"), "-o", str(tmp_path / "v.csv"),
                 "--no-progress"]) == 0  # fmt: skip
    assert main(["preprocess", str(tmp_path / "vfr.mp4"), "-o", str(tmp_path / "g.npz"),
                 "--method", "sphere", "--cell", "10", "--no-progress"]) == 0  # fmt: skip
    assert main(["ego", str(tmp_path / "g.npz"), "-o", str(tmp_path / "g.csv")]) == 0
    for name in ("v.csv", "g.csv"):
        rows = (tmp_path / name).read_text().splitlines()[1:]
        t = np.array([float(r.split(",")[1]) for r in rows])
        np.testing.assert_allclose(t, truth[: len(t)], atol=1e-6, err_msg=name)
        assert np.ptp(np.diff(t)) > 0.02  # the gaps are there
