"""Salient360! (ICME 2017 grand challenge) head traces: dynamic scanpaths and static fixations."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from simulator.core.errors import InputError
from simulator.sphere.geometry import head_rotation
from simulator.traces.path import HeadPath
from simulator.traces.readers.common import (
    _check_finite,
    _check_increasing,
    _dedupe_times,
    _hint,
    _is_float,
    _quats_to_rotation,
    _value,
)
from simulator.traces.readers.formats import TraceFormat


def _read_salient360_dyn(p: Path) -> HeadPath:
    """Salient360! raw video recording (``rawDataDyn*.csv``).

    Head pose = Unity ``transform.eulerAngles`` (degrees in [0, 360)): ``cam_pitch`` about
    +X (+ looks down), ``cam_yaw`` about +Y (+ turns right), ``cam_roll`` about +Z (+ left
    ear down), applied Z, X, Y (R = Ry Rx Rz). Unity's axes are ours (x right, y up,
    z forward), so R = head_rotation(cam_yaw, -cam_pitch, -cam_roll); then the video
    sphere's yaw ``sphere_yaw`` is removed: R_video = Ry(-sphere_yaw) R.
    Time = ``unityTS`` (ms) from the first row; rows repeating a ``unityTS`` (eye-tracker
    samples between head updates) are dropped. The data rows have one field fewer than
    the header (``binPor.y`` and ``Lval`` fused, e.g. ``666.5324True``): only the first
    11 columns are parsed, so that defect is harmless.
    """
    with open(p, encoding="utf-8", errors="replace") as fh:
        lines = [ln for ln in fh.read().splitlines() if ln.strip()]
    if not lines:
        raise InputError(f"{p}: head path file is empty")
    cols = [c.strip() for c in lines[0].split(",")]
    need = ("unityTS", "cam_pitch", "cam_yaw", "cam_roll", "sphere_yaw")
    missing = [c for c in need if c not in cols]
    if missing:
        raise InputError(
            f"{p}: Salient360 raw video file lacks columns {missing} ({len(cols)} columns "
            f"found{_hint(missing[0], cols)})"
        )
    if len(lines) < 2:
        raise InputError(f"{p}: head path file has a header but no data rows")
    idx = [cols.index(c) for c in need]
    m = max(idx) + 1
    data = np.empty((len(lines) - 1, len(need)))
    for k, ln in enumerate(lines[1:]):
        f = ln.split(",")
        if len(f) < m:
            raise InputError(f"{p}: line {k + 2} has {len(f)} fields; expected at least {m}")
        try:
            data[k] = [float(f[i]) for i in idx]
        except ValueError:
            j = next(j for j, i in enumerate(idx) if not _is_float(f[i]))
            raise InputError(
                f"{p}: line {k + 2}, column {need[j]}: non-numeric value {_value(f[idx[j]])}"
            ) from None
    line_no = list(range(2, len(lines) + 1))
    _check_finite(p, list(need), data, line_no)
    keep = _dedupe_times(data[:, 0])
    data = data[keep]
    line_no = [ln for ln, k in zip(line_no, keep) if k]
    t = (data[:, 0] - data[0, 0]) / 1000.0
    _check_increasing(p, t, line_no)
    r = head_rotation(data[:, 2], -data[:, 1], -data[:, 3])
    r = Rotation.from_euler("Y", -data[:, 4:5], degrees=True) * r
    return HeadPath(t, r, str(p))


#: The columns of a Salient360! raw image recording that are read: time (us), quaternion.
_STATIC_COLUMNS = (
    "OcutimeStamp",
    "cameraRotation.x",
    "cameraRotation.y",
    "cameraRotation.z",
    "cameraRotation.w",
)


def _read_salient360_static(p: Path) -> HeadPath:
    """Salient360! raw image recording (``rawDataStatic*.csv``): ``OcutimeStamp`` (us),
    ``cameraRotation.{x,y,z,w}`` = Unity quaternion, scalar last, head->world with Unity's
    axes = ours (x right, y up, z forward): used as is. Time from the first row."""
    cols, data, lines = _parse_salient_static(p)
    need = _STATIC_COLUMNS
    ix = {c: cols.index(c) for c in need}
    sub = data[:, [ix[c] for c in need]]
    _check_finite(p, list(need), sub, lines)
    keep = _dedupe_times(sub[:, 0])
    sub = sub[keep]
    lines = [ln for ln, k in zip(lines, keep) if k]
    t = (sub[:, 0] - sub[0, 0]) * 1e-6
    _check_increasing(p, t, lines)
    return HeadPath(t, _quats_to_rotation(p, sub[:, 1:5], lines), str(p))


def _parse_salient_static(p: Path):
    with open(p, encoding="utf-8", errors="replace") as fh:
        lines = [ln for ln in fh.read().splitlines() if ln.strip()]
    if not lines:
        raise InputError(f"{p}: head path file is empty")
    cols = [c.strip() for c in lines[0].split(",")]
    need = _STATIC_COLUMNS
    missing = [c for c in need if c not in cols]
    if missing:
        raise InputError(f"{p}: Salient360 raw image file lacks columns {missing}")
    if len(lines) < 2:
        raise InputError(f"{p}: head path file has a header but no data rows")
    idx = [cols.index(c) for c in need]
    data = np.full((len(lines) - 1, len(cols)), np.nan)
    for k, ln in enumerate(lines[1:]):
        f = ln.split(",")
        try:
            for i in idx:
                data[k, i] = float(f[i])
        except (ValueError, IndexError):
            raise InputError(f"{p}: line {k + 2}: missing or non-numeric head pose") from None
    return cols, data, list(range(2, len(lines) + 1))


#: The formats this module reads (the registry of ``simulator.traces.readers``).
TRACE_FORMATS = (
    TraceFormat("salient360-dyn", lambda p, **_: _read_salient360_dyn(p),
                lambda s: s.has("cam_pitch", "cam_yaw", "cam_roll"), rank=30),
    TraceFormat("salient360-static", lambda p, **_: _read_salient360_static(p),
                lambda s: s.has("camerarotation.x", "camerarotation.w"), rank=30),
)  # fmt: skip
