"""Coverage: a VR180 (hequirect) source measures no flow behind the viewer; EPOF averages the covered part and reports its share."""

from __future__ import annotations

import subprocess

import numpy as np
import pytest

from simulator.cli import main
from simulator.epof.viewing import compute_epof, read_epof_csv
from simulator.media.coverage import MIN_COVERAGE, coverage_masks
from simulator.media.gridfile import load_grid
from simulator.testing.reference import ffmpeg_exe
from simulator.traces.path import HeadPath


@pytest.fixture(scope="module")
def vr180(tmp_path_factory):
    d = tmp_path_factory.mktemp("vr180")
    assert main(["synth", str(d / "r.mp4"), "--scene", "rotate", "--seconds", "1",
                 "--fps", "10", "--size", "128x64"]) == 0  # fmt: skip
    subprocess.run([ffmpeg_exe(), "-v", "error", "-y", "-i", str(d / "r.mp4"), "-vf",
                    "v360=e:hequirect:w=64:h=64", "-c:v", "libx264", "-crf", "10", str(d / "h.mp4")],
                   check=True)  # fmt: skip
    return d


@pytest.mark.parametrize("method", ["sphere", "paper"])
def test_vr180_back_half_not_measured_and_epof_over_covered_part(vr180, method):
    g = vr180 / f"{method}.npz"
    args = ["preprocess", str(vr180 / "h.mp4"), "-o", str(g), "--method", method,
            "--projection", "hequirect", "--no-progress", "--window-size", "32"]  # fmt: skip
    assert main(args + (["--cell", "10"] if method == "sphere" else [])) == 0
    grid = load_grid(g)
    wins, cells = coverage_masks(grid.meta)
    assert 0.45 < grid.meta["coverage"]["sphere_share"] < 0.55
    assert not wins.all() and wins.any()
    assert np.all(np.asarray(grid.pof_dps)[:, ~wins] == 0)  # nothing measured behind
    if method == "sphere":
        f = np.asarray(grid.field_dps[:])
        assert np.all(f[:, ~cells] == 0) and f[:, cells].mean() > 1
    t = np.array([0.0, 1.0])
    front = HeadPath.from_angles_deg(t, np.zeros(2), np.zeros(2), np.zeros(2))
    back = HeadPath.from_angles_deg(t, np.full(2, 180.0), np.zeros(2), np.zeros(2))
    side = HeadPath.from_angles_deg(t, np.full(2, 80.0), np.zeros(2), np.zeros(2))
    rf, rb, rs = (compute_epof(grid, hp, hold=True) for hp in (front, back, side))
    assert np.all(rf.coverage > 0.95) and np.all(rb.coverage < 0.05)
    assert np.all(rb.epof_dps == 0)  # nothing seen: no flow
    assert np.all((rs.coverage > MIN_COVERAGE) & (rs.coverage < 0.9))
    # the covered part's mean, not diluted by the black half
    assert np.median(rs.epof_dps[1:]) > 0.7 * np.median(rf.epof_dps[1:])


def test_epof_csv_has_the_coverage_column(vr180, tmp_path):
    g = vr180 / "sphere.npz"
    if not g.exists():
        assert main(["preprocess", str(vr180 / "h.mp4"), "-o", str(g), "--method", "sphere",
                     "--projection", "hequirect", "--no-progress", "--cell", "10"]) == 0  # fmt: skip
    assert (
        main(["headpath", "synth", "sweep", "-o", str(tmp_path / "p.csv"), "--seconds", "2"]) == 0
    )
    assert main(["epof", str(g), str(tmp_path / "p.csv"), "-o", str(tmp_path / "e.csv")]) == 0
    text = (tmp_path / "e.csv").read_text()
    header = next(ln for ln in text.splitlines() if not ln.startswith("#"))
    assert header.endswith(",coverage") and "coverage_rule" not in header
    assert len(read_epof_csv(tmp_path / "e.csv").frame) == 10


def test_opacity_thresholds_come_from_covered_windows_only(vr180, tmp_path):
    """The grid-wide opacity percentiles (the paper's "whole video") leave out the windows
    the projection does not cover: their 0 deg/s is no measured flow. With them, VR180's
    10th percentile would be 0 (half the sphere is black)."""
    from simulator.mitigation.grf import OpacityRule

    g = tmp_path / "p.npz"
    assert main(["preprocess", str(vr180 / "h.mp4"), "-o", str(g), "--method", "paper",
                 "--projection", "hequirect", "--no-progress", "--window-size", "32"]) == 0  # fmt: skip
    grid = load_grid(g)
    wins, _ = coverage_masks(grid.meta)
    pof = np.asarray(grid.pof_dps, np.float64)
    want = np.percentile(pof[:, wins], [10, 90])
    lo, hi = OpacityRule().fit(grid, None)
    assert (lo, hi) == pytest.approx(tuple(want))
    assert lo > 0.5 * np.median(pof[:, wins])  # not pulled to 0 by the black half
    assert np.percentile(pof, 10) == 0.0  # which counting every window would give
    # the export's thresholds are the same ones (a sphere-mode grid: paper-mode exports of
    # a partial source are refused, tests/export/test_export_coverage.py)
    from simulator.export.unity import export_unity

    gs = tmp_path / "s.npz"
    assert main(["preprocess", str(vr180 / "h.mp4"), "-o", str(gs), "--method", "sphere",
                 "--projection", "hequirect", "--no-progress", "--window-size", "32",
                 "--cell", "10"]) == 0  # fmt: skip
    sphere = load_grid(gs)
    ws, _ = coverage_masks(sphere.meta)
    lo_s, hi_s = OpacityRule().fit(sphere, None)
    want_s = np.percentile(np.asarray(sphere.pof_dps, np.float64)[:, ws], [10, 90])
    assert (lo_s, hi_s) == pytest.approx(tuple(want_s))
    h = export_unity(gs, tmp_path / "x").header
    assert (h["opacity"]["low_dps"], h["opacity"]["high_dps"]) == pytest.approx((lo_s, hi_s))
