"""Corbillon et al. (MMSys 2017) head traces: quaternion and Euler variants."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from simulator.traces.path import HeadPath
from simulator.traces.readers.common import (
    _check_finite,
    _check_increasing,
    _columns,
    _parse_table,
    _quats_to_rotation,
)
from simulator.traces.readers.formats import TraceFormat

# Corbillon frame -> ours: their (x forward, y right, z up) -> our (z forward, x right, y up).
# A cyclic permutation (det +1): ours = _C2O @ theirs, for world and head vectors alike.
_C2O = Rotation.from_matrix(np.array([[0.0, 1, 0], [0, 0, 1], [1, 0, 0]]))


# Corbillon euler file: R(q) = P Ry(yaw) Rx(pitch) Rz(roll) P^T (SOURCES.md, exact). P is
# improper (det -1); conjugating by -P (proper) is the same map.
_CORB_P = Rotation.from_matrix(-np.array([[0.0, 1, 0], [0, 0, 1], [-1, 0, 0]]))


def _read_corbillon(p: Path) -> HeadPath:
    """Corbillon MMSys'18 ``timestamp viewpoint w x y z`` (space separated, seconds).

    Their frames: world +x = equirect centre, +y = right (+lon), +z = up; head forward
    = first column of R(q). Ours = C R(q) C^T with C mapping (x, y, z) -> (z, x, y).
    The viewpoint column (camera position of the multi-viewpoint video) is ignored.
    """
    cols, data, lines = _parse_table(p, None, what="head path")
    ix = _columns(p, cols, ("timestamp", "viewpoint", "w", "x", "y", "z"))
    _check_finite(p, cols, data, lines)
    t = data[:, ix["timestamp"]]
    _check_increasing(p, t, lines)
    q = data[:, [ix["x"], ix["y"], ix["z"], ix["w"]]]
    rot = _C2O * _quats_to_rotation(p, q, lines) * _C2O.inv()
    return HeadPath(t, rot, str(p))


def _read_corbillon_euler(p: Path) -> HeadPath:
    """Corbillon MMSys'18 ``timestamp viewpoint yaw pitch roll`` (radians, Unity names that
    do not mean what they say): R = P Ry(yaw) Rx(pitch) Rz(roll) P^T in their frame, then
    the same frame change as the quaternion file. Prefer the quaternion file."""
    cols, data, lines = _parse_table(p, None, what="head path")
    ix = _columns(p, cols, ("timestamp", "viewpoint", "yaw", "pitch", "roll"))
    _check_finite(p, cols, data, lines)
    t = data[:, ix["timestamp"]]
    _check_increasing(p, t, lines)
    e = data[:, [ix["yaw"], ix["pitch"], ix["roll"]]]
    r_c = _CORB_P * Rotation.from_euler("YXZ", e) * _CORB_P.inv()
    return HeadPath(t, _C2O * r_c * _C2O.inv(), str(p))


#: The formats this module reads (the registry of ``simulator.traces.readers``).
TRACE_FORMATS = (
    TraceFormat("corbillon", lambda p, **_: _read_corbillon(p),
                lambda s: s.has("timestamp", "viewpoint", "w", "x", "y", "z"), rank=20),
    TraceFormat("corbillon-euler", lambda p, **_: _read_corbillon_euler(p),
                lambda s: s.has("timestamp", "viewpoint", "yaw", "pitch", "roll"), rank=20),
)  # fmt: skip
