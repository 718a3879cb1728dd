"""The lazy top-level API of ``simulator``: the five steps from Python, and a light import."""

from __future__ import annotations

import importlib
import json
import subprocess
import sys

import numpy as np
import pytest

import simulator


def test_import_is_light_and_names_are_lazy():
    """``import simulator`` loads no numpy (the CLI's fast start); the first use of an
    API name imports its module."""
    code = (
        "import sys, simulator; a = 'numpy' in sys.modules; "
        "simulator.compute_epof; print(a, 'numpy' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["False", "True"]


def test_every_api_name_is_its_module_s():
    for name, module in simulator._API.items():
        assert getattr(simulator, name) is getattr(importlib.import_module(module), name)
        assert name in dir(simulator) and name in simulator.__all__
    assert set(simulator.__all__) == {*simulator._API, "InputError", "VimsimError", "__version__"}
    with pytest.raises(AttributeError, match="no_such_name"):
        simulator.no_such_name  # noqa: B018


@pytest.mark.gl
def test_the_five_steps_from_python(tmp_path):
    """Preprocess a synthetic clip, load the grid and a head path, compute the EPOF and
    render the viewing, each through ``simulator.<name>``."""
    from simulator.synth import SynthConfig, synthesize
    from simulator.traces.path import save_headpath_csv, synth

    video, _ = synthesize(SynthConfig("rotate", seconds=0.5, fps=10, size=(128, 64)),
                          tmp_path / "clip.mp4")  # fmt: skip
    save_headpath_csv(tmp_path / "p.csv", synth("look-around", 1.5, rate_hz=30, seed=2))
    windows = simulator.grid_preset("default", size=(32, 32))
    simulator.preprocess_video(video, tmp_path / "g.npz", grid=windows, progress=False)
    grid = simulator.load_grid(tmp_path / "g.npz")
    hp = simulator.load_headpath(tmp_path / "p.csv")
    res = simulator.compute_epof(grid, hp)
    assert len(res.epof_dps) == 5 and np.all(np.isfinite(res.epof_dps))
    view = simulator.ViewSpec.from_options({"grid": True, "eye_size": "32x32"})
    s = simulator.render_viewing(simulator.Source.open(video), hp, tmp_path / "r", grid=grid,
                                 view=view, progress=False)  # fmt: skip
    assert s["frames_written"] == 5
    assert json.loads((tmp_path / "r" / "summary.json").read_text())["eye_size"] == [32, 32]
