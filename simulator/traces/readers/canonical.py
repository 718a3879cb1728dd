"""vimsim's own head-path formats: the canonical CSV, a quaternion CSV and keyframes JSON."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from simulator.core.errors import InputError
from simulator.traces.path import CANONICAL_COLUMNS, HeadPath
from simulator.traces.readers.common import (
    _check_finite,
    _check_increasing,
    _check_pitch,
    _columns,
    _hint,
    _parse_table,
    _quats_to_rotation,
    _value,
    _warn_if_milliseconds,
    _warn_if_radians,
)
from simulator.traces.readers.formats import TraceFormat

QUAT_COLUMNS: tuple[str, ...] = ("time_s", "qw", "qx", "qy", "qz")


def _read_canonical(p: Path) -> HeadPath:
    """Canonical CSV ``time_s,yaw_deg,pitch_deg[,roll_deg]`` (degrees; roll 0 if absent)."""
    cols, data, lines = _parse_table(p, ",", what="head path")
    ix = _columns(p, cols, CANONICAL_COLUMNS[:3], ("roll_deg",))
    _check_finite(p, cols, data, lines)
    t = data[:, ix["time_s"]]
    _check_increasing(p, t, lines)
    y, pi = data[:, ix["yaw_deg"]], data[:, ix["pitch_deg"]]
    r = data[:, ix["roll_deg"]] if "roll_deg" in ix else np.zeros_like(t)
    _check_pitch(p, pi, lines)
    _warn_if_milliseconds(p, t)
    _warn_if_radians(p, y, pi, r)
    return HeadPath.from_angles_deg(t, y, pi, r, source=str(p))


def _read_quat(p: Path) -> HeadPath:
    """Generic quaternion CSV ``time_s,qw,qx,qy,qz`` (any column order, matched by name).

    The quaternion is head->world in *our* frames (world and head: +x right, +y up,
    +z forward; Hamilton product, scalar ``qw``); q and -q are the same pose. It is
    ``head_rotation(yaw, pitch, roll).as_quat()`` reordered to w, x, y, z. Non-unit
    quaternions are normalised; zero-length ones are an error.
    """
    cols, data, lines = _parse_table(p, ",", what="head path")
    ix = _columns(p, cols, QUAT_COLUMNS)
    _check_finite(p, cols, data, lines)
    t = data[:, ix["time_s"]]
    _check_increasing(p, t, lines)
    _warn_if_milliseconds(p, t)
    q = data[:, [ix["qx"], ix["qy"], ix["qz"], ix["qw"]]]
    return HeadPath(t, _quats_to_rotation(p, q, lines), str(p))


def _read_keyframes_json(p: Path) -> HeadPath:
    """JSON keyframes: a list of ``{"time_s", "yaw_deg", "pitch_deg", "roll_deg"?}`` objects
    (or ``{"keyframes": [...]}``), degrees."""
    try:
        obj = json.loads(p.read_text(encoding="utf-8-sig"))
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise InputError(f"{p}: not valid JSON ({e})") from None
    except RecursionError:
        raise InputError(f"{p}: JSON nested too deeply; expected a list of keyframes") from None
    if isinstance(obj, dict):
        obj = obj.get("keyframes")
    if not isinstance(obj, list) or not obj:
        raise InputError(
            f"{p}: expected a non-empty JSON list of keyframes {{time_s, yaw_deg, pitch_deg, roll_deg}}"
        )
    rows = []
    for k, kf in enumerate(obj):
        if not isinstance(kf, dict):
            raise InputError(
                f"{p}: keyframe {k} is not an object with time_s, yaw_deg, pitch_deg[, roll_deg]"
            )
        unknown = sorted(set(kf) - set(CANONICAL_COLUMNS))
        missing = [c for c in CANONICAL_COLUMNS[:3] if c not in kf]
        if unknown or missing:
            what = (
                f"unknown key {_value(unknown[0])}{_hint(unknown[0], list(CANONICAL_COLUMNS))}"
                if unknown
                else f"no {missing[0]}"
            )
            raise InputError(
                f"{p}: keyframe {k}: {what}; expected {', '.join(CANONICAL_COLUMNS)} (roll_deg optional)"
            )
        try:
            rows.append(
                [float(kf[c]) for c in CANONICAL_COLUMNS[:3]] + [float(kf.get("roll_deg", 0.0))]
            )
        except (TypeError, ValueError):
            raise InputError(f"{p}: keyframe {k} has a non-numeric value") from None
    data = np.array(rows)
    lines = list(range(len(rows)))  # keyframe numbers, 0-based as in the messages above
    _check_finite(p, list(CANONICAL_COLUMNS), data, lines, "keyframe")
    _check_increasing(p, data[:, 0], lines, "keyframe")
    _check_pitch(p, data[:, 2], lines, "keyframe")
    _warn_if_radians(p, data[:, 1], data[:, 2], data[:, 3])
    return HeadPath.from_angles_deg(data[:, 0], data[:, 1], data[:, 2], data[:, 3], source=str(p))


#: The formats this module reads (the registry of ``simulator.traces.readers``).
TRACE_FORMATS = (
    TraceFormat("quat", lambda p, **_: _read_quat(p),
                lambda s: s.has("time_s", "qw", "qx", "qy", "qz"), rank=40),
    TraceFormat("canonical", lambda p, **_: _read_canonical(p), lambda s: s.has("time_s"),
                rank=45),
    TraceFormat("keyframes-json", lambda p, **_: _read_keyframes_json(p),
                lambda s: s.is_json, rank=11),
)  # fmt: skip
