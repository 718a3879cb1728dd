"""Artefact detection on picture signals and flow made here with known artefacts."""

from __future__ import annotations

import numpy as np
import pytest

from simulator.core.errors import InputError
from simulator.preprocess.artefacts import (
    FrameSignals,
    detect_artefacts,
    load_artefacts,
    save_artefacts,
)

T = 120


def _signals(rng, *, std=None, corr=None, diff=None, coarse=None) -> FrameSignals:
    """A moving textured scene: steady contrast, correlation, change (noise on top)."""
    s = np.full(T, 30.0) if std is None else std
    c = 0.9 + 0.01 * rng.standard_normal(T) if corr is None else corr
    bd = (2.0 + 0.1 * rng.standard_normal((T, 512))).astype(np.float32) if diff is None else diff
    cc = (90 + 30 * rng.standard_normal((T, 128))).astype(np.float32) if coarse is None else coarse
    return FrameSignals(np.full(T, 90.0), s, c, bd, cc, 30.0)


def test_clean_scene_has_no_artefacts():
    rng = np.random.default_rng(0)
    pof = 20 + rng.standard_normal((T, 11, 24))
    a = detect_artefacts(_signals(rng), pof)
    assert a.counts() == {"cut": 0, "fade": 0, "keyframe": 0, "overlay": 0, "camera-fixed": 0}
    assert a.events == ()


def test_cut_is_one_frame():
    rng = np.random.default_rng(1)
    corr = 0.9 + 0.01 * rng.standard_normal(T)
    corr[60] = 0.02
    pof = 20 + rng.standard_normal((T, 11, 24))
    pof[60] *= 5
    a = detect_artefacts(_signals(rng, corr=corr), pof)
    assert [k for k in a.kind if k] == ["cut"]
    assert a.kind[60] == "cut"


def test_periodic_keyframes_found_with_their_period():
    rng = np.random.default_rng(2)
    diff = (1.0 + 0.1 * rng.standard_normal((T, 512))).astype(np.float32)
    diff[15::15] *= 3.0  # the picture resets every 15 frames
    a = detect_artefacts(_signals(rng, diff=diff), 5 + rng.standard_normal((T, 11, 24)))
    assert [i for i, k in enumerate(a.kind) if k] == list(range(15, T, 15))
    assert set(a.kind) == {"", "keyframe"}
    assert a.keyframe_period == 15


def test_fade_to_black_and_its_black_frames():
    rng = np.random.default_rng(3)
    gain = np.ones(T)
    gain[60:90] = np.linspace(1, 0, 32)[1:31]
    gain[90:] = 0.0
    base = (90 + 30 * rng.standard_normal(128)).astype(np.float32)
    coarse = np.outer(gain, base).astype(np.float32) + rng.standard_normal((T, 128)).astype(
        np.float32
    )
    std = np.maximum(30 * gain, 0.3)
    a = detect_artefacts(_signals(rng, std=std, coarse=coarse), None)
    found = {i for i, k in enumerate(a.kind) if k == "fade"}
    assert set(range(62, T)) <= found  # the ramp (after its first frames) and the black
    assert not found & set(range(55))


def test_flow_only_spike_everywhere_is_a_keyframe():
    rng = np.random.default_rng(4)
    pof = 2 + 0.1 * rng.standard_normal((T, 11, 24))
    pof[40] += 10.0
    a = detect_artefacts(None, pof, fps=30.0)
    assert [i for i, k in enumerate(a.kind) if k] == [40]
    assert a.events[0]["start_s"] == pytest.approx(40 / 30)


def test_needs_some_signal():
    with pytest.raises(InputError, match="needs"):
        detect_artefacts(None, None)


def test_json_round_trip(tmp_path):
    rng = np.random.default_rng(5)
    pof = 2 + 0.1 * rng.standard_normal((T, 11, 24))
    pof[40] += 10.0
    a = detect_artefacts(None, pof, fps=30.0)
    save_artefacts(tmp_path / "a.json", a)
    b = load_artefacts(tmp_path / "a.json")
    assert b.kind == a.kind
    (tmp_path / "bad.json").write_text('{"format": "x"}')
    with pytest.raises(InputError, match="not a vimsim artefacts file"):
        load_artefacts(tmp_path / "bad.json")


def test_weak_resets_on_a_regular_period_are_keyframes():
    rng = np.random.default_rng(6)
    diff = (1.0 + 0.05 * rng.standard_normal((T, 512))).astype(np.float32)
    diff[12::12] *= 1.4  # too weak alone (< 1.6x), but every 12th frame
    a = detect_artefacts(_signals(rng, diff=diff), 5 + rng.standard_normal((T, 11, 24)))
    assert [i for i, k in enumerate(a.kind) if k] == list(range(12, T, 12))
    diff = (1.0 + 0.05 * rng.standard_normal((T, 512))).astype(np.float32)
    diff[[17, 40, 77, 95]] *= 1.4  # as weak, not periodic: nothing
    a = detect_artefacts(_signals(rng, diff=diff), 5 + rng.standard_normal((T, 11, 24)))
    assert a.counts()["keyframe"] == 0
