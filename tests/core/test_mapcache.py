"""The map cache (simulator.core.mapcache) and its use by WindowExtractor and preprocess --no-cache."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from media_helpers import noise_frames, write_clip

from simulator.cli import main
from simulator.core import mapcache
from simulator.core.mapcache import cache_dir, cached_arrays
from simulator.sphere import windows
from simulator.sphere.windows import WindowExtractor, WindowGrid

SMALL = WindowGrid(
    yaw_step_deg=60, pitch_step_deg=30, pitch_min_deg=-30, pitch_max_deg=30, size=(24, 16)
)


@pytest.fixture
def cdir(tmp_path, monkeypatch):
    d = tmp_path / "cache"
    monkeypatch.setenv("VIMSIM_CACHE_DIR", str(d))
    windows._MEMO.clear()
    yield d
    windows._MEMO.clear()


def test_cache_dir_order(tmp_path, monkeypatch):
    monkeypatch.delenv("VIMSIM_CACHE_DIR", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert cache_dir() == tmp_path / "xdg" / "vimsim"
    monkeypatch.delenv("XDG_CACHE_HOME")
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert cache_dir() == tmp_path / "home" / ".cache" / "vimsim"
    monkeypatch.setenv("VIMSIM_CACHE_DIR", str(tmp_path / "own"))
    assert cache_dir() == tmp_path / "own"


def test_build_once_then_hit(cdir):
    calls = []

    def build():
        calls.append(1)
        return {"a": np.arange(12, dtype=np.int16).reshape(3, 4), "b": np.ones(5, np.uint16)}

    key = {"kind": "t", "n": 1}
    first, how1 = cached_arrays(key, build)
    second, how2 = cached_arrays(key, build)
    assert (how1, how2, len(calls)) == ("built", "hit", 1)
    for k in ("a", "b"):
        assert np.array_equal(first[k], second[k])
        assert second[k].dtype == first[k].dtype
    # Another key is another entry; no temporary folders are left behind.
    cached_arrays({"kind": "t", "n": 2}, build)
    assert len(calls) == 2
    assert sorted(p.name.startswith(".") for p in cdir.iterdir()) == [False, False]


def test_no_cache_neither_reads_nor_writes(cdir):
    _, how = cached_arrays({"kind": "t"}, lambda: {"a": np.zeros(3)}, use_cache=False)
    assert how == "uncached"
    assert not cdir.exists()


def test_damaged_or_foreign_entry_is_rebuilt(cdir):
    key = {"kind": "t"}
    cached_arrays(key, lambda: {"a": np.arange(100.0)})
    (entry,) = cdir.iterdir()
    (entry / "a.npy").write_bytes(b"\x93NUMPY garbage")
    got, how = cached_arrays(key, lambda: {"a": np.arange(100.0) + 1})
    assert how == "built"  # rebuilt, and it replaced the damaged entry
    assert np.array_equal(got["a"], np.arange(100.0) + 1)
    got, how = cached_arrays(key, lambda: {"a": np.zeros(1)})
    assert how == "hit" and np.array_equal(got["a"], np.arange(100.0) + 1)
    (entry / "key.json").write_text('{"format": "someone else"}')
    _, how = cached_arrays(key, lambda: {"a": np.zeros(1)})
    assert how == "built"
    assert [p.name for p in cdir.iterdir()] == [entry.name]  # nothing left aside


def test_concurrent_store_keeps_the_first(cdir):
    path, text = mapcache._entry({"kind": "t"})
    mapcache._store(path, text, {"a": np.arange(4)})
    mapcache._store(path, text, {"a": np.arange(4)})  # a second run lost the race
    assert [p.name for p in cdir.iterdir()] == [path.name]
    assert np.array_equal(mapcache._load(path, text)["a"], np.arange(4))


def test_unwritable_cache_warns_and_works(tmp_path, monkeypatch):
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    monkeypatch.setenv("VIMSIM_CACHE_DIR", str(blocker / "sub"))
    with pytest.warns(UserWarning, match="not writable"):
        got, how = cached_arrays({"kind": "t"}, lambda: {"a": np.arange(3)})
    assert how == "uncached"
    assert np.array_equal(got["a"], np.arange(3))


def test_extractor_from_cache_equals_built(cdir):
    rng = np.random.default_rng(3)
    frame = rng.integers(0, 256, (64, 128), dtype=np.uint8)
    built = WindowExtractor(SMALL, (128, 64))
    windows._MEMO.clear()
    hit = WindowExtractor(SMALL, (128, 64))
    windows._MEMO.clear()
    fresh = WindowExtractor(SMALL, (128, 64), cache=False)
    assert (built.maps_source, hit.maps_source, fresh.maps_source) == ("built", "hit", "uncached")
    a, b, c = (
        built(frame, interp="linear"),
        hit(frame, interp="linear"),
        fresh(frame, interp="linear"),
    )
    assert np.array_equal(a, b) and np.array_equal(a, c)
    assert a.shape == (*SMALL.shape, 16, 24) and a.flags.c_contiguous
    out = np.zeros_like(a)
    assert hit(frame, interp="linear", out=out) is out and np.array_equal(out, a)
    with pytest.raises(ValueError, match="C-contiguous"):
        hit(frame, out=np.zeros((2, 2), np.uint8))


def test_preprocess_no_cache_flag(tmp_path, cdir):
    vid = write_clip(tmp_path / "v.mp4", noise_frames(3))
    args = ["preprocess", str(vid), "--window-size", "16", "--method", "paper", "--no-progress"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert main([*args, "-o", str(tmp_path / "a.npz"), "--no-cache"]) == 0
    assert not cdir.exists()
    windows._MEMO.clear()  # maps are also kept in memory per process
    assert main([*args, "-o", str(tmp_path / "b.npz")]) == 0
    assert len([p for p in cdir.iterdir() if p.name.startswith("window-maps-")]) == 1
    with np.load(tmp_path / "a.npz") as a, np.load(tmp_path / "b.npz") as b:
        assert np.array_equal(a["pof_dps"], b["pof_dps"])
