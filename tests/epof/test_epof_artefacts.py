"""EPOF with artefact frames: left out of the opacity percentiles, opacity held, CSV column."""

from __future__ import annotations

import numpy as np
import pytest
from test_epof import GRIDS, _gridfile

from simulator.epof import compute_epof
from simulator.epof.viewing import read_epof_csv, write_epof_csv
from simulator.media.gridfile import load_grid
from simulator.mitigation.grf import OpacityRule
from simulator.preprocess.artefacts import Artefacts
from simulator.traces.path import synth


@pytest.mark.parametrize("source", ["grid", "viewing"])
def test_artefact_frames_out_of_thresholds_and_opacity_held(tmp_path, source):
    g = GRIDS["default"]
    pof = np.full((40, *g.shape), 10.0) + np.linspace(0, 5, 40)[:, None, None]
    pof[20] = 500.0  # a keyframe: every window at once, one frame
    gf = load_grid(_gridfile(tmp_path, g, pof, fps=10.0))
    hp = synth("static", 4.0, rate_hz=50)
    rule = OpacityRule(low_pct=0, high_pct=100, source=source)
    plain = compute_epof(gf, hp, rule=rule)
    assert plain.thresholds_dps[1] == pytest.approx(500.0, rel=1e-6)  # the artefact sets 1
    kinds = tuple("keyframe" if i == 20 else "" for i in range(40))
    res = compute_epof(gf, hp, rule=rule, artefacts=Artefacts(kinds))
    assert res.thresholds_dps[1] == pytest.approx(15.0, rel=1e-6)  # the clean maximum
    assert res.opacity[20] == res.opacity[19]  # held from the previous frame
    assert res.epof_dps[20] == pytest.approx(500.0, rel=1e-6)  # EPOF kept as measured
    assert res.artefact == kinds
    write_epof_csv(tmp_path / "e.csv", res)
    back = read_epof_csv(tmp_path / "e.csv")
    assert back.artefact == kinds
    np.testing.assert_allclose(back.opacity, res.opacity, atol=1e-9)
    header = next(
        ln for ln in (tmp_path / "e.csv").read_text().splitlines() if not ln.startswith("#")
    )
    assert header.endswith(",opacity,artefact")


def test_wrong_length_is_refused(tmp_path):
    g = GRIDS["default"]
    gf = load_grid(_gridfile(tmp_path, g, np.ones((10, *g.shape)), fps=10.0))
    with pytest.raises(Exception, match="artefacts: 3 frames; the grid has 10"):
        compute_epof(gf, synth("static", 2.0, rate_hz=50), artefacts=Artefacts(("",) * 3))


def test_camera_fixed_frames_stay_in_the_epof(tmp_path):
    """A hand or a thumb at the lens is seen: its frames stay in the thresholds and the
    opacity follows them (nothing held), while the CSV still names them."""
    g = GRIDS["default"]
    pof = np.full((40, *g.shape), 10.0) + np.linspace(0, 5, 40)[:, None, None]
    pof[20] = 500.0  # the thumb enters
    gf = load_grid(_gridfile(tmp_path, g, pof, fps=10.0))
    hp = synth("static", 4.0, rate_hz=50)
    rule = OpacityRule(low_pct=0, high_pct=100)
    kinds = tuple("camera-fixed" if i == 20 else "" for i in range(40))
    res = compute_epof(gf, hp, rule=rule, artefacts=Artefacts(kinds))
    plain = compute_epof(gf, hp, rule=rule)
    assert res.thresholds_dps == pytest.approx(plain.thresholds_dps)  # kept in the thresholds
    np.testing.assert_allclose(res.opacity, plain.opacity)  # not held
    assert res.artefact == kinds and not Artefacts(kinds).mask.any()
