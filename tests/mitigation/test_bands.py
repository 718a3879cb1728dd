"""Named flow bands and the absolute opacity rule."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from simulator.core.errors import InputError
from simulator.mitigation.bands import (
    ABSOLUTE_HIGH_DPS,
    ABSOLUTE_LOW_DPS,
    BANDS,
    band_of,
    share_above,
)
from simulator.mitigation.grf import OpacityRule


def test_bands_tile_the_axis_and_name_a_source():
    assert BANDS[0].lo_dps == 0 and math.isinf(BANDS[-1].hi_dps)
    for a, b in itertools.pairwise(BANDS):
        assert a.hi_dps == b.lo_dps
    assert all(b.source for b in BANDS)
    assert band_of(1.0) == "calm" and band_of(12.0) == "vection" and band_of(45) == "provocative"
    assert band_of(300.0) == "strong"


def test_share_above_leaves_out_masked_samples():
    e = np.array([1.0, 10.0, 40.0, 100.0])
    s = share_above(e, keep=[True, True, True, False])
    assert s == {"share_ge_vection": pytest.approx(2 / 3), "share_ge_provocative": pytest.approx(1 / 3),
                 "share_ge_strong": 0.0}  # fmt: skip


def test_absolute_rule_is_the_same_for_calm_and_provocative_flow():
    rule = OpacityRule(low_dps=ABSOLUTE_LOW_DPS, high_dps=ABSOLUTE_HIGH_DPS)
    calm, wild = np.full(50, 1.1), np.full(50, 40.0)
    assert rule.fit(None, calm) == rule.fit(None, wild) == (5.0, 30.0)
    assert rule(calm, rule.fit(None, calm)).max() == 0.0
    assert rule(wild, rule.fit(None, wild)).min() == 1.0
    assert rule.describe()["scale"] == "absolute"
    rel = OpacityRule(source="viewing")
    ramp = np.linspace(0.5, 1.5, 50)
    assert rel(ramp, rel.fit(None, ramp)).max() == 1.0  # relative: a calm video gets grains


@pytest.mark.parametrize(
    ("lo", "hi", "msg"),
    [(5.0, None, "both"), (30.0, 5.0, "below"), (5.0, 5.0, "below"), (math.nan, 3.0, "finite"),
     (-1.0, 3.0, "finite"), (1.0, math.inf, "finite")],
)  # fmt: skip
def test_absolute_rule_bad_thresholds(lo, hi, msg):
    with pytest.raises(InputError, match=msg):
        OpacityRule(low_dps=lo, high_dps=hi)


def test_fit_keep_leaves_rows_out():
    rule = OpacityRule(source="viewing", low_pct=0, high_pct=100)
    e = np.array([1.0, 2.0, 3.0, 100.0])
    assert rule.fit(None, e, keep=np.array([True, True, True, False])) == (1.0, 3.0)
