"""A study worker's memory does not grow with the video's length: a long video's sphere fields stay lazy, the weight cache is bounded small, the results are the same."""

from __future__ import annotations

import csv

import numpy as np
import pytest

from simulator.media.lazyfield import LazyField
from simulator.study import tasks


@pytest.fixture(scope="module")
def grid(tmp_path_factory):
    from simulator.synth import SynthConfig, synthesize

    d = tmp_path_factory.mktemp("wmem")
    synthesize(SynthConfig("rotate", seconds=1.0, fps=10, size=(128, 64)), d / "clip.mp4")
    video = {"path": str(d / "clip.mp4"), "layout": "mono", "eye": "left", "method": "sphere",
             "grid": "default", "hfov_deg": 107.0, "vfov_deg": 107.0, "window_size": 64,
             "flow": "dis", "cell_deg": 4.0, "projection": None, "lens_fov_deg": None,
             "artefacts": True}  # fmt: skip
    r = tasks.preprocess_task(video, str(d / "grid.npz"), 1)
    assert r["ok"], r
    return d / "grid.npz"


def _epof(grid, out, n=3, spool_dir=None):
    from simulator.screen.run import _epof_options

    items = [{"id": f"v{k}", "trace": "", "format": "synth:look-around", "user": k, "plot": False}
             for k in range(n)]  # fmt: skip
    recs = tasks.epof_task(str(grid), items, _epof_options({}, True), str(out), spool_dir)
    assert [r["status"] for r in recs] == ["ok"] * n
    return [list(csv.reader(open(out / f"v{k}.csv"))) for k in range(n)]


def test_long_fields_stay_lazy_with_the_same_results(grid, tmp_path, monkeypatch):
    tasks._GRIDS.clear()
    assert isinstance(tasks._grid(str(grid)).field_dps, np.ndarray)  # short: held whole
    (tmp_path / "whole").mkdir()
    whole = _epof(grid, tmp_path / "whole")
    tasks._GRIDS.clear()
    monkeypatch.setattr(tasks, "FIELD_IN_MEMORY_BYTES", 0)  # as for a long video
    g = tasks._grid(str(grid))
    assert isinstance(g.field_dps, LazyField) and isinstance(g.field_trans_dps, LazyField)
    (tmp_path / "lazy").mkdir()
    assert _epof(grid, tmp_path / "lazy") == whole
    tasks._GRIDS.clear()


def test_weight_cache_stays_bounded(grid, tmp_path, monkeypatch):
    """The worker's exact-EPOF cache keeps to its bound however many orientations the
    viewers visit, and the bound is bounded (192 MiB filled with a longer video's bins)."""
    from simulator.epof import exact
    from simulator.epof.overlaps import viewport_fov
    from simulator.sphere.cells import Frustum

    assert tasks.WEIGHT_CACHE_BYTES <= 64 << 20
    monkeypatch.setattr(tasks, "WEIGHT_CACHE_BYTES", 64 << 10)
    exact._query.cache_clear()
    tasks._GRIDS.clear()
    _epof(grid, tmp_path, n=4)
    g = tasks._grid(str(grid))
    q = exact.shared_query(4.0, Frustum.symmetric(*viewport_fov(g, None, None)))
    assert q._cache_bytes == 64 << 10
    assert 0 < q._bytes <= 64 << 10
    exact._query.cache_clear()
    tasks._GRIDS.clear()


def test_long_fields_spooled_once_with_the_same_results(grid, tmp_path, monkeypatch):
    """With the study's spool folder, a long video's fields are decompressed once into raw
    float32 files (and their rotational part beside them), read chunk by chunk from there:
    the same EPOF CSVs as with the fields held whole."""
    from simulator.epof.parts import keep_parts_in

    tasks._GRIDS.clear()
    (tmp_path / "whole").mkdir()
    whole = _epof(grid, tmp_path / "whole")
    tasks._GRIDS.clear()
    monkeypatch.setattr(tasks, "FIELD_IN_MEMORY_BYTES", 0)
    (tmp_path / "spooled").mkdir()
    try:
        got = _epof(grid, tmp_path / "spooled", spool_dir=str(tmp_path / "fields"))
        g = tasks._grid(str(grid), str(tmp_path / "fields"))
        assert isinstance(g.field_dps, LazyField) and g.field_dps.path.parent == tmp_path / "fields"
    finally:
        keep_parts_in(None)
        tasks._GRIDS.clear()
    assert got == whole
    names = sorted(p.name.rsplit(".", 2)[1] for p in (tmp_path / "fields").iterdir())
    assert names == ["field_dps", "field_trans_dps", "rot"]
