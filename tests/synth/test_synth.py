"""Synthetic scenes: analytic truth against independent formulas and finite differences,
clip files (probe), truth files, bad input, and a small flow-accuracy check."""

from __future__ import annotations

import json
import zipfile

import numpy as np
import pytest

from simulator.cli import main
from simulator.core.errors import InputError
from simulator.media.video import probe, read_frame
from simulator.sphere.geometry import lonlat_to_dir
from simulator.synth import (
    SynthConfig,
    angular_speed_dps,
    load_texture,
    load_truth,
    make_scene,
    synthesize,
    truth_path_for,
)


def _run(argv):
    """The CLI's exit status, whether argparse exits (usage) or main returns."""
    try:
        return main(argv)
    except SystemExit as e:
        return e.code


def _unit(rng, n):
    d = rng.standard_normal((n, 3))
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def test_rotate_truth_file_is_omega_times_sin(tmp_path):
    axis = np.array([1.0, 2.0, 0.5])
    cfg = SynthConfig(
        "rotate",
        seconds=0.2,
        fps=10,
        size=(64, 32),
        axis=tuple(axis),
        omega_dps=40.0,
        truth_cell_deg=6,
    )
    video, tpath = synthesize(cfg, tmp_path / "r.mp4")
    assert tpath == truth_path_for(video) == tmp_path / "r.truth.npz"
    tr = load_truth(tpath)
    assert tr.speed_dps.shape == (2, 30, 60)
    assert tr.speed_dps_right is None
    np.testing.assert_allclose(tr.lon_deg[[0, -1]], [-177.0, 177.0])
    np.testing.assert_allclose(tr.lat_deg[[0, -1]], [87.0, -87.0])
    LO, LA = np.meshgrid(np.radians(tr.lon_deg), np.radians(tr.lat_deg))
    d = lonlat_to_dir(LO, LA)
    a = axis / np.linalg.norm(axis)
    expect = 40.0 * np.linalg.norm(np.cross(a, d), axis=-1)
    np.testing.assert_allclose(tr.speed_dps[1], expect, rtol=1e-5, atol=1e-4)
    np.testing.assert_array_equal(tr.speed_dps[0], tr.speed_dps[1])
    # No pickles; meta is JSON with the config and one pose per frame.
    with np.load(tpath, allow_pickle=False) as z:
        meta = json.loads(str(z["meta"]))
    assert meta["config"]["scene"] == "rotate"
    assert len(meta["trajectory"]["quat_xyzw"]) == 2
    assert tr.config == cfg


def test_rotate_render_moves_texture_as_documented():
    """The panorama turns right-handedly about +y (up) at omega: +z turns toward +x, so
    content at lon moves to lon + omega t (to the right)."""
    cfg = SynthConfig("rotate", seconds=1.0, fps=10, size=(256, 128), omega_dps=90.0)
    sc = make_scene(cfg)
    f0 = sc.render(0.0).astype(float)
    f1 = sc.render(0.5).astype(float)  # turned 45 deg = 32 columns
    W = 256
    err = np.abs(f1 - np.roll(f0, 32, axis=1))[32:-32].mean()
    other = np.abs(f1 - np.roll(f0, -32, axis=1))[32:-32].mean()
    assert err < 3.0 < other, (err, other)
    assert f1.shape == (128, W, 3)


@pytest.mark.parametrize(
    "scene,eye,layout",
    [
        ("coaster", "mono", "mono"),
        ("coaster", "right", "top-bottom"),
        ("forward", "left", "top-bottom"),
    ],
)
def test_speed_matches_finite_differences_of_projected_points(scene, eye, layout):
    cfg = SynthConfig(scene, seconds=4.0, layout=layout, size=(64, 32))
    sc = make_scene(cfg)
    rng = np.random.default_rng(1)
    d = _unit(rng, 400)
    h = 1e-5
    for t in (0.3, 1.7, 3.6):
        speed = sc.speed_dps(t, d, eye)
        # Static world points seen along d at time t, re-projected at t +- h.
        X = sc.eye_origin(t, eye) + sc.rotation(t).apply(d * sc.depth(t, d, eye)[:, None])
        q = [sc.rotation(s).inv().apply(X - sc.eye_origin(s, eye)) for s in (t - h, t + h)]
        q = [v / np.linalg.norm(v, axis=1, keepdims=True) for v in q]
        chord = np.linalg.norm(q[1] - q[0], axis=1)  # precise for tiny angles, unlike arccos
        fd = np.degrees(2 * np.arcsin(chord / 2) / (2 * h))
        np.testing.assert_allclose(speed, fd, rtol=2e-3, atol=2e-3)
        assert speed.max() > 5.0  # really moving


def test_coaster_has_rotation_translation_and_varying_speed():
    sc = make_scene(SynthConfig("coaster", seconds=6.0, size=(64, 32)))
    ts = np.linspace(0, 6, 25)
    w = np.array([np.linalg.norm(sc.omega_cam_dps(t)) for t in ts])
    v = np.array([np.linalg.norm(sc.velocity(t)) for t in ts])
    assert w.max() > 20.0 and v.max() / v.min() > 1.5
    roll = [abs(sc.rotation(t).as_euler("YXZ", degrees=True)[2]) for t in ts]
    assert max(roll) > 5.0  # banks into turns


def test_angular_speed_formula_pure_cases():
    d = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    # Pure translation along +z at 2 m/s: side point at 4 m moves at 0.5 rad/s, the
    # point straight ahead does not move.
    s = angular_speed_dps(d, np.zeros(3), np.array([0, 0, 2.0]), np.array([4.0, 4.0]))
    np.testing.assert_allclose(s, [np.degrees(0.5), 0.0], atol=1e-12)
    # Pure rotation about y at 10 deg/s: equator 10, any depth.
    s = angular_speed_dps(d, np.array([0, 10.0, 0]), np.zeros(3), np.array([np.inf, 1.0]))
    np.testing.assert_allclose(s, [10.0, 10.0])


def test_forward_stereo_clip_probe_and_truth(tmp_path):
    cfg = SynthConfig(
        "forward", seconds=0.5, fps=12, size=(128, 64), layout="top-bottom", truth_cell_deg=10
    )
    video, tpath = synthesize(cfg, tmp_path / "f.mp4")
    info = probe(video)
    assert (info.width, info.height, info.n_frames) == (128, 128, 6)
    assert info.fps == pytest.approx(12.0)
    tr = load_truth(tpath)
    assert tr.speed_dps.shape == tr.speed_dps_right.shape == (6, 18, 36)
    # Eyes 64 mm apart see different images (parallax) and different truth.
    top = read_frame(video, 3, layout="top-bottom", eye="left").astype(float)
    bot = read_frame(video, 3, layout="top-bottom", eye="right").astype(float)
    assert np.abs(top - bot).mean() > 1.0
    assert not np.allclose(tr.speed_dps, tr.speed_dps_right)
    # Side walls at 3 m moving past at 2 m/s: lon +-90 on the equator ~ 2/3 rad/s.
    i = np.argmin(np.abs(tr.lat_deg - 5))
    j = np.argmin(np.abs(tr.lon_deg - 85))
    cell = np.radians([tr.lon_deg[j], tr.lat_deg[i]])
    dd = lonlat_to_dir(*cell)
    r = 3.0 / dd[0]
    expect = np.degrees(2.0 * np.sqrt(1 - dd[2] ** 2) / r)
    assert tr.speed_dps[2, i, j] == pytest.approx(expect, rel=0.03)


def test_bundled_texture_loads_and_is_textured():
    tex, name = load_texture(None)
    assert tex.shape == (512, 1024, 3) and name.startswith("bundled:")
    gy, gx = np.gradient(tex.mean(axis=2))
    assert np.median(np.hypot(gx, gy)) > 1.0


def test_custom_texture_is_used(tmp_path):
    from PIL import Image

    img = np.zeros((32, 64, 3), np.uint8)
    img[:, :32] = 255
    Image.fromarray(img).save(tmp_path / "t.png")
    sc = make_scene(SynthConfig("rotate", size=(64, 32), texture=str(tmp_path / "t.png")))
    f = sc.render(0.0)
    assert f[:, 5].mean() > 200 and f[:, 60].mean() < 50


@pytest.mark.parametrize(
    "args,needle",
    [
        (["--scene", "spin"], "invalid choice"),
        (["--scene", "rotate", "--size", "300x200"], "2:1"),
        (["--scene", "rotate", "--seconds", "0"], "--seconds"),
        (["--scene", "rotate", "--seconds", "-2"], "--seconds"),
        (["--scene", "rotate", "--fps", "0"], "--fps"),
        (["--scene", "rotate", "--fps", "1", "--seconds", "1"], "at least 2"),
        (["--scene", "forward", "--speed", "0"], "--speed"),
        (["--scene", "forward", "--speed", "-3"], "--speed"),
        (["--scene", "rotate", "--axis", "0,0,0"], "axis"),
        (["--scene", "rotate", "--truth-cell", "7"], "divide 180"),
        (["--scene", "rotate", "--fps", "1e9", "--seconds", "0.3"], "at most 240"),
        (["--scene", "rotate", "--fps", "240", "--seconds", "1e6"], "at most 100,000"),
        (["--scene", "rotate", "--seconds", "1e308", "--fps", "240"], "at most 100,000"),
        (["--scene", "rotate", "--crf", "99"], "integer 0..51"),
        (["--scene", "rotate", "--crf", "-1"], "integer 0..51"),
    ],
)
def test_bad_input_one_line_exit_2(tmp_path, capsys, args, needle):
    out = tmp_path / "x.mp4"
    rc = _run(["synth", str(out), *args])
    err = capsys.readouterr().err
    assert rc == 2
    assert needle in err
    assert len(err.strip().splitlines()) == 1
    assert not out.exists() and not truth_path_for(out).exists()


def test_texture_not_an_image(tmp_path, capsys):
    bad = tmp_path / "notes.png"
    bad.write_text("not an image\n")
    out = tmp_path / "x.mp4"
    rc = main(["synth", str(out), "--scene", "rotate", "--texture", str(bad)])
    err = capsys.readouterr().err
    assert rc == 2
    assert "texture is not a readable image" in err and str(bad) in err
    assert len(err.strip().splitlines()) == 1
    assert not out.exists()
    rc = main(["synth", str(out), "--scene", "rotate", "--texture", str(tmp_path / "missing.jpg")])
    assert rc == 2 and "not found" in capsys.readouterr().err


def test_rotate_texture_must_be_2_to_1(tmp_path, capsys):
    from PIL import Image

    tex = tmp_path / "photo.png"
    Image.fromarray(np.zeros((216, 384, 3), np.uint8)).save(tex)  # 16:9, like 3840x2160
    out = tmp_path / "x.mp4"
    rc = main(["synth", str(out), "--scene", "rotate", "--texture", str(tex), "--seconds", "0.1"])
    err = capsys.readouterr().err
    assert rc == 2
    assert f"{tex}: rotate texture" in err and "2:1" in err and "384x216" in err
    assert len(err.strip().splitlines()) == 1
    assert not out.exists() and not truth_path_for(out).exists()
    # The box scenes tile any texture.
    make_scene(SynthConfig("forward", seconds=0.1, size=(64, 32), texture=str(tex)))


def test_synthesize_refuses_bad_crf(tmp_path):
    cfg = SynthConfig("rotate", seconds=0.1, size=(64, 32))
    for crf in (52, -1, 2.5, True):
        with pytest.raises(InputError, match="crf must be an integer 0..51"):
            synthesize(cfg, tmp_path / "x.mp4", crf=crf)
    assert not (tmp_path / "x.mp4").exists()


def test_argparse_errors_exit_2(tmp_path):
    with pytest.raises(SystemExit) as e:
        main(["synth", str(tmp_path / "x.mp4"), "--scene", "spin"])
    assert e.value.code == 2


def test_load_truth_rejects_other_files(tmp_path):
    p = tmp_path / "g.npz"
    np.savez(p, a=np.zeros(3))
    with pytest.raises(InputError, match="not a vimsim truth file"):
        load_truth(p)
    (tmp_path / "z.npz").write_text("x")
    with pytest.raises(InputError):
        load_truth(tmp_path / "z.npz")
    assert not zipfile.is_zipfile(tmp_path / "z.npz")


def test_cli_synth_writes_clip(tmp_path, capsys):
    out = tmp_path / "c.mp4"
    rc = main(
        [
            "synth",
            str(out),
            "--scene",
            "coaster",
            "--seconds",
            "0.25",
            "--fps",
            "8",
            "--size",
            "64x32",
        ]
    )
    assert rc == 0
    assert "wrote" in capsys.readouterr().out
    info = probe(out)
    assert (info.width, info.height, info.n_frames, info.fps) == (64, 32, 2, 8.0)
    assert load_truth(truth_path_for(out)).speed_dps.shape == (2, 45, 90)


# Measured medians: rotate 0.005, forward 0.013.
@pytest.mark.parametrize("scene,bound", [("rotate", 0.05), ("forward", 0.05)])
def test_preprocess_matches_truth_on_small_clip(tmp_path, scene, bound):
    """CI-sized version of bench/accuracy.py: DIS on a 384x192 clip, 8 x 3 windows."""
    from simulator.media.gridfile import load_grid
    from simulator.preprocess import preprocess_video
    from simulator.sphere.windows import WindowGrid
    from simulator.synth import window_truth_dps

    cfg = SynthConfig(
        scene, seconds=0.4, fps=10, size=(384, 192), axis=(1.0, 2.0, 0.5), omega_dps=40.0
    )
    video, tpath = synthesize(cfg, tmp_path / "c.mp4")
    grid = WindowGrid(
        yaw_step_deg=45, pitch_step_deg=30, pitch_min_deg=-30, pitch_max_deg=30, size=(64, 64)
    )
    preprocess_video(video, tmp_path / "g.npz", grid=grid, flow="dis", progress=False, threads=1)
    est = load_grid(tmp_path / "g.npz").pof_dps[1:].astype(float)
    truth = window_truth_dps(make_scene(cfg), grid, load_truth(tpath).time_s, rays=16)[1:]
    rel = np.abs(est - truth) / truth
    assert np.median(rel) < bound, np.median(rel)
    # The windows' truths differ by up to 2x (rotate) and more (forward): the estimate
    # must follow that pattern, not just its mean.
    assert np.corrcoef(est.ravel(), truth.ravel())[0, 1] > 0.8


def test_mip_texture_fades_to_the_mean_past_its_coarsest_level():
    """Footprints beyond the pyramid give the texture's mean colour (no moire at any
    distance); one level finer than the mean level, the coarsest real level is unchanged."""
    from simulator.synth.textures import _MipTexture

    rng = np.random.default_rng(0)
    img = rng.integers(0, 256, (64, 128, 3), dtype=np.uint8)
    mip = _MipTexture(img)
    u = rng.uniform(0, 1000, (8, 8)).astype(np.float32)
    v = rng.uniform(0, 1000, (8, 8)).astype(np.float32)
    far = mip.sample(u, v, np.full((8, 8), 40.0, np.float32))
    mean = img.reshape(-1, 3).mean(axis=0)
    assert np.allclose(far, mean, atol=0.5)
    coarse = mip.sample(u, v, np.full((8, 8), mip.n_levels - 2.0, np.float32))
    assert coarse.std(axis=(0, 1)).max() > 1.0  # the coarsest real level still has detail
