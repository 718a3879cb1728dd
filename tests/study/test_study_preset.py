"""``[epof] preset`` in a study manifest: the same rule as ``vimsim epof --preset`` for every
viewing (EPOF CSVs byte-identical), the options it fixes refused in one line, and the
render's x264 preset as ``[render] x264_preset``."""

from __future__ import annotations

from pathlib import Path

import pytest

from simulator.cli import main
from simulator.traces.path import save_headpath_csv, synth


@pytest.fixture(scope="module")
def base(tmp_path_factory):
    from simulator.synth import SynthConfig, synthesize

    d = tmp_path_factory.mktemp("preset")
    synthesize(SynthConfig("rotate", seconds=1.0, fps=10, size=(128, 64)), d / "clip.mp4")
    for i in range(2):
        save_headpath_csv(d / f"P{i}.csv", synth("look-around", 1.5, rate_hz=30, seed=i))
    return d


def _manifest(d: Path, epof: str, extra: str = "") -> Path:
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

[epof]
{epof}
{extra}
""")
    return m


@pytest.mark.slow
def test_study_cao2021_code_equals_vimsim_epof(base, tmp_path):
    out, cache = tmp_path / "o", tmp_path / "c"
    m = _manifest(base, 'preset = "cao2021-code"')
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


@pytest.mark.parametrize(
    "epof,extra,want",
    [
        ('preset = "cao2021-code"\ntop_k = 2', "", "cannot be combined with top_k"),
        ('preset = "cao2021-code"', "[grf]\ngrain_size = 1.0",
         "[epof] preset: cao2021-code fixes [grf] grain_size"),
        ('preset = "paper"\nmethod = "sphere"', "", "paper fixes [epof] method"),
        ('preset = "veryfast"', "", "[epof] preset: expected one of vimsim, paper, cao2021-code"),
        ("", '[render]\npreset = "veryfast"', "x264_preset"),
    ],
)
def test_bad_preset_in_manifest(base, tmp_path, capsys, epof, extra, want):
    m = _manifest(base, epof, extra)
    out = tmp_path / "o"
    assert main(["study", str(m), "-o", str(out), "--cache-dir", str(tmp_path / "c")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and want in err[0], err
    assert not out.exists()
