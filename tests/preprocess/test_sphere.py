"""Sphere mode (simulator/preprocess/sphere.py, simulator/sphere/cells.py, simulator/epof/exact.py) and headset profiles (simulator/sphere/headsets.py)."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from media_helpers import write_clip

import simulator.preprocess.sphere
from simulator.core.errors import InputError
from simulator.epof import ViewportQuery, viewport_epof
from simulator.media.gridfile import load_grid, require_field, save_grid
from simulator.preprocess import (
    FieldEstimator,
    SphereConfig,
    field_from_frames,
    field_meta,
    preprocess_sphere,
)
from simulator.preprocess.sphere import _FieldRows
from simulator.sphere.cells import CellGrid, Frustum, viewport_weights, window_pof
from simulator.sphere.geometry import head_rotation, perspective_rays
from simulator.sphere.headsets import HEADSETS, get_headset, resolve_fov
from simulator.sphere.windows import grid_preset

CELL = 4.0


def _smooth_field(seed: int, cell: float = CELL, T: int = 1) -> np.ndarray:
    """A smooth positive random field (T, n_lat, n_lon) from a few dipoles/quadrupoles."""
    rng = np.random.default_rng(seed)
    cells = CellGrid(cell)
    lon, lat = cells.centres_lonlat()
    LON, LAT = np.meshgrid(lon, lat)
    d = np.stack([np.cos(LAT) * np.sin(LON), np.sin(LAT), np.cos(LAT) * np.cos(LON)], -1)
    out = np.empty((T, *cells.shape), np.float32)
    for t in range(T):
        a, b = rng.normal(size=(2, 3))
        out[t] = 45 + 8 * (d @ a) + 5 * (d @ b) ** 2 + 3 * np.sin(3 * LON) * np.cos(LAT)
    return out


def _reference_epof(field2d, cell, R, frustum, n=256) -> float:
    """Brute force: dense rays through the (possibly asymmetric) frustum, nearest cell."""
    lf, rt, dn, up = (
        math.tan(math.radians(a))
        for a in (frustum.left_deg, frustum.right_deg, frustum.down_deg, frustum.up_deg)
    )
    u = -lf + (np.arange(n) + 0.5) / n * (lf + rt)
    v = -dn + (np.arange(n) + 0.5) / n * (dn + up)
    uu, vv = np.meshgrid(u, v)
    r2 = 1 + uu**2 + vv**2
    dirs = np.stack([uu, vv, np.ones_like(uu)], -1) / np.sqrt(r2)[..., None]
    sa = 1.0 / (r2 * np.sqrt(r2))  # du dv / r^3 (constant du dv cancels)
    world = dirs.reshape(-1, 3) @ R.T
    lon = np.arctan2(world[:, 0], world[:, 2])
    lat = np.arcsin(np.clip(world[:, 1], -1, 1))
    idx = CellGrid(cell).index(lon, lat)
    return float((field2d.ravel()[idx] * sa.ravel()).sum() / sa.sum())


# ----------------------------------------------------------------------------- cells
def test_cells_solid_angle_and_index():
    cells = CellGrid(CELL)
    assert cells.shape == (45, 90)
    assert cells.solid_angles().sum() == pytest.approx(4 * math.pi, rel=1e-12)
    lon, lat = cells.centres_lonlat()
    LON, LAT = np.meshgrid(lon, lat)
    assert np.array_equal(cells.index(LON, LAT).ravel(), np.arange(cells.n_cells))
    # The seam and the poles map inside the grid.
    idx = cells.index(np.array([math.pi, -math.pi]), np.array([math.pi / 2, -math.pi / 2]))
    assert idx.min() >= 0 and idx.max() < cells.n_cells


@pytest.mark.parametrize("bad", [0, 7, 50, -4, float("nan")])
def test_cells_bad_size(bad):
    with pytest.raises(InputError, match="divide 180"):
        CellGrid(bad)


# ----------------------------------------------------------------------- integration
@pytest.mark.parametrize("fov", [(107, 107), (60, 90), (150, 40)])
def test_viewport_weights_sum_to_view_solid_angle(fov):
    h, v = fov
    true = 4 * math.asin(math.sin(math.radians(h) / 2) * math.sin(math.radians(v) / 2))
    rng = np.random.default_rng(1)
    ypr = np.column_stack(
        [rng.uniform(-180, 180, 40), rng.uniform(-90, 90, 40), rng.uniform(-180, 180, 40)]
    )
    R = head_rotation(ypr[:, 0], ypr[:, 1], ypr[:, 2]).as_matrix()
    w = viewport_weights(CELL, R, Frustum.symmetric(h, v))
    assert np.abs(w.sum(axis=1) / true - 1).max() < 0.015


@settings(max_examples=25, deadline=None)
@given(
    yaw=st.floats(-180, 180),
    pitch=st.floats(-90, 90),
    roll=st.floats(-180, 180),
    headset=st.sampled_from([None, *HEADSETS]),
    seed=st.integers(0, 5),
)
def test_exact_epof_matches_dense_ray_reference(yaw, pitch, roll, headset, seed):
    """Exact EPOF (analytic cell coverage, and the binned fast query) against >= 256^2
    rays per viewport: within 1% at any orientation, roll and asymmetric frusta included."""
    f = _smooth_field(seed)
    fr = Frustum.symmetric(107) if headset is None else Frustum.from_headset(headset)
    R = head_rotation(yaw, pitch, roll).as_matrix()
    ref = _reference_epof(f[0], CELL, R, fr)
    w = viewport_weights(CELL, R, fr)
    assert float(w @ f[0].ravel() / w.sum()) == pytest.approx(ref, rel=0.01)
    got = viewport_epof(f, CELL, yaw, pitch, roll, frustum=fr)[0]
    assert got == pytest.approx(ref, rel=0.01)


def test_query_equals_weights_on_bins_and_is_yaw_shift_invariant():
    f = _smooth_field(3)[0]
    fr = Frustum.symmetric(100, 90)
    q = ViewportQuery(CELL, fr, step_deg=0.5)
    for yaw, pitch, roll in [(12.5, 20.0, 5.0), (-179.5, -88.0, 0.0), (90.0, 45.5, -170.0)]:
        w = viewport_weights(CELL, head_rotation(yaw, pitch, roll).as_matrix(), fr)
        assert q(f, yaw, pitch, roll) == pytest.approx(float(w @ f.ravel() / w.sum()), rel=1e-5)
    # A field rotated in longitude by k cells, looked at with yaw + k cells: same EPOF.
    g = np.roll(f, 7, axis=1)
    assert q(g, 10.0 + 7 * CELL, 30.0, 10.0) == pytest.approx(q(f, 10.0, 30.0, 10.0), rel=1e-12)


def test_uniform_field_gives_constant_everywhere():
    f = np.full((3, *CellGrid(CELL).shape), 12.5, np.float32)
    e = viewport_epof(f, CELL, [0, 170, -60], [0, 89, -45], [0, 30, 180], hfov_deg=80, vfov_deg=110)
    assert np.allclose(e, 12.5, rtol=1e-6)
    dps, px = window_pof(f, CELL, grid_preset("paper-198", hfov_deg=90), fps=30.0)
    assert dps.shape == (3, 11, 18) and px.shape == dps.shape
    assert np.allclose(dps, 12.5, rtol=1e-5)
    # Pixel measure: linear in the field, larger for a smaller FOV at the same window size.
    _, px2 = window_pof(2 * f, CELL, grid_preset("paper-198", hfov_deg=90), fps=30.0)
    assert np.allclose(px2, 2 * px, rtol=1e-5)
    _, px_narrow = window_pof(f, CELL, grid_preset("paper-198", hfov_deg=60), fps=30.0)
    assert px_narrow.mean() > px.mean()


# ---------------------------------------------------------------------- field on video
def _rotating_frames(n, omega_dps, axis, size=(512, 256), fps=30.0):
    from simulator.synth import SynthConfig, make_scene

    sc = make_scene(SynthConfig(scene="rotate", size=size, axis=axis, omega_dps=omega_dps, fps=fps))
    frames = [cv2.cvtColor(sc.render(k / fps), cv2.COLOR_RGB2GRAY) for k in range(n)]
    return frames, sc


def _window_truth(sc, grid, t):
    dirs, sa = perspective_rays((48, 48), grid.hfov_deg, grid.vfov_deg)
    pitch, yaw = grid.centres_deg()
    R = head_rotation(yaw.ravel(), pitch.ravel(), 0.0).as_matrix()
    world = np.einsum("nij,hwj->nhwi", R, dirs.astype(float))
    sp = sc.speed_dps(t, world)
    return (sp * sa).sum(axis=(1, 2)) / sa.sum()


def test_field_of_rotating_panorama_matches_truth():
    """Small CI version of bench/sphere_accuracy.py: window POF derived from the field
    within 10% median of the analytic truth (oblique axis, 30 deg/s)."""
    fps = 30.0
    frames, sc = _rotating_frames(4, 30.0, (0.3, 0.8, 0.2), fps=fps)
    field = field_from_frames(frames, (512, 256), fps, SphereConfig(tile_size=128))
    assert field.shape == (4, 45, 90) and field.dtype == np.float32
    assert np.array_equal(field[0], field[1])  # frame 0 repeats frame 1
    grid = grid_preset("default")
    dps, _ = window_pof(field, CELL, grid, fps)
    truth = _window_truth(sc, grid, 1.5 / fps)
    rel = np.abs(dps[1:].mean(axis=0).ravel() - truth) / truth
    assert np.median(rel) < 0.10


def test_still_video_gives_near_zero_field():
    frames, _ = _rotating_frames(1, 30.0, (0, 1, 0))
    field = field_from_frames([frames[0]] * 3, (512, 256), 30.0, SphereConfig(tile_size=96))
    assert float(np.abs(field).max()) < 0.5


def test_estimator_bad_input():
    with pytest.raises(InputError, match="even width"):
        FieldEstimator((501, 250), 30.0)
    with pytest.raises(InputError, match="frame rate"):
        FieldEstimator((512, 256), 0.0)
    with pytest.raises(InputError, match="at least 2 frames"):
        field_from_frames([np.zeros((256, 512), np.uint8)], (512, 256), 30.0)
    with pytest.raises(InputError, match="tile FOV"):
        SphereConfig(tile_fov_deg=80)
    with pytest.raises(InputError, match="half-angle"):
        Frustum(0.0, 40, 40, 40)


# -------------------------------------------------------------------------- grid files
def _meta():
    return {
        "fps": 30.0,
        "n_frames": 2,
        "flow": {"method": "dis"},
        "layout": "mono",
        "eye": "left",
        "video": {
            "path": "x.mp4",
            "width": 512,
            "height": 256,
            "sar": 1.0,
            "content_hash": "sha256:0",
        },
    }


def test_query_on_grid_without_field_says_how_to_make_one(tmp_path):
    grid = grid_preset("paper-198")
    z = np.zeros((2, *grid.shape), np.float32)
    save_grid(tmp_path / "paper.npz", z, z, grid, _meta())
    g = load_grid(tmp_path / "paper.npz")
    with pytest.raises(InputError) as e:
        require_field(g)
    msg = str(e.value)
    assert (
        "no sphere-mode field" in msg
        and "vimsim preprocess VIDEO -o GRID.npz --method sphere" in msg
    )
    assert "\n" not in msg


def test_grid_with_field_round_trip(tmp_path):
    grid = grid_preset("default")
    f = _smooth_field(0, T=2)
    dps, px = window_pof(f, CELL, grid, 30.0)
    meta = {**_meta(), "field": field_meta(SphereConfig(cell_deg=CELL))}
    save_grid(tmp_path / "s.npz", dps, px, grid, meta, field_dps=f.astype(np.float16))
    field, cells = require_field(load_grid(tmp_path / "s.npz"))
    assert cells.cell_deg == CELL and field.shape == f.shape and field.dtype == np.float32
    assert np.allclose(field, f, rtol=1e-3)
    # A field of the wrong shape for its meta is refused.
    bad = {**meta, "field": field_meta(SphereConfig(cell_deg=5.0))}
    save_grid(tmp_path / "b.npz", dps, px, grid, bad, field_dps=f)
    with pytest.raises(InputError, match="expected"):
        require_field(load_grid(tmp_path / "b.npz"))


def test_preprocess_sphere_writes_a_grid_file(tmp_path):
    vid = _rot_video(tmp_path / "rot.mp4")
    grid = grid_preset("paper-198", hfov_deg=90)
    out = preprocess_sphere(
        vid, tmp_path / "g.npz", grid=grid, config=SphereConfig(tile_size=96), progress=False
    )
    g = load_grid(out)
    assert g.pof_dps.shape == (3, 11, 18) and g.meta["method"] == "sphere"
    assert g.meta["grid"]["hfov_deg"] == 90
    field, cells = require_field(g)
    assert field.shape == (3, *cells.shape) and g.field_dps.dtype == np.float16
    assert 20 < float(np.median(g.pof_dps[1])) < 40  # yaw pan at 30 deg/s
    with pytest.raises(InputError, match="at least 2"):
        preprocess_sphere(vid, tmp_path / "h.npz", grid=grid, start_s=0.07, progress=False)
    assert not (tmp_path / "h.npz").exists()


def _rot_video(path, n: int = 3):
    """A gray panorama panning at 30 deg/s about the vertical axis (the writer's defaults)."""
    frames, _ = _rotating_frames(n, 30.0, (0, 1, 0))
    rgb = (np.repeat(fr[..., None], 3, axis=2) for fr in frames)
    return write_clip(path, rgb, 30.0, preset="veryfast")


def test_preprocess_sphere_checks_output_dir_before_any_work(tmp_path, monkeypatch):
    vid = _rot_video(tmp_path / "rot.mp4")

    def no_work(*a, **k):
        raise AssertionError("field computed before the output directory was checked")

    monkeypatch.setattr(simulator.preprocess.sphere, "field_from_video", no_work)
    out = tmp_path / "missing" / "g.npz"
    with pytest.raises(InputError, match="output directory .* does not exist"):
        preprocess_sphere(vid, out, grid=grid_preset("default"), progress=False)


def test_preprocess_sphere_frame_range_is_paper_modes(tmp_path):
    """One --start/--end rule for both methods: a start past the end says so."""
    vid = _rot_video(tmp_path / "rot.mp4")
    grid = grid_preset("default")
    with pytest.raises(InputError, match="past the end of the video"):
        preprocess_sphere(vid, tmp_path / "g.npz", grid=grid, start_s=5.0, progress=False)
    with pytest.raises(InputError, match="--start must be seconds >= 0"):
        preprocess_sphere(vid, tmp_path / "g.npz", grid=grid, start_s=-1.0, progress=False)
    assert not (tmp_path / "g.npz").exists()


def test_preprocess_sphere_builds_the_flow_backend_once(tmp_path, monkeypatch):
    """A torch:MODEL.pt is loaded and validated once, not once per use."""
    import simulator.flow.base as F
    import simulator.preprocess.sphere as PS

    vid = _rot_video(tmp_path / "rot.mp4")
    calls = []
    real = F.make_backend

    def counting(spec, size=None):
        calls.append((spec, size))
        return real(spec, size=size)

    monkeypatch.setattr(PS, "make_backend", counting)
    out = preprocess_sphere(
        vid,
        tmp_path / "g.npz",
        grid=grid_preset("paper-198"),
        config=SphereConfig(tile_size=96),
        flow="dis",
        progress=False,
    )
    assert calls == [("dis", (96, 96))]
    meta = load_grid(out).meta
    assert meta["flow"]["method"] == "dis" and meta["field"]["tiles"]["stride"] == 2


@pytest.mark.parametrize(
    ("fov", "match"),
    [
        ((float("nan"), None), r"viewport: hfov must be degrees in \(0, 180\)"),
        ((90.0, float("inf")), r"viewport: vfov must be degrees in \(0, 180\)"),
        (("wide", None), r"viewport: hfov must be degrees in \(0, 180\)"),
        ((180.0, None), r"viewport: hfov must be degrees in \(0, 180\)"),
        ((179.5, 90.0), "viewport: hfov must be at most 179 degrees"),
    ],
)
def test_frustum_symmetric_uses_the_one_fov_rule(fov, match):
    with pytest.raises(InputError, match=match):
        Frustum.symmetric(*fov)
    assert Frustum.symmetric(179.0).hfov_deg == 179.0


# ---------------------------------------------------------------------------- headsets
def test_headset_profiles():
    assert set(HEADSETS) >= {"vive-pro-eye", "vive-focus-3", "pimax-crystal", "quest-2"}
    v = get_headset("vive-pro-eye")
    assert (v.hfov_deg, v.vfov_deg) == (107.0, 107.0) and v.approximate
    f3 = get_headset("vive-focus-3")
    assert f3.hfov_deg == pytest.approx(98.35) and f3.vfov_deg == pytest.approx(96.58)
    assert f3.half_angles_deg("right") == (40.13, 58.22, 48.31, 48.27)  # mirrored
    for h in HEADSETS.values():
        assert h.source
        assert 60 < h.hfov_deg < 130 and 60 < h.vfov_deg < 130
    fr = Frustum.from_headset("pimax-crystal", "right")
    assert fr.hfov_deg == pytest.approx(93.30) and fr.left_deg == pytest.approx(41.65)


def test_headset_bad_input_and_resolve_fov():
    with pytest.raises(InputError, match="vive-pro-eye"):
        get_headset("rift-dk1")
    assert resolve_fov() == (107.0, 107.0)
    assert resolve_fov(headset="quest-2") == (97.0, 98.0)
    assert resolve_fov(fov_deg=90) == (90.0, 90.0)
    assert resolve_fov(hfov_deg=100, vfov_deg=80) == (100.0, 80.0)
    with pytest.raises(InputError, match="only one"):
        resolve_fov(headset="quest-2", fov_deg=90)
    with pytest.raises(InputError, match="hfov"):
        resolve_fov(hfov_deg=-5)
    # The one FOV rule (geometry.check_fov): NaN and non-numbers are InputErrors too.
    with pytest.raises(InputError, match=r"hfov must be degrees in \(0, 180\); got nan"):
        resolve_fov(fov_deg=float("nan"))
    with pytest.raises(InputError, match=r"hfov must be degrees in \(0, 180\); got wide"):
        resolve_fov(hfov_deg="wide")


# --------------------------------------------------- integration: the commands, sphere mode


def test_compute_epof_uses_the_field(tmp_path):
    from simulator.epof import compute_epof
    from simulator.traces.path import synth

    grid = grid_preset("default")
    f = _smooth_field(2, T=4)
    dps, px = window_pof(f, CELL, grid, 30.0)
    meta = {**_meta(), "n_frames": 4, "field": field_meta(SphereConfig(cell_deg=CELL))}
    save_grid(tmp_path / "s.npz", dps, px, grid, meta, field_dps=f)
    g = load_grid(tmp_path / "s.npz")
    hp = synth("sine", 1.0, rate_hz=60.0)
    auto = compute_epof(g, hp, hfov_deg=90.0, vfov_deg=70.0)
    yaw, pitch, roll = hp.sample_angles_deg(np.arange(4) / 30.0)
    exact = viewport_epof(f, CELL, yaw, pitch, roll, hfov_deg=90.0, vfov_deg=70.0)
    assert np.allclose(auto.epof_dps, exact, rtol=1e-9) and auto.meta["method"] == "sphere"
    assert compute_epof(g, hp, method="paper").meta["method"] == "paper"
    z = np.zeros((4, *grid.shape), np.float32)
    save_grid(tmp_path / "p.npz", z, z, grid, {**_meta(), "n_frames": 4})
    with pytest.raises(InputError, match="--method sphere"):
        compute_epof(load_grid(tmp_path / "p.npz"), hp, method="sphere")


@pytest.mark.parametrize("expected", [2, 3, 6, 50])
def test_field_rows_grow_and_repeat_row_one(expected):
    """The field accumulator: rows in order whatever the expected count (grown when it
    was short, trimmed when long), row 0 a copy of row 1."""
    rows = _FieldRows((2, 3), expected)
    data = [np.full((2, 3), k + 1.0, np.float32) for k in range(5)]
    for d in data:
        rows.append(d)
    out = rows.result()
    assert out.shape == (6, 2, 3) and out.dtype == np.float32
    assert np.array_equal(out[1:], np.stack(data)) and np.array_equal(out[0], out[1])


def test_compute_epof_carries_an_asymmetric_headset_frustum(tmp_path):
    """The headset's per-eye frustum (not a centred view of the same FOV) reaches exact EPOF."""
    from simulator.epof import compute_epof
    from simulator.traces.path import synth

    grid = grid_preset("default")
    f = _smooth_field(5, T=3)
    dps, px = window_pof(f, CELL, grid, 30.0)
    meta = {**_meta(), "n_frames": 3, "field": field_meta(SphereConfig(cell_deg=CELL))}
    save_grid(tmp_path / "s.npz", dps, px, grid, meta, field_dps=f)
    g = load_grid(tmp_path / "s.npz")
    hp = synth("sine", 1.0, rate_hz=60.0)
    fr = Frustum.from_headset("quest-2", "left")
    assert fr.left_deg != fr.right_deg  # the profile is asymmetric
    res = compute_epof(g, hp, frustum=fr)
    yaw, pitch, roll = hp.sample_angles_deg(np.arange(3) / 30.0)
    exact = viewport_epof(f, CELL, yaw, pitch, roll, frustum=fr)
    centred = viewport_epof(
        f, CELL, yaw, pitch, roll, frustum=Frustum.symmetric(fr.hfov_deg, fr.vfov_deg)
    )
    assert np.allclose(res.epof_dps, exact, rtol=1e-9)
    assert np.max(np.abs(exact - centred)) > 1e-3 * np.max(np.abs(exact))
    assert res.meta["frustum_deg"] == [fr.left_deg, fr.right_deg, fr.down_deg, fr.up_deg]


def _open_fds_to(path) -> int:
    import os

    fd_dir = "/proc/self/fd"
    target = os.path.realpath(path)
    n = 0
    for fd in os.listdir(fd_dir):
        try:
            n += os.path.realpath(os.readlink(os.path.join(fd_dir, fd))) == target
        except OSError:
            pass
    return n


@pytest.mark.parametrize("err", [RuntimeError, KeyboardInterrupt])
def test_field_from_video_error_in_the_consumer_stops_the_decoding_thread(tmp_path, err):
    """Decoding and tiling run a few frames ahead in a background thread (media.video.prefetch):
    an error in the caller's flow step (KeyboardInterrupt = what SIGINT raises there) stops
    that thread and closes the video before the error reaches the caller."""
    import threading
    import time

    vid = _rot_video(tmp_path / "rot.mp4", n=12)
    calls = []

    def flow(prev, cur):
        calls.append(1)
        if len(calls) == 2:
            time.sleep(0.5)  # the thread fills its queue and waits to hand on the next frame
            assert _open_fds_to(vid) >= 1  # the decoder has the file open now
            assert any(t.name == "vimsim-prefetch" for t in threading.enumerate())
            raise err("stop here")
        return np.zeros((*prev.shape, 2), np.float32)

    with pytest.raises(err, match="stop here") as info:
        simulator.preprocess.sphere.field_from_video(vid, SphereConfig(tile_size=32), flow=flow)
    # while the error (its traceback: the generators) is still held, e.g. being reported
    assert not any(t.name == "vimsim-prefetch" for t in threading.enumerate())
    assert _open_fds_to(vid) == 0
    assert info.value.args == ("stop here",)
