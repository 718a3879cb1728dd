"""Legibility: the review strip's legend and threshold lines, local-grf without an
opacity it does not use, the EPOF plot's yaw line broken at the seam."""

from __future__ import annotations

import numpy as np

from simulator.epof.viewing import break_at_wraps
from simulator.viewing.review import ReviewWriter


def _writer(tmp_path, **kw):
    n = 20
    return ReviewWriter(tmp_path / "r.mp4", tmp_path / "s.png", times_s=np.arange(n) / 10,
                        yaw_deg=np.zeros(n), pitch_deg=np.zeros(n), roll_deg=np.zeros(n),
                        epof_dps=np.linspace(0, 41, n), opacity=np.linspace(0, 1, n),
                        hfov_deg=90, vfov_deg=90, fps=10, height=120, **kw)  # fmt: skip


def test_strip_threshold_lines_and_local_grf(tmp_path):
    plain = _writer(tmp_path)
    lined = _writer(tmp_path, thresholds_dps=(10.0, 30.0))
    # dashed lines in the EPOF colour at the thresholds' heights: the strips differ there
    diff = np.abs(lined._strip.astype(int) - plain._strip.astype(int)).sum(axis=(1, 2))
    assert diff.max() > 0
    h, top = lined.strip_h, 6
    bot = h - 18
    y30 = round(bot - 30.0 / lined.epof_max * (bot - top))
    assert diff[y30] > 0
    assert "opacity" in plain._numbers(3) and "deg/s" in plain._numbers(3)
    local = _writer(tmp_path, opacity_used=False)
    assert "opacity" not in local._numbers(3)
    for w in (plain, lined, local):
        w.close(ok=False)


def test_yaw_line_breaks_at_the_seam():
    t = np.arange(6.0)
    yaw = np.array([170.0, 175.0, 179.0, -178.0, -170.0, -160.0])
    tb, yb = break_at_wraps(t, yaw)
    assert np.isnan(yb[3]) and np.isnan(tb[3]) and len(yb) == 7
    assert np.nanmax(np.abs(np.diff(yb[~np.isnan(yb)][:3]))) < 10
    _, same_y = break_at_wraps(t, np.linspace(-90, 90, 6))
    assert not np.isnan(same_y).any()
