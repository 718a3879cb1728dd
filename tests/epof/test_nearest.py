"""``vimsim epof --preset cao2021-code`` (the authors' runtime over one viewing) and ``--preset paper``."""

from __future__ import annotations

import numpy as np
import pytest

from simulator.cli import main
from simulator.epof import read_epof_csv
from simulator.export.caocsv import window_file_name
from simulator.media.gridfile import load_grid
from simulator.mitigation.cao2021 import FixedPxRule, nearest_flow
from simulator.traces.path import save_headpath_csv, synth


def _grid(tmp_path, yaws, pitches):
    d = tmp_path / "csv"
    d.mkdir(parents=True)
    rng = np.random.default_rng(1)
    T = 40
    for p in pitches:
        for y in yaws:
            v = rng.uniform(0, 60, T).astype(np.float32)
            v[0] = 2000.0  # their frame 0 (88 deg FOV): the flash at frame 2
            rows = "".join(f"{t},{float(x)!r}\n" for t, x in enumerate(v))
            (d / window_file_name(y, p)).write_text(",0\n" + rows)
    out = tmp_path / "g.npz"
    assert main(["grid", "import", str(d), "-o", str(out), "--fps", "20"]) == 0
    return out


@pytest.fixture
def cao_grid(tmp_path):
    return _grid(tmp_path, range(-180, 180, 15), range(-90, 91, 15))


def test_epof_cao2021_code(tmp_path, cao_grid, capsys):
    hp = synth("sine", 2.5, yaw_amp=200.0, yaw_freq=0.4, pitch_amp=85.0)
    path = tmp_path / "path.csv"
    save_headpath_csv(path, hp)
    out = tmp_path / "epof.csv"
    assert main(["epof", str(cao_grid), str(path), "-o", str(out), "--preset", "cao2021-code"]) == 0
    assert "px/frame" in capsys.readouterr().out
    res = read_epof_csv(out)
    g = load_grid(cao_grid)
    px = nearest_flow(g.pof_px, res.frame, res.yaw_deg, res.pitch_deg, g.yaw_deg, g.pitch_deg)
    np.testing.assert_allclose(res.opacity, FixedPxRule()(px), atol=1e-9)
    assert res.opacity[0] == 0 and res.opacity[1] == 0  # frame 1 reads the header ,0
    assert res.opacity[2] == 1.0  # row 0 (2000 px/frame) at frame 2: the flash
    text = out.read_text()
    assert "\nframe,time_s,yaw_deg,pitch_deg,roll_deg,epof_dps,opacity,flow_px\n" in text
    assert '"low_px": 0.18' in text and "cao2021-code" in text


def test_epof_preset_refusals(tmp_path, cao_grid, capsys):
    path = tmp_path / "p.csv"
    path.write_text("time_s,yaw_deg,pitch_deg,roll_deg\n0,0,0,0\n3,10,0,0\n")
    out = tmp_path / "e.csv"
    for extra in (["--top-k", "2"], ["--method", "sphere"], ["--opacity-rule", "absolute"],
                  ["--fov", "90"]):  # fmt: skip
        assert main(["epof", str(cao_grid), str(path), "-o", str(out), "--preset",
                     "cao2021-code", *extra]) == 2  # fmt: skip
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and "cannot be combined" in err
    assert not out.exists()
    small = _grid(tmp_path / "small", range(-180, 180, 90), (-45, 0, 45))
    assert main(["epof", str(small), str(path), "-o", str(out), "--preset", "paper"]) == 0
    res = read_epof_csv(out)
    assert "paper" in capsys.readouterr().out
    assert '# epof_method: "paper"' in out.read_text()
    assert res.opacity.min() >= 0
