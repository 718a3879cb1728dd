"""The EPOF split into rotation and translation (simulator/epof/parts.py) and ``--flow-weights``."""

from __future__ import annotations

import numpy as np
import pytest

from simulator.cli import main
from simulator.core.errors import InputError
from simulator.epof import compute_epof, read_epof_csv, viewport_epof
from simulator.epof.parts import parse_flow_weights, rotation_share, viewport_parts
from simulator.media.gridfile import load_grid, save_grid
from simulator.preprocess import SphereConfig, field_meta
from simulator.sphere.cells import CellGrid, window_pof
from simulator.sphere.geometry import lonlat_to_dir
from simulator.sphere.windows import grid_preset
from simulator.traces.readers import load_headpath

CELL = 6.0
T = 5


def _meta():
    return {
        "fps": 30.0,
        "n_frames": T,
        "flow": {"method": "test"},
        "layout": "mono",
        "eye": "left",
        "video": {"path": "x.mp4", "width": 512, "height": 256, "sar": 1.0,
                  "content_hash": "sha256:0"},
        "field": field_meta(SphereConfig(cell_deg=CELL)),
    }  # fmt: skip


def _grid(path, *, parts=True, trans_scale=1.0):
    """A sphere grid whose field is a camera rotation (omega) plus a translational
    field: s = |omega x d| + s_t (speeds of motions at right angles would not add; the
    split does not care how s was made)."""
    rng = np.random.default_rng(0)
    cells = CellGrid(CELL)
    lon, lat = cells.centres_lonlat()
    d = lonlat_to_dir(*np.meshgrid(lon, lat))
    om = rng.normal(0, 40, (T, 3))
    sr = np.linalg.norm(np.cross(om[:, None, None], d[None]), axis=-1)
    st = trans_scale * (20 + 10 * rng.random((T, *cells.shape)))
    f = (sr + st).astype(np.float32)
    grid = grid_preset("default")
    dps, px = window_pof(f, CELL, grid, 30.0)
    kw = {}
    if parts:
        kw = {
            "field_trans_dps": st.astype(np.float32),
            "extras": {
                "ego_omega_dps": om.astype(np.float32),
                "ego_confidence": np.ones(T, np.float32),
            },
        }
    save_grid(path, dps, px, grid, _meta(), field_dps=f, **kw)
    return path, sr, st


def test_parse_flow_weights():
    assert parse_flow_weights("rot=1,trans=0.5") == (1.0, 0.5)
    assert parse_flow_weights("trans=2") == (1.0, 2.0)
    assert parse_flow_weights(" ROT = 0 , trans=1 ") == (0.0, 1.0)
    for bad, msg in (
        ("rot=1,speed=2", "unknown part 'speed=2'"),
        ("rot", "unknown part"),
        ("rot=-1", "finite number >= 0"),
        ("trans=inf", "finite number >= 0"),
        ("trans=x", "finite number >= 0"),
        ("rot=0,trans=0", "both 0"),
        ("rot=1,rot=2", "given twice"),
    ):
        with pytest.raises(InputError, match=msg):
            parse_flow_weights(bad)


def test_parts_add_up_and_follow_the_definition(tmp_path):
    path, sr, st = _grid(tmp_path / "g.npz")
    g = load_grid(path)
    yaw, pitch, roll = np.linspace(-90, 90, T), np.linspace(-30, 30, T), np.zeros(T)
    rot, trans = viewport_parts(g, yaw, pitch, roll, hfov_deg=100, vfov_deg=90)
    total = viewport_epof(g.field_dps, CELL, yaw, pitch, roll, hfov_deg=100, vfov_deg=90)
    assert np.allclose(rot + trans, total, rtol=1e-9)
    # rotation part = viewport mean of s * s_r / (s_r + s_t), here = the mean of s_r
    ref = viewport_epof(sr, CELL, yaw, pitch, roll, hfov_deg=100, vfov_deg=90)
    assert np.allclose(rot, ref, rtol=2e-3)
    share = rotation_share(g.field_dps[:], st, g.extras["ego_omega_dps"], CellGrid(CELL))
    assert share.shape == (T, *CellGrid(CELL).shape) and 0 <= share.min() and share.max() <= 1
    # pure rotation: all of it is rotation
    p0, _, _ = _grid(tmp_path / "r.npz", trans_scale=0.0)
    r0, t0 = viewport_parts(load_grid(p0), yaw, pitch, roll)
    assert np.allclose(t0, 0, atol=1e-6) and np.all(r0 > 1)


def test_parts_of_a_field_in_memory_beside_a_lazy_one(tmp_path):
    """A study worker holds the field in memory while the translational field stays lazy
    (read chunk by chunk): the parts are the same as with both lazy, in small chunks too."""
    import dataclasses

    path, _, _ = _grid(tmp_path / "g.npz")
    yaw, pitch, roll = np.linspace(-90, 90, T), np.linspace(-30, 30, T), np.zeros(T)
    want = viewport_parts(load_grid(path), yaw, pitch, roll, hfov_deg=100, vfov_deg=90)
    g = load_grid(path)
    g.field_trans_dps.chunk_rows = 2  # several chunks of the lazy field
    mixed = dataclasses.replace(g, field_dps=np.asarray(g.field_dps, np.float32))
    got = viewport_parts(mixed, yaw, pitch, roll, hfov_deg=100, vfov_deg=90)
    assert np.allclose(got[0], want[0], rtol=1e-9) and np.allclose(got[1], want[1], rtol=1e-9)


def test_parts_of_lazy_fields_kept_in_a_folder(tmp_path):
    """keep_parts_in(folder): the rotational part of lazy fields (a long video in a study
    worker) is computed once into a raw file and read from it; the same parts as computed
    chunk by chunk; a changed grid file gets a new file."""
    import os

    from simulator.epof.parts import keep_parts_in
    from simulator.media.lazyfield import spool

    path, _, _ = _grid(tmp_path / "g.npz")
    yaw, pitch, roll = np.linspace(-90, 90, T), np.linspace(-30, 30, T), np.zeros(T)
    want = viewport_parts(load_grid(path), yaw, pitch, roll, hfov_deg=100, vfov_deg=90)
    keep = tmp_path / "parts"
    keep_parts_in(keep)
    try:
        g = load_grid(path)
        g.field_dps.chunk_rows = g.field_trans_dps.chunk_rows = 2
        got = viewport_parts(g, yaw, pitch, roll, hfov_deg=100, vfov_deg=90)
        (f,) = keep.iterdir()
        assert f.name.endswith(".rot.f32") and f.stat().st_size == 4 * T * np.prod(CellGrid(CELL).shape)
        os.utime(f, ns=(0, 0))
        again = viewport_parts(g, yaw, pitch, roll, hfov_deg=100, vfov_deg=90)
        assert f.stat().st_mtime_ns == 0  # made once, read since
        for a in (got, again):
            assert np.allclose(a[0], want[0], rtol=1e-6) and np.allclose(a[1], want[1], rtol=1e-5)
        _grid(path, trans_scale=0.5)  # the grid file changes: another part file
        viewport_parts(load_grid(path), yaw, pitch, roll, hfov_deg=100, vfov_deg=90)
        assert len(list(keep.iterdir())) == 2
    finally:
        keep_parts_in(None)
    raw = spool(load_grid(path).field_dps, tmp_path / "f.f32")  # a field's raw copy
    assert np.array_equal(np.asarray(raw), np.asarray(load_grid(path).field_dps, np.float32))


def _path(tmp_path):
    p = tmp_path / "p.csv"
    p.write_text("time_s,yaw_deg,pitch_deg,roll_deg\n0,0,0,0\n1,30,10,0\n")
    return p


def test_epof_writes_parts_and_weights_drive_opacity(tmp_path):
    path, _, _ = _grid(tmp_path / "g.npz")
    hp = _path(tmp_path)
    assert main(["epof", str(path), str(hp), "-o", str(tmp_path / "e.csv")]) == 0
    r = read_epof_csv(tmp_path / "e.csv")
    assert np.allclose(r.epof_rot_dps + r.epof_trans_dps, r.epof_dps, atol=1e-6)
    assert main(["epof", str(path), str(hp), "-o", str(tmp_path / "w.csv"),
                 "--flow-weights", "rot=1,trans=0", "--opacity-source", "viewing"]) == 0  # fmt: skip
    w = read_epof_csv(tmp_path / "w.csv")
    assert np.allclose(w.epof_dps, r.epof_rot_dps, atol=1e-6)
    assert not np.allclose(w.opacity, r.opacity)
    assert w.meta["settings"]["flow_weights"] == [1.0, 0.0]
    g = load_grid(path)
    res = compute_epof(g, load_headpath(hp), flow_weights=(2.0, 0.5))
    assert np.allclose(res.epof_dps, 2 * res.epof_rot_dps + 0.5 * res.epof_trans_dps)


def test_a_grid_without_parts_asked_for_them(tmp_path, capsys):
    path, _, _ = _grid(tmp_path / "old.npz", parts=False)
    hp = _path(tmp_path)
    out = tmp_path / "e.csv"
    # without --flow-weights: as before, no part columns
    assert main(["epof", str(path), str(hp), "-o", str(out)]) == 0
    assert read_epof_csv(out).epof_rot_dps is None
    out.unlink()
    capsys.readouterr()
    assert main(["epof", str(path), str(hp), "-o", str(out), "--flow-weights", "rot=1"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "no per-frame camera rotation" in err and "re-run" in err
    assert not out.exists()
    assert main(["epof", str(path), str(hp), "-o", str(out), "--flow-weights", "rot=0,trans=0"]) == 2
    assert "both 0" in capsys.readouterr().err and not out.exists()
