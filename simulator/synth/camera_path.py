"""Camera trajectories: timed poses, their interpolation, the camera CSV and a z-up converter.

World frame (everywhere in vimsim): +x right, +y up, +z forward, metres. A pose's
orientation is yaw/pitch/roll in degrees (yaw + turns right, pitch + looks up, roll +
right ear down; applied yaw, then pitch, then roll, intrinsic, as ffmpeg v360:
:func:`simulator.sphere.geometry.head_rotation`), i.e. a rotation taking camera-frame vectors
(+x right, +y up, +z forward) to the world frame. Between poses the position follows a
linear or cubic (not-a-knot) interpolating spline
(:func:`scipy.interpolate.make_interp_spline`) and the orientation scipy's
:class:`~scipy.spatial.transform.Slerp`; velocities and angular velocities are the exact
derivatives of these interpolants (Slerp turns at a constant rate about a fixed axis
between two poses: camera-frame angular velocity ``rotvec(R_i^-1 R_i+1) / (t_i+1 - t_i)``).

Camera CSV: ``time_s,x_m,y_m,z_m,yaw_deg,pitch_deg,roll_deg`` (:func:`load_camera_csv`).
:func:`trajectory_from_zup` converts poses given in a z-up right-handed world (Blender's:
+x right, +y forward, +z up) to this frame.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
from numpy.typing import NDArray
from scipy.interpolate import make_interp_spline
from scipy.spatial.transform import Rotation, Slerp

from simulator.core.choices import CAMERA_INTERPS
from simulator.core.errors import InputError
from simulator.core.fileio import atomic_output, check_input_file, csv_row
from simulator.sphere.geometry import head_angles_deg, head_rotation

__all__ = [
    "CAMERA_COLUMNS",
    "INTERPS",
    "CameraTrajectory",
    "load_camera_csv",
    "save_camera_csv",
    "trajectory_from_zup",
]

CAMERA_COLUMNS: tuple[str, ...] = (
    "time_s",
    "x_m",
    "y_m",
    "z_m",
    "yaw_deg",
    "pitch_deg",
    "roll_deg",
)
Interp = Literal["linear", "cubic"]
INTERPS: tuple[str, ...] = CAMERA_INTERPS


@dataclass(frozen=True, eq=False)
class CameraTrajectory:
    """Timed camera poses, interpolated (positions: spline, orientations: Slerp).

    Parameters
    ----------
    times_s : ndarray, shape (N,), float64, seconds, finite and strictly increasing, N >= 2
    positions_m : ndarray, shape (N, 3), float64, world frame (+x right, +y up, +z forward)
    rotations : scipy Rotation of N poses, camera -> world (camera +x right, +y up,
        +z forward; :func:`simulator.sphere.geometry.head_rotation` of yaw/pitch/roll)
    interp : ``"linear"`` or ``"cubic"`` (positions; cubic = not-a-knot spline, quadratic
        for 3 poses, linear for 2)
    source : where the poses came from (a file name), for messages
    """

    times_s: NDArray[np.float64]
    positions_m: NDArray[np.float64]
    rotations: Rotation
    interp: str = "cubic"
    source: str = ""

    def __post_init__(self) -> None:
        src = self.source or "camera trajectory"
        t = np.array(self.times_s, dtype=np.float64)
        p = np.array(self.positions_m, dtype=np.float64)
        if t.ndim != 1 or t.size < 2:
            raise InputError(
                f"{src}: {t.size} pose(s); a trajectory needs at least 2 (one per CSV row)"
            )
        if p.shape != (t.size, 3):
            raise InputError(f"{src}: positions must have shape ({t.size}, 3); got {p.shape}")
        if not (isinstance(self.rotations, Rotation) and len(self.rotations) == t.size):
            raise InputError(f"{src}: need {t.size} rotations (a scipy Rotation)")
        bad = ~(np.isfinite(t) & np.all(np.isfinite(p), axis=1))
        if np.any(bad):
            i = int(np.flatnonzero(bad)[0])
            raise InputError(f"{src}: pose {i + 1} has a non-finite time or position")
        d = np.diff(t)
        if np.any(d <= 0):
            i = int(np.flatnonzero(d <= 0)[0])
            raise InputError(
                f"{src}: time is not strictly increasing at pose {i + 2} "
                f"({t[i + 1]:.6g} s after {t[i]:.6g} s)"
            )
        if self.interp not in INTERPS:
            raise InputError(
                f"unknown interpolation {self.interp!r}; expected one of {', '.join(INTERPS)}"
            )
        t.setflags(write=False)
        p.setflags(write=False)
        object.__setattr__(self, "times_s", t)
        object.__setattr__(self, "positions_m", p)
        k = 1 if self.interp == "linear" else min(3, t.size - 1)
        spline = make_interp_spline(t, p, k=k)
        object.__setattr__(self, "_spline", spline)
        object.__setattr__(self, "_dspline", spline.derivative())
        object.__setattr__(self, "_slerp", Slerp(t, self.rotations))
        # Camera-frame angular velocity of each Slerp segment, rad/s (constant on it).
        rel = self.rotations[:-1].inv() * self.rotations[1:]
        object.__setattr__(self, "_seg_omega", rel.as_rotvec() / d[:, None])

    @classmethod
    def from_poses_deg(
        cls, times_s, positions_m, yaw_deg, pitch_deg, roll_deg, *, interp="cubic", source=""
    ) -> CameraTrajectory:
        """Build from positions (metres) and yaw/pitch/roll (degrees), one row per pose."""
        y, p, r = (np.asarray(a, float) for a in (yaw_deg, pitch_deg, roll_deg))
        bad = ~(np.isfinite(y) & np.isfinite(p) & np.isfinite(r))
        if np.any(bad):
            i = int(np.flatnonzero(bad)[0])
            raise InputError(
                f"{source or 'camera trajectory'}: angle of pose {i + 1} is not finite"
            )
        return cls(times_s, positions_m, head_rotation(y, p, r), interp, source)

    @property
    def n(self) -> int:
        return int(self.times_s.size)

    @property
    def start_s(self) -> float:
        return float(self.times_s[0])

    @property
    def end_s(self) -> float:
        return float(self.times_s[-1])

    def _clip(self, t) -> NDArray[np.float64]:
        return np.clip(np.asarray(t, dtype=np.float64), self.start_s, self.end_s)

    def position(self, t) -> NDArray[np.float64]:
        """Position (metres, world) at trajectory time(s) ``t`` (seconds; held outside the
        span), shape ``(..., 3)``."""
        return self._spline(self._clip(t))

    def velocity(self, t) -> NDArray[np.float64]:
        """Velocity (m/s, world): the derivative of the position spline; 0 outside the span."""
        t = np.asarray(t, dtype=np.float64)
        v = self._dspline(self._clip(t))
        inside = (t >= self.start_s) & (t <= self.end_s)
        return np.where(inside[..., None], v, 0.0)

    def rotation(self, t) -> Rotation:
        """Orientation (camera -> world) at time(s) ``t``, Slerp (held outside the span)."""
        return self._slerp(self._clip(t))

    def omega_cam_rad(self, t) -> NDArray[np.float64]:
        """Camera-frame angular velocity (rad/s) at time(s) ``t``: constant on each Slerp
        segment (at a pose, the segment that starts there); 0 outside the span."""
        t = np.asarray(t, dtype=np.float64)
        i = np.clip(np.searchsorted(self.times_s, t, side="right") - 1, 0, self.n - 2)
        w = self._seg_omega[i]
        inside = (t >= self.start_s) & (t <= self.end_s)
        return np.where(inside[..., None], w, 0.0)

    def angles_deg(self) -> tuple[NDArray, NDArray, NDArray]:
        """``(yaw, pitch, roll)`` of the poses, degrees (yaw, roll in (-180, 180])."""
        return head_angles_deg(self.rotations)


def _parse_csv(p: Path) -> tuple[list[str], NDArray[np.float64], list[int]]:
    """Header and float rows of a comma-separated file (``#`` lines are comments)."""
    try:
        with open(p, encoding="utf-8", errors="replace", newline="") as fh:
            lines = fh.read().splitlines()
    except OSError as e:
        raise InputError(f"{p}: cannot read camera file ({e.strerror})") from None
    rows = [
        (i + 1, ln) for i, ln in enumerate(lines) if ln.strip() and not ln.lstrip().startswith("#")
    ]
    if not rows:
        raise InputError(f"{p}: camera file is empty; expected a header {','.join(CAMERA_COLUMNS)}")
    cols = [c.strip() for c in csv_row(rows[0][1], p)]
    missing = [c for c in CAMERA_COLUMNS if c not in cols]
    unknown = [c for c in cols if c not in CAMERA_COLUMNS]
    if missing or unknown or len(set(cols)) != len(cols):
        raise InputError(
            f"{p}: columns {cols} do not match; expected {','.join(CAMERA_COLUMNS)}"
            + (f" (missing {missing})" if missing else "")
            + (f" (unknown {unknown})" if unknown else "")
        )
    data = np.empty((len(rows) - 1, len(cols)))
    for k, (ln, text) in enumerate(rows[1:]):
        vals = csv_row(text, f"{p}: line {ln}")
        if len(vals) != len(cols):
            raise InputError(f"{p}: line {ln} has {len(vals)} fields; the header has {len(cols)}")
        try:
            data[k] = [float(v) for v in vals]
        except ValueError:
            raise InputError(f"{p}: line {ln}: non-numeric value in {text[:60]!r}") from None
    order = [cols.index(c) for c in CAMERA_COLUMNS]
    return list(CAMERA_COLUMNS), data[:, order], [ln for ln, _ in rows[1:]]


def load_camera_csv(path: str | os.PathLike, *, interp: str = "cubic") -> CameraTrajectory:
    """Read ``time_s,x_m,y_m,z_m,yaw_deg,pitch_deg,roll_deg`` (any column order; ``#``
    comments). InputError (one line naming the file) for missing or unknown columns,
    non-numeric or non-finite values, non-increasing time, fewer than 2 poses."""
    p = check_input_file(path, "camera")
    cols, data, lines = _parse_csv(p)
    if len(data) < 2:
        raise InputError(
            f"{p}: {len(data)} pose(s); a camera trajectory needs at least 2 rows of "
            f"{','.join(CAMERA_COLUMNS)}"
        )
    bad = ~np.isfinite(data)
    if np.any(bad):
        k, c = np.argwhere(bad)[0]
        raise InputError(
            f"{p}: line {lines[k]}: {cols[c]} is {data[k, c]}; expected a finite number"
        )
    d = np.diff(data[:, 0])
    if np.any(d <= 0):
        k = int(np.flatnonzero(d <= 0)[0])
        raise InputError(
            f"{p}: time is not strictly increasing at line {lines[k + 1]} "
            f"({data[k + 1, 0]:.6g} s after {data[k, 0]:.6g} s)"
        )
    return CameraTrajectory.from_poses_deg(
        data[:, 0], data[:, 1:4], data[:, 4], data[:, 5], data[:, 6], interp=interp, source=str(p)
    )


def save_camera_csv(path: str | os.PathLike, traj: CameraTrajectory) -> Path:
    """Write ``traj``'s poses as a camera CSV (atomic); returns the path."""
    y, pi, r = traj.angles_deg()
    rows = np.column_stack([traj.times_s, traj.positions_m, y, pi, r])
    out = Path(path)
    with atomic_output(out) as tmp, open(tmp, "w", newline="") as fh:
        fh.write(",".join(CAMERA_COLUMNS) + "\n")
        fh.writelines(",".join(f"{v:.9g}" for v in row) + "\n" for row in rows)
    return out


def trajectory_from_zup(
    times_s,
    location_m,
    rotation: Rotation,
    *,
    camera_looks: Literal["-z", "+y"] = "-z",
    interp: str = "cubic",
    source: str = "",
) -> CameraTrajectory:
    """Convert poses from a z-up right-handed world (Blender's: +x right, +y forward,
    +z up) to this project's frame (+x right, +y up, +z forward).

    Parameters
    ----------
    times_s : array_like, shape (N,), seconds
    location_m : array_like, shape (N, 3), positions in the z-up world, metres
    rotation : scipy Rotation of N poses, object -> z-up world (e.g. Blender's
        ``matrix_world.to_quaternion()``, or ``Rotation.from_euler("xyz",
        rotation_euler)`` for Blender's default XYZ Euler mode, radians)
    camera_looks : the object's local viewing axis: ``"-z"`` for a Blender camera (looks
        along local -z, local +y up, +x right), ``"+y"`` for an object whose local axes
        match the world's (+y forward, +z up)

    Positions map as ``(x, y, z)_ours = (x, z, y)_zup`` (``M``, a reflection: the two
    worlds differ in handedness); the camera -> world rotation is ``M R C`` with ``C`` the
    object's local axes in ours (``diag(1, 1, -1)`` for ``"-z"``, ``M`` for ``"+y"``).
    """
    m = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 1.0, 0.0]])
    if camera_looks == "-z":
        c = np.diag([1.0, 1.0, -1.0])
    elif camera_looks == "+y":
        c = m
    else:
        raise InputError(f"camera_looks must be '-z' or '+y'; got {camera_looks!r}")
    loc = np.asarray(location_m, dtype=np.float64)
    mats = m @ rotation.as_matrix().reshape(-1, 3, 3) @ c
    return CameraTrajectory(
        np.asarray(times_s, float), loc @ m.T, Rotation.from_matrix(mats), interp, source
    )
