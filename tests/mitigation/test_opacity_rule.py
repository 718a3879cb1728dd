"""Opacity easing (ease-in / ease-out), the comfort default, the opacity options of render."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from media_helpers import gray_frames, write_clip

from simulator.core.errors import InputError
from simulator.mitigation.opacity import OpacityRule, comfort_rule, ease


def _data_lines(path):
    """The lines of an EPOF CSV without its '#' settings lines (header first)."""
    return [ln for ln in path.read_text().splitlines() if not ln.startswith("#")]


def test_ease_is_a_slew_rate_limit_analytic():
    step = np.array([0, 1, 1, 1, 1, 1, 1, 0, 0, 0, 0, 0, 0, 0, 0.0])
    out = ease(step, 10.0, 0.5, 1.0)  # up 0.2 / frame, down 0.1 / frame
    want = [0, 0.2, 0.4, 0.6, 0.8, 1.0, 1.0, 0.9, 0.8, 0.7, 0.6, 0.5, 0.4, 0.3, 0.2]
    assert np.allclose(out, want)
    assert np.array_equal(ease(step, 10.0, 0.0, 0.0), step)  # 0 = unlimited


def test_rule_paper_is_the_clamp_and_eased_bounds_the_change():
    rng = np.random.default_rng(1)
    e = rng.uniform(0, 100, 500)
    paper = OpacityRule()
    assert paper.is_paper
    assert np.allclose(paper(e, (20.0, 80.0)), np.clip((e - 20) / 60, 0, 1))
    r = comfort_rule()
    op = r(e, (20.0, 80.0), fps=30.0)
    d = np.diff(op)
    assert d.max() <= 1 / (30 * r.ease_in_s) + 1e-12
    assert -d.min() <= 1 / (30 * r.ease_out_s) + 1e-12
    assert np.abs(d).max() < np.abs(np.diff(paper(e, (20.0, 80.0)))).max()
    with pytest.raises(InputError, match="frame rate"):
        r(e, (20.0, 80.0))
    with pytest.raises(InputError, match="ease-in"):
        OpacityRule(ease_in_s=-1)


def _grid_and_path(tmp_path: Path, n: int = 6):
    from simulator.media.gridfile import save_grid
    from simulator.sphere.windows import WindowGrid

    g = WindowGrid()
    rng = np.random.default_rng(0)
    z = rng.uniform(0, 50, (n, len(g.pitch_deg), len(g.yaw_deg)))
    z = (z * np.where(np.arange(n) % 2, 3.0, 0.3)[:, None, None]).astype(np.float32)  # shake
    meta = {"fps": 10.0, "n_frames": n, "flow": {"method": "none"}, "layout": "mono",
            "eye": "left", "video": {"path": "v.mp4", "width": 128, "height": 64, "sar": 1.0}}  # fmt: skip
    save_grid(tmp_path / "g.npz", z, z, g, meta)
    (tmp_path / "p.csv").write_text(
        "time_s,yaw_deg,pitch_deg,roll_deg\n0,0,0,0\n" + f"{n / 10:.1f},90,0,0\n"
    )
    return tmp_path / "g.npz", tmp_path / "p.csv"


def _opacity(csv: Path) -> np.ndarray:
    return np.array([float(r.split(",")[6]) for r in _data_lines(csv)[1:]])


def test_epof_cli_comfort_default_paper_one_option_away(tmp_path, capsys):
    from simulator.cli import main

    g, p = _grid_and_path(tmp_path)
    a, b = tmp_path / "a.csv", tmp_path / "b.csv"
    assert main(["epof", str(g), str(p), "-o", str(a)]) == 0
    assert main(["epof", str(g), str(p), "-o", str(b), "--opacity-rule", "paper"]) == 0
    oa, ob = _opacity(a), _opacity(b)
    assert np.abs(np.diff(oa)).max() <= 1 / (10 * 0.4) + 1e-6
    assert not np.allclose(oa, ob)
    e = np.array([float(r.split(",")[5]) for r in _data_lines(b)[1:]])
    assert np.corrcoef(e, ob)[0, 1] > 0.99  # paper: opacity follows EPOF frame by frame
    from simulator.epof import read_epof_csv

    # each CSV records the rule that made its opacity
    assert read_epof_csv(a).meta["settings"]["opacity_rule"]["rule"] == "eased"
    assert read_epof_csv(b).meta["settings"]["opacity_rule"]["rule"] == "paper"
    capsys.readouterr()
    c = tmp_path / "c.csv"
    assert (
        main(["epof", str(g), str(p), "-o", str(c), "--opacity-rule", "paper", "--ease-in", "1"])
        == 2
    )
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--ease-in" in err and not c.exists()


@pytest.mark.gl
def test_render_takes_epof_csv_opacity(tmp_path, capsys):
    from simulator.render import create_context

    try:
        create_context()
    except InputError as e:
        pytest.skip(f"headless EGL absent ({e})")
    from simulator.cli import main

    vid = write_clip(tmp_path / "v.mp4", gray_frames(100 + 10 * i for i in range(6)))
    p = tmp_path / "p.csv"
    p.write_text("time_s,yaw_deg,pitch_deg,roll_deg\n0,0,0,0\n1,10,0,0\n")
    ecsv = tmp_path / "e.csv"
    ops = [0.0, 0.1, 0.5, 0.9, 1.0, 0.3]
    ecsv.write_text("frame,time_s,yaw_deg,pitch_deg,roll_deg,epof_dps,opacity\n"
                    + "".join(f"{i},{i / 10},0,0,0,1,{o}\n" for i, o in enumerate(ops)))  # fmt: skip
    out = tmp_path / "o"
    base = ["render", str(vid), str(p), "-o", str(out), "--eye-size", "32x32", "--no-progress"]
    assert main([*base, "--opacity", str(ecsv)]) == 0
    got = _opacity(out / "epof.csv")
    assert np.allclose(got, ops)
    s = json.loads((out / "summary.json").read_text())
    assert s["grf"] is not None and s["opacity"] == str(ecsv)
    # A CSV with other frame counts: one line, exit 2, nothing written.
    short = tmp_path / "short.csv"
    short.write_text("\n".join(_data_lines(ecsv)[:4]) + "\n")
    out2 = tmp_path / "o2"
    capsys.readouterr()
    assert main([*base[:4], str(out2), *base[5:], "--opacity", str(short)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "short.csv" in err and "frames" in err
    assert not out2.exists() or not list(out2.iterdir())
