"""JSON head logs read entry by entry: the same rows and errors as a whole-document parse, across block boundaries, in memory within a few times the file's size."""

from __future__ import annotations

import json
import tracemalloc

import numpy as np
import pytest

from simulator.core.errors import InputError
from simulator.traces.readers import jsonlog, load_columns

SIT_FORMAT = "%Y%m%dZ-%H%M%S_%fZ"
SIT_MAP = "time=key,yaw=HMD.rot.y,pitch=-HMD.rot.x,roll=-HMD.rot.z"


def _sit(n: int) -> dict:
    log = {}
    for k in range(n):
        ms = 686 + 20 * k
        key = f"20210510Z-{20 + ms // 3_600_000:02d}{ms // 60_000 % 60:02d}{ms // 1000 % 60:02d}_{ms % 1000:03d}Z"
        log[key] = {"HMD": {"rot": {"x": (2.5 * k) % 360.0, "y": (3.25 * k) % 360.0, "z": 0.125},
                            "pos": {"x": 0.1, "y": 1.6, "z": -0.2}}, "scene": "sandwich",
                    "buttons": [0, 1, 0]}  # fmt: skip
    return log


@pytest.mark.parametrize("block", [1, 7, 64, 1 << 20])
@pytest.mark.parametrize("doc", [
    _sit(25),
    [{"t": k / 10, "y": 1.5 * k, "x": -k} for k in range(30)],
    [1.25, 2.5, 12345.678, -3e-5, 7],
    {},
    [],
])  # fmt: skip
def test_entries_as_a_whole_parse_at_any_block_size(tmp_path, monkeypatch, block, doc):
    monkeypatch.setattr(jsonlog, "BLOCK_CHARS", block)
    p = tmp_path / "log.json"
    for text in (json.dumps(doc), json.dumps(doc, indent=2)):
        p.write_text(text)
        got = list(jsonlog.json_entries(p))
        want = list(doc.items()) if isinstance(doc, dict) else [(None, v) for v in doc]
        assert got == want


@pytest.mark.parametrize("block", [3, 1 << 20])
@pytest.mark.parametrize("text", [
    '{"a": {"x": 1},\n"b": {"x": 2}\n"c": 3}',
    '[{"t": 1},\n {"t": 2},\n {"t": }]',
    '{"a": 1,\n}',
    '[1, 2]\n[3]',
    '{"a": 1',
    '{1: 2}',
])  # fmt: skip
def test_invalid_json_named_with_its_line(tmp_path, monkeypatch, block, text):
    monkeypatch.setattr(jsonlog, "BLOCK_CHARS", block)
    p = tmp_path / "bad.json"
    p.write_text(text)
    with pytest.raises(json.JSONDecodeError) as want:
        json.loads(text)
    with pytest.raises(InputError, match=rf"bad.json: not valid JSON \(line {want.value.lineno}:"):
        list(jsonlog.json_entries(p))


def test_deep_nesting_is_bad_input(tmp_path):
    p = tmp_path / "deep.json"
    p.write_text("[" + "[" * 200_000 + "]" * 200_000 + "]")
    with pytest.raises(InputError, match="deep.json: JSON nested too deeply"):
        list(jsonlog.json_entries(p))


def test_a_long_one_line_log_is_read_within_3x_its_size(tmp_path, monkeypatch):
    """Each entry's mapped numbers are kept, not its objects: the reader's peak
    allocations stay within 3x the file (a whole-document parse and a dict per sample
    took over 20x: a 94 MB log peaked at 2.6 GB). Blocks of 64 KB scale the reader's
    fixed buffer to this small log (bench/jsonlog_memory.py: a 100 MB one)."""
    monkeypatch.setattr(jsonlog, "BLOCK_CHARS", 1 << 16)
    log = [{"t": k / 50, "HMD": {"rot": {"x": (2.5 * k) % 360.0, "y": (3.25 * k) % 360.0,
            "z": 0.125}, "pos": {"x": 0.1, "y": 1.6, "z": -0.2}}, "scene": "sandwich",
            "buttons": [0, 1, 0]} for k in range(6000)]  # fmt: skip
    p = tmp_path / "long.json"
    p.write_text(json.dumps(log, separators=(",", ":")))  # one line
    size = p.stat().st_size
    tracemalloc.start()
    try:
        hp = load_columns(p, "time=t,yaw=HMD.rot.y,pitch=-HMD.rot.x,roll=-HMD.rot.z")
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert hp.n == 6000
    assert np.allclose(hp.times_s[:3], [0.0, 0.02, 0.04])
    assert peak < 3 * size, (peak, size)
