"""``[epof] preset`` in a study manifest: the same rule as ``vimsim epof --preset`` for every
viewing (EPOF CSVs byte-identical), the options it fixes refused in one line, and the
render's x264 preset as ``[render] x264_preset``."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from simulator.cli import main
from simulator.epof import read_epof_csv
from simulator.traces.path import save_headpath_csv, synth


@pytest.fixture(scope="module")
def base(tmp_path_factory):
    from simulator.synth import SynthConfig, synthesize

    d = tmp_path_factory.mktemp("preset")
    synthesize(SynthConfig("rotate", seconds=1.0, fps=10, size=(128, 64)), d / "clip.mp4")
    for i in range(2):
        save_headpath_csv(d / f"P{i}.csv", synth("look-around", 1.5, rate_hz=30, seed=i))
    return d


def _manifest(d: Path, epof: str, extra: str = "", render: bool = False,
              render_keys: str = "") -> Path:  # fmt: skip
    m = d / "study.toml"
    m.write_text(f"""
[[videos]]
id = "clip"
path = "clip.mp4"
method = "paper"
window_size = 32

[[viewings]]
video = "clip"
trace = "P*.csv"
participant = "{{stem}}"

[[viewings]]
video = "clip"
trace = "P0.csv"
id = "render-P0"
render = {"true" if render else "false"}

[render]
eye_size = "64x64"
x264_preset = "ultrafast"
{render_keys}

[epof]
{epof}
{extra}
""")
    return m


@pytest.mark.gl
@pytest.mark.slow
def test_study_cao2021_code_equals_vimsim_epof(base, tmp_path):
    out, cache = tmp_path / "o", tmp_path / "c"
    m = _manifest(base, 'preset = "cao2021-code"', render=True)
    assert main(["study", str(m), "-o", str(out), "--cache-dir", str(cache), "--no-progress",
                 "--workers", "1"]) == 0  # fmt: skip
    grid = next((cache / "grids").glob("*.npz"))
    for p in ("P0", "P1"):
        ref = tmp_path / f"{p}.csv"
        assert main(["epof", str(grid), str(base / f"{p}.csv"), "-o", str(ref), "--preset",
                     "cao2021-code"]) == 0  # fmt: skip
        got = out / "epof" / f"clip-{p}.csv"
        assert got.read_bytes() == ref.read_bytes()
        assert ",flow_px\n" in got.read_text()
    s = json.loads((out / "render" / "render-P0" / "summary.json").read_text())
    assert s["preset"] == "cao2021-code" and s["grf"]["layout"] == "fibonacci"
    assert s["x264"]["preset"] == "ultrafast"
    ren = read_epof_csv(out / "render" / "render-P0" / "epof.csv")
    np.testing.assert_allclose(ren.opacity, read_epof_csv(out / "epof" / "render-P0.csv").opacity,
                               atol=1e-12)  # fmt: skip


@pytest.mark.parametrize(
    "epof,extra,want",
    [
        ('preset = "cao2021-code"\ntop_k = 2', "", "cannot be combined with top_k"),
        ('preset = "cao2021-code"', "[grf]\ngrain_size = 1.0",
         "[epof] preset: cao2021-code fixes [grf] grain_size"),
        ('preset = "paper"\nmethod = "sphere"', "", "paper fixes [epof] method"),
        ('preset = "veryfast"', "", "[epof] preset: expected one of vimsim, paper, cao2021-code"),
        ("", 'RENDER:preset = "veryfast"', "x264_preset"),
    ],
)
def test_bad_preset_in_manifest(base, tmp_path, capsys, epof, extra, want):
    keys = extra.removeprefix("RENDER:") if extra.startswith("RENDER:") else ""
    m = _manifest(base, epof, "" if keys else extra, render_keys=keys)
    out = tmp_path / "o"
    assert main(["study", str(m), "-o", str(out), "--cache-dir", str(tmp_path / "c")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and want in err[0], err
    assert not out.exists()
