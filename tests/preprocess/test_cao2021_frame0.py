"""The authors' frame-0 defect (88 deg instead of 107) is measured for cao2021 grids and read only
by the cao2021-code preset: the grains flash at video frame 2 there, never in vimsim's own EPOF."""

from __future__ import annotations

import numpy as np
import pytest

from simulator.epof import compute_epof
from simulator.epof.nearest import nearest_epof, preset_pof_px
from simulator.media.gridfile import load_grid
from simulator.mitigation.grf import OpacityRule
from simulator.preprocess import preprocess_video
from simulator.sphere.windows import grid_preset
from simulator.synth import SynthConfig, synthesize
from simulator.traces.path import synth


@pytest.mark.slow  # 312 windows per frame: a few seconds unloaded
def test_frame0_defect_only_in_preset(tmp_path):
    vid = tmp_path / "c.mp4"
    synthesize(SynthConfig("rotate", 2.0, 4.0, (128, 64), omega_dps=4.0), vid)
    out = tmp_path / "g.npz"
    preprocess_video(str(vid), out, grid=grid_preset("cao2021", size=(32, 29)), progress=False)
    g = load_grid(out)
    row0 = np.asarray(g.meta["cao"]["row0_px"])
    assert row0.shape == g.pof_px.shape[1:]
    ratio = row0.mean() / g.pof_px[1:].mean()
    assert ratio > 5, ratio  # the zoom 88 -> 107 deg dwarfs the 1 deg/frame pan
    np.testing.assert_array_equal(g.pof_px[0], g.pof_px[1])  # vimsim's own row 0 is untouched
    assert np.array_equal(preset_pof_px(g)[0], row0.astype(np.float32))
    hp = synth("static", 2.0, yaw=10.0)
    res = nearest_epof(g, hp, hold=True)
    px = res.meta["flow_px"]
    assert px[0] == px[1] == 0 and px[2] == np.float32(row0[6, 13])  # yaw 10 -> 15, pitch 0
    assert px[2] > 5 * np.median(px[3:])
    own = compute_epof(g, hp, rule=OpacityRule(), hold=True)
    assert own.epof_dps[2] < 2 * np.median(own.epof_dps[3:])  # no flash in vimsim's EPOF
