"""The sphere-mode field read lazily from a grid file: same numbers as the array in memory."""

from __future__ import annotations

import json
import zipfile

import numpy as np
import pytest

from simulator.core.errors import InputError
from simulator.epof.exact import viewport_epof
from simulator.media import lazyfield
from simulator.media.gridfile import load_grid, require_field, save_grid
from simulator.media.lazyfield import LazyField, take_rows
from simulator.mitigation.kinds import Mitigation, cell_opacity, visible_flow
from simulator.sphere.cells import CellGrid, Frustum
from simulator.sphere.windows import grid_preset

CELL = 10.0
T = 23


def _field(T=T, seed=0):
    rng = np.random.default_rng(seed)
    n_lat, n_lon = CellGrid(CELL).shape
    return (rng.random((T, n_lat, n_lon)) * 80).astype(np.float16)


def _meta(T):
    return {
        "fps": 30.0, "n_frames": T, "flow": {"method": "dis"}, "layout": "mono", "eye": "left",
        "video": {"path": "v.mp4", "width": 64, "height": 32, "sar": 1.0},
        "field": {"cell_deg": CELL},
    }  # fmt: skip


def _save(path, f):
    grid = grid_preset("default")
    P, Y = grid.shape
    pof = np.ones((len(f), P, Y), np.float32)
    save_grid(path, pof, pof, grid, _meta(len(f)), field_dps=f)
    return path


def _restore(path, compression):
    """Rewrite a grid file with every member stored with ``compression`` (an old grid file
    is deflated; ``np.savez`` stores)."""
    with zipfile.ZipFile(path) as zf:
        members = {i.filename: zf.read(i) for i in zf.infolist()}
    with zipfile.ZipFile(path, "w", compression) as zf:
        for k, b in members.items():
            zf.writestr(k, b)


@pytest.fixture(params=[zipfile.ZIP_DEFLATED, zipfile.ZIP_STORED], ids=["deflated", "stored"])
def grid_path(request, tmp_path, monkeypatch):
    monkeypatch.setattr(lazyfield, "CHUNK_BYTES", 3 * CellGrid(CELL).shape[0] * 36 * 4)  # 3 rows
    p = _save(tmp_path / "g.npz", _field())
    _restore(p, request.param)
    return p


def test_lazy_field_rows_and_chunks_equal_the_array(grid_path):
    f = _field()
    g = load_grid(grid_path)
    lf = g.field_dps
    assert isinstance(lf, LazyField) and lf.shape == f.shape and lf.dtype == np.float16
    assert lf.chunk_rows == 3
    assert np.array_equal(np.asarray(lf), f)
    # Rows in any order (a backward read reopens a compressed member), negative, slices.
    for t in (5, 2, 22, 0, -1, 7, 6):
        assert np.array_equal(lf[t], f[t])
    assert np.array_equal(lf[4:13], f[4:13])
    assert np.array_equal(lf[::4], f[::4])
    rows = np.array([9, 9, 10, 3, 22, 0])
    assert np.array_equal(lf[rows], f[rows])
    sel = take_rows(lf, np.clip(np.arange(-2, 30), 0, T - 1))  # lazy, as viewing/job.py uses it
    assert np.array_equal(np.asarray(sel), f[np.clip(np.arange(-2, 30), 0, T - 1)])
    assert np.array_equal(np.asarray(sel.take([0, 31, 5])), f[[0, 22, 3]])
    seen = [(i0, c) for i0, c in lf.chunks()]
    assert [i0 for i0, _ in seen] == list(range(0, T, 3)) and seen[0][1].dtype == np.float32
    assert np.array_equal(np.concatenate([c for _, c in seen]), f.astype(np.float32))
    with pytest.raises(IndexError):
        lf[T]


def test_epof_and_visible_flow_from_a_lazy_field_are_bit_identical(grid_path):
    """What epof / render compute chunk by chunk equals the in-memory computation."""
    f32 = _field().astype(np.float32)
    field, _cells = require_field(load_grid(grid_path))
    assert isinstance(field, LazyField) and field.dtype == np.float32
    rng = np.random.default_rng(3)
    yaw, pitch, roll = rng.uniform(-180, 180, T), rng.uniform(-80, 80, T), rng.uniform(-30, 30, T)
    fr = Frustum.symmetric(107.0)
    lazy = viewport_epof(field, CELL, yaw, pitch, roll, frustum=fr)
    mem = viewport_epof(f32, CELL, yaw, pitch, roll, frustum=fr)
    assert np.array_equal(lazy, mem)
    rows = np.clip(np.arange(T) - 4, 0, T - 1)
    assert np.array_equal(
        viewport_epof(take_rows(field, rows), CELL, yaw, pitch, roll, frustum=fr),
        viewport_epof(f32[rows], CELL, yaw, pitch, roll, frustum=fr),
    )
    assert np.array_equal(cell_opacity(field, (10.0, 60.0)), cell_opacity(f32, (10.0, 60.0)))
    ang = np.stack([yaw, pitch, roll], 1)[:6]
    a, b = (
        visible_flow(Mitigation("vignette"), fr, ang, np.full(6, 0.7), mem[:6],
                     field_dps=x, cell_deg=CELL, samples=24)
        for x in (field, f32)
    )  # fmt: skip
    assert np.array_equal(a.ratio, b.ratio) and np.array_equal(a.visible_dps, b.visible_dps)
    assert 0 < float(a.ratio.min()) < 1  # the vignette blocks some of the flow


def test_load_refuses_bad_lazy_fields(tmp_path):
    f = _field(T=4)
    f[2, 3, 4] = np.nan
    with pytest.raises(InputError, match="finite and >= 0"):
        load_grid(_save(tmp_path / "nan.npz", f))
    f[2, 3, 4] = -1
    with pytest.raises(InputError, match="finite and >= 0"):
        load_grid(_save(tmp_path / "neg.npz", f))
    # A member cut short after the header check (a truncated copy): one line, no traceback.
    p = _save(tmp_path / "cut.npz", _field(T=4))
    with zipfile.ZipFile(p) as zf:
        members = {i.filename: zf.read(i) for i in zf.infolist()}
    with zipfile.ZipFile(p, "w") as zf:
        for k, b in members.items():
            zf.writestr(k, b[:-3000] if k == "field_dps.npy" else b)
    with pytest.raises(InputError, match="truncated") as e:
        load_grid(p)
    assert str(p) in str(e.value) and "\n" not in str(e.value)
    assert json.loads(str(np.load(_save(tmp_path / "ok.npz", _field(T=2)))["meta"]))["field"]


def test_viewport_query_cache_is_bounded_in_bytes():
    """A head path visits a new weight bin almost every frame: the cache stays under its
    byte bound, and evicted bins give the same EPOF when recomputed."""
    from simulator.epof.exact import ViewportQuery

    fr = Frustum.symmetric(107.0)
    f = _field(T=1)[0].astype(np.float32)
    q = ViewportQuery(CELL, fr, cache_bytes=200_000)
    fresh = ViewportQuery(CELL, fr, cache_bytes=1 << 30)
    rng = np.random.default_rng(5)
    angles = rng.uniform([-180, -80, -40], [180, 80, 40], (200, 3))
    got = [q(f, *a) for a in angles]
    assert 0 < q._bytes <= 200_000 and len(q._bins) < 200
    assert q._bytes == sum(
        sum(x.nbytes for x in (b[0], b[1], b[3], b[4])) for b in q._bins.values()
    )
    assert got == [fresh(f, *a) for a in angles] == [q(f, *a) for a in angles]


def test_opacity_fit_keeps_its_inputs():
    """The percentile fit works on one copy it partitions in place: inputs unchanged."""
    from simulator.mitigation.grf import OpacityRule

    e = np.random.default_rng(1).random(101) * 40
    e[7] = np.nan
    keep = e.copy()
    lo, hi = OpacityRule(source="viewing").fit(None, e)
    assert np.array_equal(e, keep, equal_nan=True)
    ok = keep[np.isfinite(keep)]
    assert (lo, hi) == (float(np.percentile(ok, 10)), float(np.percentile(ok, 90)))
