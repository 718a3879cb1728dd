"""The study's grid cache is validated before use and a bad entry is made again; a
``[[videos]] path`` that is not a video is a manifest error."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from simulator.cli import main
from simulator.media.gridfile import load_grid
from simulator.study.manifest import load_manifest


def _toml(video: str = "clip.mp4") -> str:
    return (
        '[study]\nname = "t"\n\n[[videos]]\nid = "clip"\n'
        f'path = "{video}"\nmethod = "sphere"\nwindow_size = 32\ncell = 10\n\n'
        '[[viewings]]\nvideo = "clip"\ntrace = "P01.csv"\n'
    )


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    """A one-viewing study run once (its cache filled); the folder."""
    from simulator.synth import SynthConfig, synthesize
    from simulator.traces.path import save_headpath_csv, synth

    d = tmp_path_factory.mktemp("cache")
    synthesize(SynthConfig("rotate", seconds=0.4, fps=10, size=(64, 32)), d / "clip.mp4")
    synthesize(SynthConfig("coaster", seconds=0.4, fps=10, size=(64, 32)), d / "other.mp4")
    save_headpath_csv(d / "P01.csv", synth("look-around", 0.6, rate_hz=30, seed=0))
    (d / "s.toml").write_text(_toml())
    argv = ["study", str(d / "s.toml"), "-o", str(d / "o1"), "--cache-dir", str(d / "cache"),
            "--workers", "1", "--no-progress"]  # fmt: skip
    assert main(argv) == 0
    return d


def _grid(d: Path) -> Path:
    (g,) = (d / "cache" / "grids").glob("*.npz")
    return g


def test_cache_problem_names_what_is_wrong(study, tmp_path):
    from simulator.study.plan import cache_problem

    m = load_manifest(study / "s.toml")
    v = m.videos[0]
    assert cache_problem(_grid(study), v) is None
    other = load_manifest(_write(tmp_path, study, _toml(str(study / "other.mp4")))).videos[0]
    assert "another video" in cache_problem(_grid(study), other)
    bad = tmp_path / "bad.npz"
    bad.write_bytes(_grid(study).read_bytes()[:-200])  # truncated
    assert "not a valid grid file" in cache_problem(bad, v)


def _write(tmp_path: Path, study: Path, text: str) -> Path:
    p = tmp_path / "m.toml"
    p.write_text(text.replace('trace = "P01.csv"', f'trace = "{study / "P01.csv"}"'))
    return p


@pytest.mark.parametrize("damage", ["garbage", "foreign"])  # truncated: above
def test_bad_cache_entry_is_rebuilt(study, tmp_path, capsys, damage):
    """A corrupt entry (or another video's grid under the key) is made again: the study
    completes (exit 0) with the same EPOF as the first run and says so in study.json."""
    g = _grid(study)
    good = g.read_bytes()
    try:
        if damage == "garbage":
            g.write_bytes(b"\0" * 100)
        elif damage == "truncated":
            g.write_bytes(good[: len(good) // 2])
        else:  # a valid grid of another clip under this key
            assert main(["preprocess", str(study / "other.mp4"), "-o", str(tmp_path / "x.npz"),
                         "--method", "sphere", "--cell", "10", "--window-size", "32",
                         "--no-progress"]) == 0  # fmt: skip
            g.write_bytes((tmp_path / "x.npz").read_bytes())
        out = tmp_path / "o"
        argv = ["study", str(study / "s.toml"), "-o", str(out), "--cache-dir",
                str(study / "cache"), "--workers", "1", "--no-progress"]  # fmt: skip
        assert main(argv) == 0, capsys.readouterr().err
        s = json.loads((out / "study.json").read_text())
        assert next(iter(s["videos"].values()))["cache"].startswith("rebuilt: ")
        assert (out / "epof" / "clip-P01.csv").read_bytes() == (
            study / "o1" / "epof" / "clip-P01.csv"
        ).read_bytes()
        load_grid(g)  # valid again
    finally:
        g.write_bytes(good)


def test_not_a_video_is_a_manifest_error(study, tmp_path, capsys):
    (tmp_path / "bad.mp4").write_text("not a video")
    m = tmp_path / "s.toml"
    m.write_text(_toml(str(tmp_path / "bad.mp4")).replace("P01.csv", str(study / "P01.csv")))
    out = tmp_path / "o"
    rc = main(
        ["study", str(m), "-o", str(out), "--cache-dir", str(tmp_path / "c"), "--no-progress"]
    )
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1 and "'clip'" in err and "bad.mp4" in err, err
    assert "internal error" not in err and not out.exists()


def test_field_values_checked_once_per_cache_entry(study, tmp_path):
    """A cache entry's field values are scanned once: a ``.checked`` mark holds the file's
    size, time and inode; a changed file (NaN in its field) is scanned again and refused;
    a user's own grid gets no mark."""
    import numpy as np

    from simulator.study.plan import cache_problem

    v = load_manifest(study / "s.toml").videos[0]
    g = _grid(study)
    mark = g.with_name(g.name + ".checked")
    mark.unlink(missing_ok=True)
    assert cache_problem(g, v, remember=True) is None  # scanned, then marked
    st = g.stat()
    assert mark.read_text() == f"{st.st_size}:{st.st_mtime_ns}:{st.st_ino}"
    good = g.read_bytes()
    try:
        with np.load(g, allow_pickle=False) as z:
            arrs = {k: z[k] for k in z.files}
        arrs["field_dps"][0, 0, 0] = np.nan
        np.savez_compressed(g, **arrs)  # a new stamp: scanned again
        assert "not a valid grid file" in cache_problem(g, v, remember=True)
    finally:
        g.write_bytes(good)
    assert cache_problem(g, v, remember=True) is None  # passes again, a new mark
    st = g.stat()
    assert mark.read_text() == f"{st.st_size}:{st.st_mtime_ns}:{st.st_ino}"
    mine = tmp_path / "mine.npz"
    mine.write_bytes(good)
    assert cache_problem(mine, v) is None and not (tmp_path / "mine.npz.checked").exists()


def test_a_grid_made_without_artefacts_is_made_again_when_they_are_on(study, tmp_path):
    """Artefacts are on by default: a cached grid from before (no stored artefacts) is made
    again once with them instead of every worker decoding the video in every run."""
    import dataclasses
    import json as _json

    import numpy as np

    from simulator.study.plan import cache_problem

    v = load_manifest(study / "s.toml").videos[0]
    assert v.artefacts  # the default
    g = tmp_path / "old.npz"
    with np.load(_grid(study), allow_pickle=False) as z:
        arrs = {k: z[k] for k in z.files}
    meta = _json.loads(str(arrs["meta"]))
    assert isinstance(meta.pop("artefacts"), dict)
    arrs["meta"] = np.array(_json.dumps(meta))
    np.savez_compressed(g, **arrs)
    assert cache_problem(g, v) == "made without artefact detection"
    assert cache_problem(g, dataclasses.replace(v, artefacts=False)) is None
    assert cache_problem(_grid(study), v) is None


@pytest.mark.parametrize("width, says", [("8000", "<= 4096"), ("128", "wider than the video (64 px)")])
def test_browser_width_refused_before_any_work_dry_run_too(study, tmp_path, capsys, width, says):
    for extra in (["--dry-run"], []):
        out = tmp_path / f"o{len(extra)}"
        argv = ["study", str(study / "s.toml"), "-o", str(out), "--cache-dir",
                str(study / "cache"), "--browser-width", width, "--no-progress", *extra]  # fmt: skip
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert "--browser-width" in err and says in err and err.count("\n") == 1, err
        assert not out.exists()
