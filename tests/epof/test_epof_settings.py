"""EPOF CSVs and summary.json record the method, frustum and opacity rule; a stereo grid's eye picks the EPOF's frustum."""

from __future__ import annotations

import json

import numpy as np
import pytest
from media_helpers import gray_frames, write_clip

from simulator.epof import EPOF_COLUMNS, read_epof_csv, viewport_epof
from simulator.media.gridfile import load_grid, save_grid
from simulator.preprocess import SphereConfig, field_meta
from simulator.sphere.cells import CellGrid, Frustum, window_pof
from simulator.sphere.windows import grid_preset
from simulator.traces.path import save_headpath_csv, synth

CELL = 6.0


def _field(seed: int, T: int) -> np.ndarray:
    """A smooth random positive field (T, n_lat, n_lon), not symmetric left/right."""
    rng = np.random.default_rng(seed)
    lon, lat = CellGrid(CELL).centres_lonlat()
    LON, LAT = np.meshgrid(lon, lat)
    d = np.stack([np.cos(LAT) * np.sin(LON), np.sin(LAT), np.cos(LAT) * np.cos(LON)], -1)
    out = np.empty((T, *LON.shape), np.float32)
    for t in range(T):
        a, b = rng.normal(size=(2, 3))
        out[t] = 45 + 12 * (d @ a) + 5 * (d @ b) ** 2 + 6 * np.sin(3 * LON + 0.7) * np.cos(LAT)
    return out


def _sphere_grid(path, *, T=4, w=128, h=64, layout="mono", eye="left"):
    grid = grid_preset("default")
    f = _field(1, T)
    dps, px = window_pof(f, CELL, grid, 30.0)
    meta = {"fps": 30.0, "n_frames": T, "flow": {"method": "dis"}, "layout": layout,
            "eye": eye, "video": {"path": "x.mp4", "width": w, "height": h, "sar": 1.0},
            "field": field_meta(SphereConfig(cell_deg=CELL))}  # fmt: skip
    save_grid(path, dps, px, grid, meta, field_dps=f)
    return f


def test_epof_csv_records_settings_and_top_k_method(tmp_path, capsys):
    from simulator.analyze.data import session_flow
    from simulator.cli import main

    _sphere_grid(tmp_path / "s.npz")
    save_headpath_csv(tmp_path / "p.csv", synth("sine", 1.0, rate_hz=60.0))
    base = ["epof", str(tmp_path / "s.npz"), str(tmp_path / "p.csv"), "-o"]
    assert main([*base, str(tmp_path / "a.csv")]) == 0
    assert main([*base, str(tmp_path / "k.csv"), "--top-k", "4"]) == 0
    assert "--top-k uses paper-mode EPOF" in capsys.readouterr().err
    a, k = read_epof_csv(tmp_path / "a.csv"), read_epof_csv(tmp_path / "k.csv")
    sa, sk = a.meta["settings"], k.meta["settings"]
    assert sa["epof_method"] == "sphere" and sa["top_k"] is None
    assert sk["epof_method"] == "paper" and sk["top_k"] == 4
    assert not np.allclose(a.epof_dps, k.epof_dps)  # really another method
    assert sa["opacity_rule"]["rule"] == "eased"
    assert sa["opacity_thresholds_dps"] == pytest.approx(list(a.thresholds_dps))
    # the columns are unchanged below the '#' lines; every reader skips those
    text = (tmp_path / "k.csv").read_text().splitlines()
    data = [ln for ln in text if not ln.startswith("#")]
    assert data[0] == ",".join(EPOF_COLUMNS) and len(data) == 5 and text[0].startswith("# ")
    assert session_flow(tmp_path / "k.csv") == pytest.approx(float(np.mean(k.epof_dps)))
    assert session_flow(tmp_path / "k.csv", "sum") == pytest.approx(float(np.sum(k.epof_dps)))


def test_stereo_grid_eye_picks_the_epof_frustum(tmp_path):
    """A grid of the right eye of a top-bottom video: the EPOF is over the right eye's
    frustum (the left's mirrored), exactly as viewport_epof gives it."""
    from simulator.media.source import Source
    from simulator.render import RenderConfig
    from simulator.viewing.job import plan_viewing

    vid = write_clip(tmp_path / "tb.mp4", gray_frames([90] * 4, (128, 128)), 30.0)
    hp = synth("sine", 1.0, rate_hz=60.0)
    fr = Frustum.from_headset("quest-2", "left")
    assert fr.left_deg != fr.right_deg
    mirrored = Frustum(fr.right_deg, fr.left_deg, fr.down_deg, fr.up_deg)
    yaw, pitch, roll = hp.sample_angles_deg(np.arange(4) / 30.0)
    cfg = RenderConfig(eye_size=(32, 32), frustum=fr, grf=None)
    got = {}
    for eye in ("left", "right"):
        f = _sphere_grid(tmp_path / f"{eye}.npz", w=128, h=128, layout="top-bottom", eye=eye)
        plan = plan_viewing(Source.open(vid, layout="top-bottom"), hp,
                            grid=load_grid(tmp_path / f"{eye}.npz"), config=cfg)  # fmt: skip
        want = fr if eye == "left" else mirrored
        assert plan.epof_eye == eye and plan.epof_frustum == want
        exact = viewport_epof(f, CELL, yaw, pitch, roll, frustum=want)
        assert np.allclose(plan.epof_dps, exact, rtol=1e-9)
        got[eye] = plan.epof_dps
    assert np.max(np.abs(got["left"] - got["right"])) > 1e-3 * np.max(got["left"])


@pytest.mark.gl
def test_render_records_settings_in_summary_and_csv(tmp_path):
    from simulator.cli import main

    pytest.importorskip("moderngl")
    from simulator.core.errors import InputError
    from simulator.render import create_context

    try:
        create_context()
    except InputError as e:
        pytest.skip(f"headless EGL absent ({e})")

    vid = write_clip(tmp_path / "v.mp4", gray_frames(40 * i for i in range(4)), 30.0)
    _sphere_grid(tmp_path / "g.npz")
    save_headpath_csv(tmp_path / "p.csv", synth("sine", 1.0, rate_hz=60.0))
    out = tmp_path / "o"
    argv = ["render", str(vid), str(tmp_path / "p.csv"), "-o", str(out), "--grid",
            str(tmp_path / "g.npz"), "--eye-size", "32x32", "--no-progress", "--headset",
            "quest-2", "--opacity-rule", "paper"]  # fmt: skip
    assert main(argv) == 0
    s = json.loads((out / "summary.json").read_text())
    c = read_epof_csv(out / "epof.csv").meta["settings"]
    fr = Frustum.from_headset("quest-2", "left")
    want = {"left": fr.left_deg, "right": fr.right_deg, "down": fr.down_deg, "up": fr.up_deg}
    for d in (s, c):
        assert d["epof_method"] == "sphere" and d["opacity_rule"]["rule"] == "paper"
        assert d["opacity_thresholds_dps"] == pytest.approx(s["opacity_thresholds_dps"])
    assert s["epof_frustum_deg"] == pytest.approx(want) and c["frustum_deg"] == pytest.approx(want)
    assert np.isfinite(s["opacity_thresholds_dps"]).all()
