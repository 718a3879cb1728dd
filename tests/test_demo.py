"""The end-to-end demo at a tiny size: every file, a sane summary, determinism, bad output."""

from __future__ import annotations

import ast
import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from simulator.cli import main
from simulator.demo import DemoConfig, run_demo
from simulator.media.gridfile import load_grid
from simulator.media.video import probe


def _data_lines(path):
    """The lines of an EPOF CSV without its '#' settings lines (header first)."""
    return [ln for ln in path.read_text().splitlines() if not ln.startswith("#")]


TINY = DemoConfig(
    seconds=0.5, fps=10.0, eye_size=(128, 64), window=32, render_size=(64, 64), seed=3
)


@pytest.fixture(scope="module")
def demo_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("demo")
    run_demo(out, TINY, progress=False)
    return out


@pytest.mark.gl
@pytest.mark.slow
def test_demo_writes_every_file(demo_dir):
    s = json.loads((demo_dir / "summary.json").read_text())
    for name in s["files"]:
        assert (demo_dir / name).is_file(), name
    for name in (
        "coaster.mp4",
        "coaster.truth.npz",
        "headpath.csv",
        "grid.npz",
        "epof.csv",
        "epof_opacity.png",
        "pof_heatmaps.png",
        "README.txt",
    ):
        assert name in s["files"], name
    info = probe(demo_dir / "coaster.mp4")
    assert (info.width, info.height, info.n_frames) == (128, 128, 5)
    g = load_grid(demo_dir / "grid.npz")
    assert g.pof_dps.shape == (5, 11, 24)
    assert g.meta["layout"] == "top-bottom" and g.meta["eye"] == "left"
    rows = _data_lines(demo_dir / "epof.csv")
    assert rows[0] == "frame,time_s,yaw_deg,pitch_deg,roll_deg,epof_dps,opacity" and len(rows) == 6
    readme = (demo_dir / "README.txt").read_text()
    assert "coaster.mp4" in readme and "pof_heatmaps.png" in readme
    assert s["render"]["ok"]  # a failed render stops the demo (below)
    for eye in ("left", "right"):
        ri = probe(demo_dir / "render" / f"{eye}.mp4")
        assert (ri.width, ri.height, ri.n_frames) == (64, 64, 5)


def test_demo_stops_at_the_first_failed_step(tmp_path, monkeypatch, capsys):
    """A failed step (here the render, on a full disk) stops the demo: exit 1 in one line
    naming the file, no completion marker, the manifest incomplete, no temporary file."""
    import errno

    import simulator.demo as dm

    def full(*a, **k):
        raise OSError(errno.ENOSPC, "No space left on device", str(tmp_path / "o/render/left.mp4"))

    monkeypatch.setattr(dm, "render_viewing", full)
    monkeypatch.setattr(dm, "DemoConfig", lambda **k: replace(TINY, **k))
    assert main(["demo", "-o", str(tmp_path / "o"), "--seconds", "0.5", "--no-progress"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].endswith("left.mp4: No space left on device") and "Traceback" not in str(err)
    names = {q.name for q in (tmp_path / "o").iterdir()}
    assert (
        "summary.json" not in names
        and "README.txt" not in names
        and "epof_opacity.png" not in names
    )
    assert not [n for n in names if ".tmp-" in n]
    m = json.loads((tmp_path / "o" / ".vimsim-manifest.json").read_text())
    assert m["state"] == "incomplete"


@pytest.mark.gl
@pytest.mark.slow
def test_demo_flow_is_close_to_truth(demo_dir):
    s = json.loads((demo_dir / "summary.json").read_text())
    acc = s["accuracy_vs_truth"]
    # Tiny clip (128x64 per eye, 32 px windows): loose bounds, still far from chance.
    assert acc["window_pof_rel_error_median"] < 0.35
    assert acc["epof_rel_error_vs_truth_grid_median"] < 0.35
    assert 0 < s["epof_dps"]["median"] < 500


@pytest.mark.gl
@pytest.mark.slow
def test_demo_is_deterministic_given_seed(demo_dir, tmp_path):
    out = tmp_path / "again"
    run_demo(out, replace(TINY, render=False), progress=False)  # render is covered above
    a, b = load_grid(demo_dir / "grid.npz"), load_grid(out / "grid.npz")
    np.testing.assert_array_equal(a.pof_dps, b.pof_dps)
    assert (demo_dir / "headpath.csv").read_text() == (out / "headpath.csv").read_text()
    assert (demo_dir / "epof.csv").read_text() == (out / "epof.csv").read_text()


def test_demo_bad_output_dir(tmp_path, capsys):
    f = tmp_path / "file"
    f.write_text("x")
    rc = main(["demo", "-o", str(f / "sub")])
    err = capsys.readouterr().err
    assert rc == 2
    assert len(err.strip().splitlines()) == 1 and "output directory" in err


def test_demo_and_render_do_not_import_the_cli():
    """Layering: the demo calls simulator.viewing.job.render_viewing, not ``vimsim render``;
    neither module imports simulator.cli or simulator.commands (higher layers)."""
    import simulator.demo
    import simulator.render

    for mod in (simulator.demo, simulator.render):
        tree = ast.parse(Path(mod.__file__).read_text())
        names = [a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names]
        names += [n.module or "" for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)]
        bad = [
            m
            for m in names
            if m in ("simulator.cli", "simulator.commands") or m.startswith("simulator.commands.")
        ]
        assert bad == [], f"{mod.__name__} imports {bad}"


@pytest.mark.gl
@pytest.mark.slow
def test_demo_render_matches_the_command(demo_dir):
    """The demo's render/ is what ``vimsim render --grid grid.npz --layout top-bottom`` writes."""
    s = json.loads((demo_dir / "summary.json").read_text())
    assert s["render"]["ok"]  # a failed render stops the demo
    r = json.loads((demo_dir / "render" / "summary.json").read_text())
    assert r["layout"] == "top-bottom" and r["eye_size"] == [64, 64]
    assert r["grid"] == str(demo_dir / "grid.npz") and r["headpath"] == str(
        demo_dir / "headpath.csv"
    )
    assert r["opacity"] == "auto" and r["grf"]["seed"] == TINY.seed
    assert r["hfov_deg"] == r["vfov_deg"] == 107.0
