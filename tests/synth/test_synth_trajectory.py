"""The trajectory scene (simulator.synth.trajectory) and camera paths
(simulator.synth.camera_path): CSV reading and bad input, pose conventions, interpolation
derivatives, analytic truth against finite differences and against the rotate scene,
the room, the truth file, the z-up converter, and a small flow-accuracy check."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from simulator.cli import main
from simulator.core.errors import InputError
from simulator.media.video import probe, read_frame
from simulator.sphere.geometry import head_angles_deg
from simulator.synth import SynthConfig, load_truth, synthesize, truth_path_for
from simulator.synth.camera_path import (
    CAMERA_COLUMNS,
    CameraTrajectory,
    load_camera_csv,
    save_camera_csv,
    trajectory_from_zup,
)
from simulator.synth.trajectory import (
    make_trajectory_scene,
    scene_from_truth,
    synthesize_trajectory,
    trajectory_config,
)

HEADER = ",".join(CAMERA_COLUMNS)


def _run(argv):
    try:
        return main(argv)
    except SystemExit as e:
        return e.code


def _csv(path, rows, header=HEADER):
    path.write_text(header + "\n" + "\n".join(",".join(str(v) for v in r) for r in rows) + "\n")
    return path


def _walk(seconds=2.0, step=0.1, turn_dps=20.0):
    t = np.arange(0.0, seconds + 1e-9, step)
    pos = np.column_stack([0.3 * np.sin(t), 0.03 * np.sin(4 * np.pi * t), 1.4 * t])
    return CameraTrajectory.from_poses_deg(
        t, pos, turn_dps * t, 3 * np.sin(2 * t), 2 * np.cos(3 * t), source="walk"
    )


def _unit(rng, n):
    d = rng.standard_normal((n, 3))
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def test_csv_round_trip_any_column_order(tmp_path):
    tr = _walk()
    p = save_camera_csv(tmp_path / "c.csv", tr)
    back = load_camera_csv(p)
    np.testing.assert_allclose(back.times_s, tr.times_s)
    np.testing.assert_allclose(back.positions_m, tr.positions_m, atol=1e-8)
    assert np.max((back.rotations.inv() * tr.rotations).magnitude()) < 1e-7
    # Columns in another order, with a comment line.
    cols = ["roll_deg", "time_s", "z_m", "y_m", "x_m", "pitch_deg", "yaw_deg"]
    q = _csv(
        tmp_path / "o.csv", [[0, 0, 0, 0, 0, 0, 0], [5, 1, 2, 1, 0.5, -10, 30]], ",".join(cols)
    )
    q.write_text("# made by hand\n" + q.read_text())
    t = load_camera_csv(q)
    np.testing.assert_allclose(t.positions_m[1], [0.5, 1, 2])
    np.testing.assert_allclose(np.column_stack(t.angles_deg())[1], [30, -10, 5], atol=1e-9)


def test_pose_conventions_match_spec():
    """yaw + turns right (forward -> +x), pitch + looks up, roll + right ear down."""
    t = [0.0, 1.0]
    fwd, right = np.array([0, 0, 1.0]), np.array([1.0, 0, 0])
    for ypr, axis, expect in (
        ((90, 0, 0), fwd, [1, 0, 0]),
        ((0, 30, 0), fwd, [0, 0.5, np.sqrt(3) / 2]),
        ((0, 0, 30), right, [np.sqrt(3) / 2, -0.5, 0]),
    ):
        tr = CameraTrajectory.from_poses_deg(t, np.zeros((2, 3)), *([a, a] for a in ypr))
        np.testing.assert_allclose(tr.rotation(0.5).apply(axis), expect, atol=1e-12)


def test_rendered_yaw_shifts_the_image_left():
    """A camera turned right by 45 deg sees at lon what the unturned one saw at lon + 45."""
    tr = CameraTrajectory.from_poses_deg(
        [0.0, 1.0], np.zeros((2, 3)), [0.0, 45.0], [0.0, 0.0], [0.0, 0.0]
    )
    sc = make_trajectory_scene(trajectory_config(tr, fps=1, size=(256, 128)), tr)
    f0, f1 = sc.render(0.0).astype(float), sc.render(1.0).astype(float)
    err = np.abs(f1 - np.roll(f0, -32, axis=1))[24:-24].mean()
    other = np.abs(f1 - np.roll(f0, 32, axis=1))[24:-24].mean()
    assert err < 3.0 < other, (err, other)


@pytest.mark.parametrize("interp", ["linear", "cubic"])
def test_interpolants_and_their_derivatives(interp):
    tr = _walk()
    tr = CameraTrajectory(tr.times_s, tr.positions_m, tr.rotations, interp)
    # Through every pose.
    np.testing.assert_allclose(tr.position(tr.times_s), tr.positions_m, atol=1e-12)
    assert np.max((tr.rotation(tr.times_s).inv() * tr.rotations).magnitude()) < 1e-9
    # Velocity and camera-frame angular velocity = finite differences (off the poses).
    h = 1e-6
    for t in (0.23, 0.77, 1.55):
        fd_v = (tr.position(t + h) - tr.position(t - h)) / (2 * h)
        np.testing.assert_allclose(tr.velocity(t), fd_v, rtol=1e-6, atol=1e-6)
        rel = tr.rotation(t - h).inv() * tr.rotation(t + h)
        np.testing.assert_allclose(tr.omega_cam_rad(t), rel.as_rotvec() / (2 * h), atol=1e-6)
    if interp == "linear":
        np.testing.assert_allclose(tr.position(0.05), tr.positions_m[:2].mean(0), atol=1e-12)


def test_slerp_reproduces_a_constant_rotation_from_sparse_poses():
    a = np.array([1.0, 2.0, 0.5]) / np.linalg.norm([1.0, 2.0, 0.5])
    t = np.arange(0.0, 1.01, 0.25)
    rot = Rotation.from_rotvec(-a * np.radians(30.0) * t[:, None])
    tr = CameraTrajectory.from_poses_deg(t, np.zeros((t.size, 3)), *head_angles_deg(rot))
    for s in (0.1, 0.33, 0.9):
        exact = Rotation.from_rotvec(-a * np.radians(30.0) * s)
        assert (tr.rotation(s).inv() * exact).magnitude() < 1e-9
        np.testing.assert_allclose(np.degrees(tr.omega_cam_rad(s)), -30.0 * a, atol=1e-9)


@pytest.mark.parametrize("eye,layout", [("mono", "mono"), ("right", "top-bottom")])
def test_speed_matches_finite_differences_of_projected_points(eye, layout):
    tr = _walk()
    sc = make_trajectory_scene(trajectory_config(tr, layout=layout, size=(64, 32)), tr)
    d = _unit(np.random.default_rng(2), 400)
    h = 1e-5
    for t in (0.33, 1.07, 1.81):
        speed = sc.speed_dps(t, d, eye)
        X = sc.eye_origin(t, eye) + sc.rotation(t).apply(d * sc.depth(t, d, eye)[:, None])
        q = [sc.rotation(s).inv().apply(X - sc.eye_origin(s, eye)) for s in (t - h, t + h)]
        q = [v / np.linalg.norm(v, axis=1, keepdims=True) for v in q]
        chord = np.linalg.norm(q[1] - q[0], axis=1)
        fd = np.degrees(2 * np.arcsin(chord / 2) / (2 * h))
        np.testing.assert_allclose(speed, fd, rtol=2e-3, atol=2e-3)
        assert speed.max() > 20.0


def test_pure_rotation_truth_equals_rotate_scene(tmp_path):
    """A fixed camera turning like the rotate scene (oblique axis, poses every 0.1 s)
    has the rotate scene's truth in every cell and frame (within 0.1 %)."""
    axis = np.array([1.0, 2.0, 0.5])
    a = axis / np.linalg.norm(axis)
    t = np.arange(0.0, 0.51, 0.1)
    rot = Rotation.from_rotvec(-a * np.radians(40.0) * t[:, None])
    csv = save_camera_csv(tmp_path / "rot.csv", CameraTrajectory(t, np.zeros((t.size, 3)), rot))
    _, tpath, cfg = synthesize_trajectory(csv, tmp_path / "t.mp4", fps=10, size=(64, 32))
    rcfg = SynthConfig(
        "rotate", seconds=cfg.seconds, fps=10, size=(64, 32), axis=tuple(axis), omega_dps=40.0
    )
    _, rpath = synthesize(rcfg, tmp_path / "r.mp4")
    st, sr = load_truth(tpath).speed_dps, load_truth(rpath).speed_dps
    assert st.shape == sr.shape == (6, 45, 90)
    m = sr > 1.0
    assert np.max(np.abs(st[m] - sr[m]) / sr[m]) < 1e-3
    assert sr.max() > 35.0
    np.testing.assert_allclose(load_truth(tpath).time_s, load_truth(rpath).time_s)


def test_truth_file_stereo_clip_and_rebuild(tmp_path):
    tr = _walk(seconds=0.5, step=0.05)
    video, tpath, _ = synthesize_trajectory(
        save_camera_csv(tmp_path / "w.csv", tr),
        tmp_path / "w.mp4",
        fps=12,
        size=(128, 64),
        layout="top-bottom",
        truth_cell_deg=10,
    )
    info = probe(video)
    assert (info.width, info.height, info.n_frames) == (128, 128, 7)
    assert info.fps == pytest.approx(12.0)
    top = read_frame(video, 3, layout="top-bottom", eye="left").astype(float)
    bot = read_frame(video, 3, layout="top-bottom", eye="right").astype(float)
    assert np.abs(top - bot).mean() > 1.0
    with np.load(tpath, allow_pickle=False) as z:
        arr = {k: z[k] for k in z.files}
    tru = load_truth(tpath)
    assert tru.speed_dps.shape == tru.speed_dps_right.shape == (7, 18, 36)
    assert not np.allclose(tru.speed_dps, tru.speed_dps_right)
    np.testing.assert_allclose(arr["camera_time_s"], tr.times_s)
    np.testing.assert_allclose(arr["camera_position_m"], tr.positions_m, atol=1e-12)
    # Both parts present and the total between |rot - trans| and rot + trans.
    rot, trans = arr["speed_rot_dps"], arr["speed_trans_dps"]
    assert rot.max() > 1.0 and trans.max() > 1.0
    assert np.all(tru.speed_dps <= rot + trans + 1e-3)
    assert np.all(tru.speed_dps >= np.abs(rot - trans) - 1e-3)
    assert "speed_trans_dps_right" in arr
    assert tru.meta["camera"]["n_poses"] == tr.n and tru.meta["config"]["scene"] == "trajectory"
    # The rebuilt scene gives the same truth at the cells.
    sc = scene_from_truth(tpath)
    LO, LA = np.meshgrid(np.radians(tru.lon_deg), np.radians(tru.lat_deg))
    from simulator.sphere.geometry import lonlat_to_dir

    d = lonlat_to_dir(LO, LA)
    np.testing.assert_allclose(sc.speed_dps(tru.time_s[4], d, "left"), tru.speed_dps[4], rtol=1e-5)
    with pytest.raises(InputError, match="camera path"):
        tru.scene()  # make_scene cannot rebuild it without the poses


def test_room_default_size_and_placement():
    tr = CameraTrajectory.from_poses_deg(
        [0.0, 2.0], [[0, 0, 0], [0, 0, 4.0]], [0, 0], [0, 0], [0, 0], interp="linear"
    )
    sc = make_trajectory_scene(trajectory_config(tr, size=(64, 32)), tr)
    assert sc.box.lo == pytest.approx((-3.0, -1.6, -3.0))
    assert sc.box.hi == pytest.approx((3.0, 2.4, 7.0))
    # --room W,H,D: centred on the path in x, z; floor 1.6 m below it.
    sc = make_trajectory_scene(trajectory_config(tr, size=(64, 32)), tr, (8.0, 3.0, 10.0))
    assert sc.box.lo == pytest.approx((-4.0, -1.6, -3.0))
    assert sc.box.hi == pytest.approx((4.0, 1.4, 7.0))
    d = np.array([[1.0, 0, 0], [0, -1.0, 0], [0, 1.0, 0], [0, 0, -1.0]])
    np.testing.assert_allclose(sc.depth(0.0, d), [4.0, 1.6, 1.4, 3.0])
    # Corners.
    sc = make_trajectory_scene(trajectory_config(tr, size=(64, 32)), tr, (-1, -1, -1, 1, 1, 5))
    assert sc.box.hi == (1.0, 1.0, 5.0)


def test_zup_converter_blender_camera(tmp_path):
    """Blender: +x right, +y forward, +z up; a camera looks along its local -z. Blender's
    rotation_euler (90, 0, 0) deg (XYZ) looks along +y (our +z): yaw = pitch = roll = 0."""
    eul = np.array([[90, 0, 0], [90, 0, -90], [120, 0, 0], [90, 10, 0], [60, 0, 45]], float)
    loc = np.array([[1.0, 2.0, 3.0]] * len(eul))
    rot = Rotation.from_euler("xyz", eul, degrees=True)
    tr = trajectory_from_zup(np.arange(len(eul), dtype=float), loc, rot)
    np.testing.assert_allclose(tr.positions_m[0], [1.0, 3.0, 2.0])
    y, p, r = tr.angles_deg()
    # look +y; turn to +x (right); tilt up 30; bank right 10; down 30 and left 45.
    np.testing.assert_allclose(y, [0, 90, 0, 0, -45], atol=1e-9)
    np.testing.assert_allclose(p, [0, 0, 30, 0, -30], atol=1e-9)
    np.testing.assert_allclose(r, [0, 0, 0, 10, 0], atol=1e-9)
    # Every converted pose looks where the Blender camera looks (converted) and keeps
    # its up vector: independent of the angle read-out.
    rng = np.random.default_rng(0)
    rots = Rotation.random(20, random_state=rng)
    tr = trajectory_from_zup(np.arange(20.0), rng.normal(size=(20, 3)), rots)
    m = np.array([[1, 0, 0], [0, 0, 1], [0, 1, 0]], float)
    np.testing.assert_allclose(
        tr.rotations.apply([0, 0, 1.0]), rots.apply([0, 0, -1.0]) @ m.T, atol=1e-12
    )
    np.testing.assert_allclose(
        tr.rotations.apply([0, 1.0, 0]), rots.apply([0, 1.0, 0]) @ m.T, atol=1e-12
    )
    # The recipe of docs/trajectory.md: Blender's time_s,x,y,z,qw,qx,qy,qz rows (camera at
    # rotation_euler (90, 0, -90) deg, i.e. looking along Blender's +x) -> our CSV.
    q = Rotation.from_euler("xyz", [90, 0, -90], degrees=True).as_quat()  # x, y, z, w
    rows = [[t, 1.0, 2.0 + t, 3.0, q[3], q[0], q[1], q[2]] for t in (0.0, 0.5)]
    blender_csv = tmp_path / "blender_cam.csv"
    _csv(blender_csv, rows, "time_s,x,y,z,qw,qx,qy,qz")
    d = np.loadtxt(blender_csv, delimiter=",", skiprows=1)
    rot = Rotation.from_quat(d[:, [5, 6, 7, 4]])  # scipy wants x, y, z, w
    traj = trajectory_from_zup(d[:, 0], d[:, 1:4], rot, camera_looks="-z")
    back = load_camera_csv(save_camera_csv(tmp_path / "CAMERA.csv", traj))
    np.testing.assert_allclose(np.column_stack(back.angles_deg()), [[90, 0, 0]] * 2, atol=1e-6)
    np.testing.assert_allclose(back.positions_m, [[1, 3, 2], [1, 3, 2.5]], atol=1e-8)
    # An object with the world's axes (+y forward): identity -> looks along +z.
    tr = trajectory_from_zup([0.0, 1.0], np.zeros((2, 3)), Rotation.identity(2), camera_looks="+y")
    np.testing.assert_allclose(np.column_stack(tr.angles_deg()), 0, atol=1e-12)


@pytest.mark.parametrize(
    "rows,header,needle",
    [
        (
            [[0, 0, 0, 0, 0, 0], [1, 0, 0, 0, 0, 0]],
            "time_s,x_m,y_m,z_m,yaw_deg,pitch_deg",
            "missing ['roll_deg']",
        ),
        (
            [[0, 0, 0, 0, 0, 0, 0], [1, 0, 0, 0, 0, 0, 0]],
            "time_s,x,y_m,z_m,yaw_deg,pitch_deg,roll_deg",
            "unknown ['x']",
        ),
        (
            [[0, 0, 0, 0, 0, 0, 0], [1, 0, 0, 0, 0, 0, 0], [1, 0, 0, 0.1, 0, 0, 0]],
            HEADER,
            "not strictly increasing at line 4",
        ),
        ([[0, 0, 0, 0, 0, 0, 0], [1, 0, "nan", 0, 0, 0, 0]], HEADER, "line 3: y_m is nan"),
        ([[0, 0, 0, 0, 0, 0, 0], [1, 0, 0, 0, "inf", 0, 0]], HEADER, "yaw_deg is inf"),
        ([[0, 0, 0, 0, 0, 0, 0]], HEADER, "1 pose(s)"),
        ([], HEADER, "0 pose(s)"),
        ([[0, 0, 0, 0, 0, 0, 0], [1, 0, 0, "x", 0, 0, 0]], HEADER, "non-numeric"),
        ([[0, 0, 0, 0, 0, 0, 0], [1, 0, 0, 0, 0, 0]], HEADER, "line 3 has 6 fields"),
        ([[0, 0, 0, 0, 0, 0, 0], [0.02, 0, 0, 0, 0, 0, 0]], HEADER, "flow needs at least 2"),
    ],
)
def test_bad_camera_csv_one_line_exit_2(tmp_path, capsys, rows, header, needle):
    cam = _csv(tmp_path / "cam.csv", rows, header)
    out = tmp_path / "x.mp4"
    rc = _run(["synth", str(out), "--scene", "trajectory", "--camera", str(cam), "--size", "64x32"])
    err = capsys.readouterr().err
    assert rc == 2
    assert needle in err and str(cam) in err, err
    assert len(err.strip().splitlines()) == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cam.csv"]


def test_trajectory_leaving_the_room_names_the_first_time(tmp_path, capsys):
    # Walks 1 m/s along +z from z = 0 to 10; a 6 m deep room centred on the path spans
    # z 2..8, so the camera is outside at once.
    cam = _csv(tmp_path / "cam.csv", [[0, 0, 0, 0, 0, 0, 0], [10, 0, 0, 10, 0, 0, 0]])
    out = tmp_path / "x.mp4"
    args = ["synth", str(out), "--scene", "trajectory", "--camera", str(cam), "--size", "64x32"]
    assert _run([*args, "--room", "6,4,6"]) == 2
    err = capsys.readouterr().err
    assert "leaves the room at t = 0.000 s" in err and "z = 0.00 m" in err and str(cam) in err
    assert len(err.strip().splitlines()) == 1
    # Corners: the path leaves through z = 7 m at t = 7 - 0.232 = 6.768 s.
    assert _run([*args, "--room=-3,-2,-1,3,2,7"]) == 2  # "=": argparse reads -3 as an option
    err = capsys.readouterr().err
    assert "leaves the room at t = 6.768 s" in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cam.csv"]
    # A path that overshoots the poses (cubic spline) is checked between them too.
    tr = CameraTrajectory.from_poses_deg(
        [0, 1, 2, 3], [[0, 0, 0], [2.6, 0, 1], [-2.6, 0, 2], [0, 0, 3]], *[[0] * 4] * 3
    )
    with pytest.raises(InputError, match="leaves the room at t = 0\\.[0-9]+ s \\(x ="):
        make_trajectory_scene(trajectory_config(tr, size=(64, 32)), tr, (6.0, 4.0, 8.0))


@pytest.mark.parametrize(
    "extra,needle",
    [
        ([], "needs --camera"),
        (["--camera", "{cam}", "--seconds", "2"], "--seconds does not apply"),
        (["--camera", "{cam}", "--room", "0,4,5"], "> 0 m"),
        (["--camera", "{cam}", "--room", "1,2"], "W,H,D"),
        (["--camera", "{cam}", "--room", "1,1,1,0,2,2"], "X0 < X1"),
        (["--camera", "{dir}/missing.csv"], "camera file not found"),
        (["--camera", "{cam}", "--fps", "500"], "240"),
    ],
)
def test_bad_options_one_line_exit_2(tmp_path, capsys, extra, needle):
    cam = _csv(tmp_path / "cam.csv", [[0, 0, 0, 0, 0, 0, 0], [1, 0, 0, 1, 0, 0, 0]])
    out = tmp_path / "x.mp4"
    extra = [e.format(cam=cam, dir=tmp_path) for e in extra]
    rc = _run(["synth", str(out), "--scene", "trajectory", "--size", "64x32", *extra])
    err = capsys.readouterr().err
    assert rc == 2 and needle in err, err
    assert len(err.strip().splitlines()) == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cam.csv"]


def test_camera_option_needs_the_trajectory_scene(tmp_path, capsys):
    cam = _csv(tmp_path / "cam.csv", [[0, 0, 0, 0, 0, 0, 0], [1, 0, 0, 1, 0, 0, 0]])
    rc = _run(["synth", str(tmp_path / "x.mp4"), "--scene", "rotate", "--camera", str(cam)])
    assert rc == 2 and "--camera is for --scene trajectory" in capsys.readouterr().err


def test_output_that_is_an_input_is_refused(tmp_path):
    cam = _csv(tmp_path / "c.truth.npz", [[0, 0, 0, 0, 0, 0, 0], [1, 0, 0, 1, 0, 0, 0]])
    before = cam.read_bytes()
    with pytest.raises(InputError, match="output is the input"):
        synthesize_trajectory(cam, tmp_path / "c.mp4", size=(64, 32))
    assert cam.read_bytes() == before and not (tmp_path / "c.mp4").exists()


def test_cli_writes_clip_covering_the_span(tmp_path, capsys):
    # Poses from t = 5 s to 5.3 s: 10 frames at 30 fps, video time 0 = camera time 5 s.
    cam = _csv(tmp_path / "cam.csv", [[5, 0, 0, 0, 0, 0, 0], [5.3, 0, 0, 0.4, 9, 0, 0]])
    out = tmp_path / "c.mp4"
    rc = main(
        [
            "synth",
            str(out),
            "--scene",
            "trajectory",
            "--camera",
            str(cam),
            "--size",
            "64x32",
            "--interp",
            "linear",
        ]
    )
    assert rc == 0 and "wrote" in capsys.readouterr().out
    assert probe(out).n_frames == 10
    tru = load_truth(truth_path_for(out))
    assert tru.meta["camera"]["time_offset_s"] == 5.0
    np.testing.assert_allclose(tru.meta["trajectory"]["position_m"][9], [0, 0, 0.4], atol=1e-9)
    # Yaw right at 30 deg/s (9 deg in 0.3 s) = +30 deg/s about the camera's +y (up) axis,
    # 0.4 m in 0.3 s along +z.
    traj = tru.meta["trajectory"]
    assert traj["omega_cam_dps"][3] == pytest.approx([0, 30.0, 0], abs=1e-6)
    assert np.linalg.norm(traj["velocity_cam_mps"][3]) == pytest.approx(0.4 / 0.3)


def test_sphere_mode_matches_truth_on_small_walk(tmp_path):
    """CI-sized version of bench/trajectory_accuracy.py: a turning walk, 512x256, sphere
    mode (DIS), window POF within 10 % median of the truth."""
    from simulator.media.gridfile import load_grid
    from simulator.preprocess import SphereConfig, preprocess_sphere
    from simulator.sphere.windows import grid_preset
    from simulator.synth import window_truth_dps

    tr = _walk(seconds=0.2, step=0.05, turn_dps=30.0)
    video, tpath, cfg = synthesize_trajectory(tr, tmp_path / "w.mp4", fps=30, size=(512, 256))
    grid = grid_preset("default")
    g = preprocess_sphere(
        video, tmp_path / "g.npz", grid=grid, config=SphereConfig(tile_size=128), progress=False
    )
    est = load_grid(g).pof_dps[1:].astype(float)
    scene = make_trajectory_scene(cfg, tr)
    truth = window_truth_dps(scene, grid, load_truth(tpath).time_s, rays=16)[1:]
    rel = np.abs(est - truth) / truth
    assert np.median(rel) < 0.10, np.median(rel)
    assert np.corrcoef(est.ravel(), truth.ravel())[0, 1] > 0.8


def test_cli_choice_list_matches_module():
    from simulator.core import choices
    from simulator.synth import camera_path

    assert camera_path.INTERPS == choices.CAMERA_INTERPS
