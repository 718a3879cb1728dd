"""Head paths: times plus head orientations, scripted (synth) or recorded (real datasets).

Conventions (SPEC.md, :mod:`simulator.geometry`)
------------------------------------------------
World frame +x right, +y up, +z forward (the centre of the equirect frame). Head
orientation = yaw (+ turns right, toward +lon), pitch (+ looks up), roll (+ right ear
down), in **degrees** at every boundary, applied yaw, then pitch, then roll (intrinsic):
``geometry.head_rotation(yaw, pitch, roll)`` is the head->world rotation. Times are
seconds from the video start.

A :class:`HeadPath` holds ``times_s`` (N,) strictly increasing and a stacked
``scipy.spatial.transform.Rotation`` (N poses, head->world). Sampling at any time uses
``Slerp`` (shortest arc, so yaw wrap-around at +-180 deg and q == -q sign flips need no
special care; irregular sampling and gaps are interpolated along the great arc between
the poses either side).

Readers (:func:`load_headpath`, format names in :data:`FORMATS`; ``auto`` detects them
from the content) and the mapping of each dataset's axes to ours are documented in
``docs/headpath.md`` and beside each reader below.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation, Slerp

from simulator.errors import InputError
from simulator.fileio import atomic_output, check_input_file
from simulator.geometry import head_angles_deg, head_rotation

__all__ = [
    "FORMATS",
    "MAX_SAMPLES",
    "SYNTH_KINDS",
    "CoarseSamplingWarning",
    "HeadPath",
    "RadiansWarning",
    "load_all_users",
    "load_headpath",
    "plot_headpath",
    "save_headpath_csv",
    "synth",
]

#: Formats :func:`load_headpath` reads (``auto`` detects one of these from the content).
FORMATS: tuple[str, ...] = (
    "canonical",
    "quat",
    "keyframes-json",
    "corbillon",
    "corbillon-euler",
    "salient360-dyn",
    "salient360-static",
    "avtrack360",
    "360vidstr",
)
SYNTH_KINDS: tuple[str, ...] = ("static", "sweep", "sine", "look-around", "keyframes")
CANONICAL_COLUMNS: tuple[str, ...] = ("time_s", "yaw_deg", "pitch_deg", "roll_deg")
QUAT_COLUMNS: tuple[str, ...] = ("time_s", "qw", "qx", "qy", "qz")

#: Time tolerance (s) when checking that a path covers a video.
_TIME_TOL = 1e-6
#: Most samples :func:`synth` makes (seconds x rate + 1); beyond, InputError.
MAX_SAMPLES = 10_000_000
#: A loaded path whose consecutive poses differ by more than this (deg) gives a
#: :class:`CoarseSamplingWarning`.
COARSE_STEP_DEG = 90.0


class RadiansWarning(UserWarning):
    """Angles in a file that should hold degrees all lie within +-2*pi: radians?"""


class CoarseSamplingWarning(UserWarning):
    """Consecutive poses differ by more than 90 deg: Slerp takes the shortest arc between
    them, which may not be the way the head turned."""


# ------------------------------------------------------------------------------ HeadPath
@dataclass(frozen=True)
class HeadPath:
    """Head orientations over time.

    Parameters
    ----------
    times_s : ndarray, shape (N,), float64
        Seconds from the video start, finite and strictly increasing (N >= 1).
    rotations : scipy.spatial.transform.Rotation, N rotations
        Head->world (``geometry.head_rotation``; world +x right, +y up, +z forward).
    source : str
        Where the path came from (a file name or ``synth:KIND``), for messages.
    """

    times_s: NDArray[np.float64]
    rotations: Rotation
    source: str = ""

    def __post_init__(self) -> None:
        src = self.source or "head path"
        t = np.asarray(self.times_s, dtype=np.float64)
        if t.ndim != 1 or t.size < 1:
            raise InputError(f"{src}: no samples (times must be a 1-D array of at least one time)")
        if not np.all(np.isfinite(t)):
            i = int(np.flatnonzero(~np.isfinite(t))[0])
            raise InputError(f"{src}: time of sample {i} is {t[i]}; expected finite seconds")
        d = np.diff(t)
        if np.any(d <= 0):
            i = int(np.flatnonzero(d <= 0)[0])
            raise InputError(
                f"{src}: time is not strictly increasing at sample {i + 1} "
                f"({t[i + 1]:.6g} s after {t[i]:.6g} s)"
            )
        if not isinstance(self.rotations, Rotation):
            raise InputError(f"{src}: rotations must be a scipy Rotation")
        n_rot = 1 if self.rotations.single else len(self.rotations)
        if n_rot != t.size:
            raise InputError(f"{src}: {t.size} times but {n_rot} rotations")
        rot = self.rotations
        if rot.single:
            rot = Rotation.from_quat(rot.as_quat()[None, :])
        t.setflags(write=False)
        object.__setattr__(self, "times_s", t)
        object.__setattr__(self, "rotations", rot)

    # -- construction
    @classmethod
    def from_angles_deg(
        cls, times_s, yaw_deg, pitch_deg, roll_deg=0.0, source: str = ""
    ) -> HeadPath:
        """Build from yaw/pitch/roll in degrees (arrays like ``times_s`` or scalars)."""
        t = np.asarray(times_s, dtype=np.float64)
        y, p, r = np.broadcast_arrays(
            np.asarray(yaw_deg, float), np.asarray(pitch_deg, float), np.asarray(roll_deg, float)
        )
        y, p, r = (np.broadcast_to(a, t.shape) for a in (y, p, r))
        bad = ~(np.isfinite(y) & np.isfinite(p) & np.isfinite(r))
        if np.any(bad):
            i = int(np.flatnonzero(bad)[0])
            raise InputError(f"{source or 'head path'}: angle of sample {i} is not finite")
        return cls(t, head_rotation(y, p, r), source)

    # -- properties
    @property
    def n(self) -> int:
        return int(self.times_s.size)

    @property
    def start_s(self) -> float:
        return float(self.times_s[0])

    @property
    def end_s(self) -> float:
        return float(self.times_s[-1])

    def angles_deg(self) -> tuple[NDArray, NDArray, NDArray]:
        """``(yaw, pitch, roll)`` of every sample, degrees, each shape (N,).

        yaw in (-180, 180], pitch in [-90, 90], roll in (-180, 180].
        """
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # gimbal lock at pitch +-90
            return head_angles_deg(self.rotations)

    # -- sampling
    def sample(self, times_s, *, hold: bool = False) -> Rotation:
        """Orientations at ``times_s`` (seconds), Slerp between recorded poses.

        Times before the first or after the last sample raise :class:`InputError`
        unless ``hold=True``, which holds the first/last pose there.
        """
        t = np.atleast_1d(np.asarray(times_s, dtype=np.float64))
        if not np.all(np.isfinite(t)):
            raise InputError(f"{self.source or 'head path'}: sample times must be finite")
        lo, hi = self.start_s, self.end_s
        outside = (t < lo - _TIME_TOL) | (t > hi + _TIME_TOL)
        if np.any(outside) and not hold:
            bad = float(t[outside][0])
            raise InputError(
                f"head path {self.source or ''} covers {lo:.3f}..{hi:.3f} s; asked for "
                f"{bad:.3f} s (use --hold-last to hold the first/last pose)"
            )
        tc = np.clip(t, lo, hi)
        if self.n == 1:
            return Rotation.from_quat(np.repeat(self.rotations.as_quat(), t.size, axis=0))
        return Slerp(self.times_s, self.rotations)(tc)

    def sample_angles_deg(self, times_s, hold: bool = False) -> tuple[NDArray, NDArray, NDArray]:
        """``(yaw, pitch, roll)`` in degrees at ``times_s`` (see :meth:`sample`)."""
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)
            return head_angles_deg(self.sample(times_s, hold=hold))

    def check_covers(
        self, duration_s: float, *, hold: bool = False, video: str = "", start_s: float = 0.0
    ) -> None:
        """Raise InputError unless the path covers ``[start_s, duration_s]`` seconds.

        ``start_s`` > 0 for a part of a video (a grid made with ``--start``). With
        ``hold=True`` nothing is checked (the first/last pose are held).
        """
        if hold:
            return
        src = self.source or "(unnamed)"
        vid = f"video {video} " if video else "the video "
        if self.end_s < duration_s - _TIME_TOL:
            raise InputError(
                f"head path {src} ends at {self.end_s:.3f} s; {vid}lasts {duration_s:.3f} s "
                "(use --hold-last to hold the last pose)"
            )
        if self.start_s > start_s + _TIME_TOL:
            where = (
                f"the start of {vid.strip()}"
                if start_s <= 0
                else f"{start_s:.3f} s of {vid.strip()}"
            )
            raise InputError(
                f"head path {src} starts at {self.start_s:.3f} s, after {where} "
                "(use --hold-last to hold the first and last poses)"
            )

    def resample(self, times_s, *, hold: bool = False) -> HeadPath:
        """A new path sampled at ``times_s`` (Slerp)."""
        t = np.asarray(times_s, dtype=np.float64)
        return HeadPath(t, self.sample(t, hold=hold), self.source)

    def angular_speed_dps(self) -> NDArray[np.float64]:
        """Angle between consecutive poses over their time step, deg/s, shape (N-1,)."""
        if self.n < 2:
            return np.zeros(0)
        r = self.rotations
        delta = r[:-1].inv() * r[1:]
        return np.degrees(delta.magnitude()) / np.diff(self.times_s)


# ------------------------------------------------------------------------------ writing
def save_headpath_csv(path: str | os.PathLike, hp: HeadPath) -> None:
    """Write the canonical CSV ``time_s,yaw_deg,pitch_deg,roll_deg`` atomically."""
    y, p, r = (np.round(a, 9) + 0.0 for a in hp.angles_deg())  # no 1e-16 noise, no -0
    buf = io.StringIO()
    buf.write(",".join(CANONICAL_COLUMNS) + "\n")
    for row in zip(hp.times_s, y, p, r):
        buf.write(",".join(f"{v:.10g}" for v in row) + "\n")
    with atomic_output(path) as tmp:
        Path(tmp).write_text(buf.getvalue())


# ------------------------------------------------------------------------------ reading
def _first_line(p: Path) -> str:
    with open(p, encoding="utf-8", errors="replace") as fh:
        for line in fh:
            if line.strip():
                return line.strip()
    raise InputError(f"{p}: head path file is empty")


def detect_format(path: str | os.PathLike) -> str:
    """Guess the format (one of :data:`FORMATS`) from the file's content."""
    p = check_input_file(path, "head path")
    head = _first_line(p)
    low = head.lower()
    if head.startswith(("{", "[")):
        with open(p, encoding="utf-8", errors="replace") as fh:
            text = fh.read(1 << 16)
        if "pitch_yaw_roll_data_hmd" in text:
            return "avtrack360"
        return "keyframes-json"
    toks = set(low.replace(",", " ").split())
    if {"timestamp", "viewpoint", "w", "x", "y", "z"} <= toks:
        return "corbillon"
    if {"timestamp", "viewpoint", "yaw", "pitch", "roll"} <= toks:
        return "corbillon-euler"
    if {"cam_pitch", "cam_yaw", "cam_roll"} <= toks:
        return "salient360-dyn"
    if "camerarotation.x" in toks and "camerarotation.w" in toks:
        return "salient360-static"
    if "time_s" in toks and {"qw", "qx", "qy", "qz"} <= toks:
        return "quat"
    if "time_s" in toks:
        return "canonical"
    try:
        [float(v) for v in head.split()]
        return "360vidstr"
    except ValueError:
        pass
    raise InputError(
        f"{p}: cannot tell the head path format from its first line {head[:80]!r}; expected a "
        f"CSV with header {','.join(CANONICAL_COLUMNS)} (or pass --format, one of {', '.join(FORMATS)})"
    )


def load_headpath(
    path: str | os.PathLike,
    format: str = "auto",
    *,
    video: str | None = None,
    user: int | None = None,
) -> HeadPath:
    """Read a head path file.

    Parameters
    ----------
    path : file name
    format : ``auto`` or one of :data:`FORMATS`
    video : str, AVTrack360 only: which video's trace (``"6.mp4"`` or ``"6"``)
    user : int, 360VidStr only: which user (1-based, as the dataset's readMe counts)

    Raises
    ------
    InputError
        One line naming the file and the problem (empty, unknown columns, NaN, time not
        increasing, zero-length quaternion, ...). Angles that look like radians where
        degrees are expected give a :class:`RadiansWarning`.
    """
    p = check_input_file(path, "head path")
    fmt = detect_format(p) if format == "auto" else format
    if fmt not in FORMATS:
        raise InputError(
            f"{p}: unknown head path format {format!r}; expected auto or one of {', '.join(FORMATS)}"
        )
    if fmt == "avtrack360":
        hp = _read_avtrack360(p, video)
    elif fmt == "360vidstr":
        hp = _read_360vidstr(p, user)
    else:
        hp = _READERS[fmt](p)
    _warn_if_coarse(hp)
    return hp


def _warn_if_coarse(hp: HeadPath) -> None:
    """CoarseSamplingWarning when consecutive poses differ by more than 90 deg."""
    if hp.n < 2:
        return
    r = hp.rotations
    step = np.degrees((r[:-1].inv() * r[1:]).magnitude())
    big = np.flatnonzero(step > COARSE_STEP_DEG)
    if big.size:
        k = int(big[0])
        t = hp.times_s
        more = f" ({big.size} such steps)" if big.size > 1 else ""
        warnings.warn(
            f"{hp.source or 'head path'}: poses at {t[k]:.6g} s and {t[k + 1]:.6g} s differ by "
            f"{step[k]:.0f} deg{more}: sampling too coarse; interpolation takes the shortest arc",
            CoarseSamplingWarning,
            stacklevel=3,
        )


def _parse_table(
    p: Path, sep: str | None, *, what: str
) -> tuple[list[str], NDArray[np.float64], list[int]]:
    """Header (stripped names) and float rows of a delimited text file.

    Returns ``(columns, data (N, C), line_numbers)``; InputError on ragged or
    non-numeric rows (names the line) and on a file with a header only.
    """
    with open(p, encoding="utf-8", errors="replace") as fh:
        lines = fh.read().splitlines()
    rows = [
        (i + 1, ln) for i, ln in enumerate(lines) if ln.strip() and not ln.lstrip().startswith("#")
    ]
    if not rows:
        raise InputError(f"{p}: {what} file is empty")
    split = (lambda s: next(csv.reader([s]))) if sep == "," else (lambda s: s.split())
    cols = [c.strip() for c in split(rows[0][1])]
    if len(rows) < 2:
        raise InputError(f"{p}: {what} file has a header but no data rows")
    data = np.empty((len(rows) - 1, len(cols)))
    for k, (ln, text) in enumerate(rows[1:]):
        vals = split(text)
        if len(vals) != len(cols):
            raise InputError(f"{p}: line {ln} has {len(vals)} fields; the header has {len(cols)}")
        try:
            data[k] = [float(v) for v in vals]
        except ValueError:
            raise InputError(f"{p}: line {ln}: non-numeric value in {text[:60]!r}") from None
    return cols, data, [ln for ln, _ in rows[1:]]


def _check_finite(
    p: Path, cols: list[str], data: NDArray, lines: list[int], what: str = "line"
) -> None:
    """InputError naming ``{what} {lines[k]}`` (file line, or 1-based sample number)."""
    bad = ~np.isfinite(data)
    if np.any(bad):
        k, c = np.argwhere(bad)[0]
        raise InputError(
            f"{p}: {what} {lines[k]}: {cols[c]} is {data[k, c]}; expected a finite number"
        )


def _check_increasing(p: Path, t: NDArray, lines: list[int], what: str = "line") -> None:
    """InputError naming ``{what} {lines[k]}``; ``lines`` labels the rows of ``t``."""
    d = np.diff(t)
    if np.any(d <= 0):
        k = int(np.flatnonzero(d <= 0)[0])
        raise InputError(
            f"{p}: time is not strictly increasing at {what} {lines[k + 1]} "
            f"({t[k + 1]:.6g} s after {t[k]:.6g} s)"
        )


def _warn_if_radians(p: Path, *angles: NDArray) -> None:
    a = np.concatenate([np.abs(np.ravel(x)) for x in angles])
    if a.size and a.max() <= 2 * math.pi + 1e-9 and a.max() > 0.05:
        warnings.warn(
            f"{p}: every angle lies within +-2*pi (max {a.max():.3f}): these look like RADIANS, "
            "but this format holds DEGREES; convert them (x 180/pi) if so",
            RadiansWarning,
            stacklevel=3,
        )


def _columns(
    p: Path, cols: list[str], need: tuple[str, ...], optional: tuple[str, ...] = ()
) -> dict[str, int]:
    missing = [c for c in need if c not in cols]
    unknown = [c for c in cols if c not in need and c not in optional]
    if missing or unknown:
        exp = ",".join(need + optional)
        raise InputError(
            f"{p}: columns {cols} do not match; expected {exp}"
            + (f" (missing {missing})" if missing else "")
            + (f" (unknown {unknown})" if unknown else "")
        )
    return {c: cols.index(c) for c in cols}


def _read_canonical(p: Path) -> HeadPath:
    """Canonical CSV ``time_s,yaw_deg,pitch_deg[,roll_deg]`` (degrees; roll 0 if absent)."""
    cols, data, lines = _parse_table(p, ",", what="head path")
    ix = _columns(p, cols, CANONICAL_COLUMNS[:3], ("roll_deg",))
    _check_finite(p, cols, data, lines)
    t = data[:, ix["time_s"]]
    _check_increasing(p, t, lines)
    y, pi = data[:, ix["yaw_deg"]], data[:, ix["pitch_deg"]]
    r = data[:, ix["roll_deg"]] if "roll_deg" in ix else np.zeros_like(t)
    _warn_if_radians(p, y, pi, r)
    return HeadPath.from_angles_deg(t, y, pi, r, source=str(p))


def _quats_to_rotation(p: Path, q_xyzw: NDArray, lines: list[int]) -> Rotation:
    n = np.linalg.norm(q_xyzw, axis=1)
    bad = n < 1e-9
    if np.any(bad):
        k = int(np.flatnonzero(bad)[0])
        raise InputError(
            f"{p}: line {lines[k]}: quaternion has zero length; expected a unit quaternion"
        )
    return Rotation.from_quat(q_xyzw / n[:, None])


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
    q = data[:, [ix["qx"], ix["qy"], ix["qz"], ix["qw"]]]
    return HeadPath(t, _quats_to_rotation(p, q, lines), str(p))


def _read_keyframes_json(p: Path) -> HeadPath:
    """JSON keyframes: a list of ``{"time_s", "yaw_deg", "pitch_deg", "roll_deg"?}`` objects
    (or ``{"keyframes": [...]}``), degrees."""
    try:
        obj = json.loads(p.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise InputError(f"{p}: not valid JSON ({e})") from None
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
            raise InputError(
                f"{p}: keyframe {k} has keys {sorted(kf)}; expected {', '.join(CANONICAL_COLUMNS)} (roll_deg optional)"
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
    _warn_if_radians(p, data[:, 1], data[:, 2], data[:, 3])
    return HeadPath.from_angles_deg(data[:, 0], data[:, 1], data[:, 2], data[:, 3], source=str(p))


# Corbillon frame -> ours: their (x forward, y right, z up) -> our (z forward, x right, y up).
# A cyclic permutation (det +1): ours = _C2O @ theirs, for world and head vectors alike.
_C2O = Rotation.from_matrix(np.array([[0.0, 1, 0], [0, 0, 1], [1, 0, 0]]))
# Corbillon euler file: R(q) = P Ry(yaw) Rx(pitch) Rz(roll) P^T (SOURCES.md, exact). P is
# improper (det -1); conjugating by -P (proper) is the same map.
_CORB_P = Rotation.from_matrix(-np.array([[0.0, 1, 0], [0, 0, 1], [-1, 0, 0]]))


def _dedupe_times(t: NDArray) -> NDArray[np.bool_]:
    """Mask keeping the first row of each run of equal times."""
    keep = np.ones(t.size, bool)
    keep[1:] = np.diff(t) != 0
    return keep


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
            f"{p}: Salient360 raw video file lacks columns {missing}; found {cols[:12]}..."
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
            raise InputError(f"{p}: line {k + 2}: non-numeric head pose in {ln[:60]!r}") from None
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


def _read_salient360_static(p: Path) -> HeadPath:
    """Salient360! raw image recording (``rawDataStatic*.csv``): ``OcutimeStamp`` (us),
    ``cameraRotation.{x,y,z,w}`` = Unity quaternion, scalar last, head->world with Unity's
    axes = ours (x right, y up, z forward): used as is. Time from the first row."""
    cols, data, lines = _parse_salient_static(p)
    need = (
        "OcutimeStamp",
        "cameraRotation.x",
        "cameraRotation.y",
        "cameraRotation.z",
        "cameraRotation.w",
    )
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
    need = (
        "OcutimeStamp",
        "cameraRotation.x",
        "cameraRotation.y",
        "cameraRotation.z",
        "cameraRotation.w",
    )
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


def _read_avtrack360(p: Path, video: str | None) -> HeadPath:
    """AVTrack360 ``Head_rotation/<subject>.json``: one entry per video, integer degrees,
    ``sec`` = playback time. Their pitch is + down, yaw + right (yaw 0 = start view),
    roll + right ear down: ours = (yaw, -pitch, roll), applied yaw, pitch, roll."""
    try:
        obj = json.loads(p.read_text(encoding="utf-8"))
        entries = obj["data"]
        names = [str(e["filename"]) for e in entries]
    except (json.JSONDecodeError, UnicodeDecodeError, KeyError, TypeError) as e:
        raise InputError(
            f"{p}: not an AVTrack360 head rotation file ({type(e).__name__}: {e})"
        ) from None
    if video is None:
        if len(names) == 1:
            video = names[0]
        else:
            raise InputError(
                f"{p}: holds {len(names)} videos; choose one with --video (one of {', '.join(names)})"
            )
    want = video if video.endswith(".mp4") else f"{video}.mp4"
    if want not in names:
        raise InputError(f"{p}: no video {video!r}; available: {', '.join(names)}")
    try:
        samples = entries[names.index(want)]["pitch_yaw_roll_data_hmd"]
    except (KeyError, TypeError):
        raise InputError(
            f"{p}: video {want}: entry has no pitch_yaw_roll_data_hmd samples; "
            "not an AVTrack360 head rotation file?"
        ) from None
    try:
        data = np.array(
            [
                [float(s["sec"]), float(s["yaw"]), float(s["pitch"]), float(s["roll"])]
                for s in samples
            ]
        )
    except (KeyError, TypeError, ValueError):
        raise InputError(f"{p}: video {want}: samples need numeric sec, yaw, pitch, roll") from None
    if data.size == 0:
        raise InputError(f"{p}: video {want} has no samples")
    # Errors name the 1-based sample of the video's entry (JSON has no useful line numbers).
    src = f"{p}: video {want}"
    labels = np.arange(1, len(data) + 1)
    _check_finite(src, ["sec", "yaw", "pitch", "roll"], data, labels, "sample")
    keep = _dedupe_times(data[:, 0])
    data, labels = data[keep], labels[keep]
    _check_increasing(src, data[:, 0], labels, "sample")
    return HeadPath.from_angles_deg(
        data[:, 0], data[:, 1], -data[:, 2], data[:, 3], source=f"{p}:{want}"
    )


def _read_360vidstr(p: Path, user: int | None) -> HeadPath:
    """360VidStr aggregated ``<video>.txt``: line 1 times (s, 10 Hz), then per user a line of
    pitch and a line of yaw, radians; no roll. Signs/origin undocumented (taken as ours:
    yaw + right, pitch + up). A user's lines may be shorter than the time line: the path
    ends at that user's last sample."""
    rows = _parse_360vidstr(p)
    n_users = (len(rows) - 1) // 2
    if user is None:
        if n_users == 1:
            user = 1
        else:
            raise InputError(f"{p}: holds {n_users} users; choose one with --user 1..{n_users}")
    if not 1 <= user <= n_users:
        raise InputError(f"{p}: no user {user}; choose --user 1..{n_users}")
    return _360vidstr_user(p, rows, user)


def _parse_360vidstr(p: Path) -> list[NDArray]:
    """The number rows of a 360VidStr aggregated file (2n+1 of them), read once."""
    with open(p, encoding="utf-8", errors="replace") as fh:
        lines = [ln for ln in fh.read().splitlines() if ln.strip()]
    try:
        rows = [np.array(ln.split(), dtype=float) for ln in lines]
    except ValueError:
        raise InputError(f"{p}: not a 360VidStr aggregated file (non-numeric values)") from None
    if len(rows) < 3 or len(rows) % 2 == 0:
        raise InputError(
            f"{p}: a 360VidStr file has 2n+1 lines (times, then pitch and yaw per user); found {len(rows)}"
        )
    return rows


def _360vidstr_user(p: Path, rows: list[NDArray], user: int) -> HeadPath:
    """User ``user`` (1-based) of the parsed rows of a 360VidStr file."""
    pitch, yaw = rows[2 * user - 1], rows[2 * user]
    n = min(len(pitch), len(yaw), len(rows[0]))
    if n < 1:
        raise InputError(f"{p}: user {user} has no samples")
    t = rows[0][:n]
    data = np.stack([t, yaw[:n], pitch[:n]], axis=1)
    labels = list(range(1, n + 1))  # 1-based sample (column) numbers
    _check_finite(p, ["time", "yaw", "pitch"], data, labels, "sample")
    _check_increasing(p, t, labels, "sample")
    return HeadPath.from_angles_deg(
        t, np.degrees(yaw[:n]), np.degrees(pitch[:n]), 0.0, source=f"{p}:user{user}"
    )


def load_all_users(path: str | os.PathLike, format: str = "auto") -> dict[int, HeadPath]:
    """Every user of a head path file, read once: ``{user (1-based): HeadPath}``.

    360VidStr aggregated files hold many users (one pair of lines each); any other format
    holds one trace and gives ``{1: path}`` (read as :func:`load_headpath` reads it). A
    user whose samples are bad raises InputError naming the file and the user.
    """
    p = check_input_file(path, "head path")
    fmt = detect_format(p) if format == "auto" else format
    if fmt != "360vidstr":
        return {1: load_headpath(p, fmt)}
    rows = _parse_360vidstr(p)
    out = {u: _360vidstr_user(p, rows, u) for u in range(1, (len(rows) - 1) // 2 + 1)}
    for hp in out.values():
        _warn_if_coarse(hp)
    return out


_READERS = {
    "canonical": _read_canonical,
    "quat": _read_quat,
    "keyframes-json": _read_keyframes_json,
    "corbillon": _read_corbillon,
    "corbillon-euler": _read_corbillon_euler,
    "salient360-dyn": _read_salient360_dyn,
    "salient360-static": _read_salient360_static,
}


# ------------------------------------------------------------------------------ synth
def _smoothstep5(x: NDArray) -> NDArray:
    """Minimum-jerk profile on [0, 1]: 10x^3 - 15x^4 + 6x^5."""
    return x * x * x * (10 - 15 * x + 6 * x * x)


def synth(kind: str, seconds: float, rate_hz: float = 60.0, seed: int = 0, **params) -> HeadPath:
    """A scripted head path, sampled at ``rate_hz`` from 0 to ``seconds`` inclusive.

    Kinds (angles in degrees, rates in deg/s, frequencies in Hz):

    ``static``
        ``yaw``, ``pitch``, ``roll`` fixed (e.g. ``pitch=-70`` stares at the ground).
    ``sweep``
        yaw = ``yaw`` + ``yaw_rate`` * t (default 30 deg/s), fixed ``pitch`` and ``roll``.
    ``sine``
        yaw = ``yaw`` + ``yaw_amp`` sin(2 pi ``yaw_freq`` t), pitch = ``pitch`` +
        ``pitch_amp`` sin(2 pi ``pitch_freq`` t + pi/2); defaults 60 deg at 0.1 Hz,
        20 deg at 0.15 Hz.
    ``look-around``
        Seeded random exploration like real viewers: dwell periods with small drift,
        separated by minimum-jerk head turns (yaw steps mostly 20-90 deg, pitch drawn
        around the horizon, roll small). Tuned to the real traces' angular-speed
        percentiles and pitch distribution (bench/headtrace_stats.py, docs/headpath.md).
    ``keyframes``
        ``keyframes=PATH`` (JSON list or canonical CSV of time_s/yaw_deg/pitch_deg/roll_deg),
        Slerp between them; ``seconds`` may be 0 to end at the last keyframe; the last
        pose is held after it.

    At most :data:`MAX_SAMPLES` samples. Sampling so coarse that the head could turn
    180 deg or more between two samples (Slerp would then take the shortest arc, the
    wrong way) raises :class:`InputError` asking for a higher rate.
    """
    if kind not in SYNTH_KINDS:
        raise InputError(
            f"unknown head path kind {kind!r}; expected one of {', '.join(SYNTH_KINDS)}"
        )
    if not (rate_hz > 0 and math.isfinite(rate_hz)):
        raise InputError(f"rate must be > 0 Hz; got {rate_hz}")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise InputError(f"seed must be an integer >= 0; got {seed!r}")
    if kind == "keyframes":
        return _synth_keyframes(seconds, rate_hz, params)
    if not (seconds > 0 and math.isfinite(seconds)):
        raise InputError(f"seconds must be > 0; got {seconds}")
    t = _sample_times(seconds, rate_hz, f"synth {kind}")
    g = {k: float(v) for k, v in params.items() if v is not None}
    yaw0, pitch0, roll0 = g.get("yaw", 0.0), g.get("pitch", 0.0), g.get("roll", 0.0)
    src = f"synth:{kind}"
    if kind == "static":
        return HeadPath.from_angles_deg(t, yaw0, pitch0, roll0, source=src)
    if kind == "sweep":
        yaw_rate = g.get("yaw_rate", 30.0)
        step = abs(yaw_rate) / rate_hz
        _check_step(kind, step, rate_hz, f"--yaw-rate {yaw_rate:g} deg/s", abs(yaw_rate) / 180)
        yaw = yaw0 + yaw_rate * t
        return HeadPath.from_angles_deg(t, yaw, pitch0, roll0, source=src)
    if kind == "sine":
        ya, yf = g.get("yaw_amp", 60.0), g.get("yaw_freq", 0.1)
        pa, pf = g.get("pitch_amp", 20.0), g.get("pitch_freq", 0.15)
        # Largest change between two samples: speed x step, at most peak to peak (2 amp);
        # yaw and pitch together turn at most the sum (triangle inequality on rotations).
        speed = [2 * math.pi * abs(a * f) for a, f in ((ya, yf), (pa, pf))]  # peak deg/s
        step = sum(min(2 * abs(a), v / rate_hz) for a, v in zip((ya, pa), speed))
        _check_step(kind, step, rate_hz, "amplitude x frequency", sum(speed) / 180)
        yaw = yaw0 + ya * np.sin(2 * np.pi * yf * t)
        pitch = pitch0 + pa * np.sin(2 * np.pi * pf * t + np.pi / 2)
        if np.any(np.abs(pitch) > 90):
            raise InputError(
                f"sine: pitch + pitch_amp reaches {np.abs(pitch).max():.1f} deg; keep |pitch| <= 90"
            )
        return HeadPath.from_angles_deg(t, yaw, pitch, roll0, source=src)
    return _synth_look_around(t, np.random.default_rng(seed), yaw0, g, rate_hz)


def _sample_times(seconds: float, rate_hz: float, what: str) -> NDArray[np.float64]:
    """``arange(n) / rate_hz`` covering 0..seconds; InputError beyond :data:`MAX_SAMPLES`."""
    n_f = seconds * rate_hz  # inf for huge values: refused below, no OverflowError
    if not n_f < MAX_SAMPLES:
        raise InputError(
            f"{what}: --seconds {seconds:g} x --rate {rate_hz:g} Hz = {n_f:.3g} samples; "
            f"at most {MAX_SAMPLES:,} (lower --seconds or --rate)"
        )
    n = math.floor(n_f + 1e-9) + 1
    return np.arange(n) / rate_hz


def _check_step(kind: str, step_deg: float, rate_hz: float, cause: str, need_hz: float) -> None:
    """InputError when the head can turn 180 deg or more between two samples (``need_hz``
    = a rate above which it cannot, for the message)."""
    if step_deg >= 180.0 - 1e-9:
        raise InputError(
            f"synth {kind}: the head can turn {step_deg:.0f} deg between two samples at --rate "
            f"{rate_hz:g} Hz ({cause}) and interpolation takes the shortest arc, the wrong way: "
            f"raise --rate above {need_hz:.3g} Hz"
        )


#: look-around model parameters (tuned against the real traces, see docs/headpath.md).
_LOOK = {
    "dwell_mean_s": 1.1,  # mean dwell between head turns (exponential, + 0.3 s minimum)
    "turn_yaw_scale_deg": 35.0,  # |yaw step| ~ 5 deg + exponential with this scale
    "turn_peak_dps": 45.0,  # peak angular speed of a 30 deg turn (scales with sqrt of size)
    "pitch_sd_deg": 22.0,  # target pitch ~ N(-2, sd), clipped to +-75
    "drift_sd_dps": 7.0,  # slow drift (OU velocity, deg/s; pitch 0.6x and leaky)
    "roll_sd_deg": 3.0,  # slow roll sway amplitude
}


def _synth_look_around(
    t: NDArray, rng: np.random.Generator, yaw0: float, g: dict, rate_hz: float
) -> HeadPath:
    c = dict(_LOOK)
    c.update({k: v for k, v in g.items() if k in c})
    T = t[-1]
    # Key poses: alternate dwell and turn segments.
    kt, ky, kp = [0.0], [yaw0], [float(np.clip(rng.normal(-2.0, c["pitch_sd_deg"]), -75, 75))]
    now = 0.0
    while now < T:
        dwell = 0.3 + rng.exponential(c["dwell_mean_s"])
        now += dwell
        kt.append(now)
        ky.append(ky[-1])
        kp.append(kp[-1])
        dy = (5.0 + rng.exponential(c["turn_yaw_scale_deg"])) * rng.choice([-1.0, 1.0])
        tp = float(np.clip(rng.normal(-2.0, c["pitch_sd_deg"]), -75, 75))
        amp = math.hypot(dy, tp - kp[-1])
        # Minimum-jerk peak speed = 1.875 amp / duration; bigger turns are faster.
        peak = c["turn_peak_dps"] * math.sqrt(max(amp, 1.0) / 30.0) * rng.uniform(0.7, 1.3)
        dur = max(0.25, 1.875 * amp / peak)
        now += dur
        kt.append(now)
        ky.append(ky[-1] + dy)
        kp.append(tp)
    kt, ky, kp = np.array(kt), np.array(ky), np.array(kp)
    seg = np.clip(np.searchsorted(kt, t, side="right") - 1, 0, len(kt) - 2)
    x = (t - kt[seg]) / (kt[seg + 1] - kt[seg])
    s = _smoothstep5(np.clip(x, 0, 1))
    yaw = ky[seg] + (ky[seg + 1] - ky[seg]) * s
    pitch = kp[seg] + (kp[seg + 1] - kp[seg]) * s
    # Drift: integrated Ornstein-Uhlenbeck velocity (deg/s), correlation time 0.5 s.
    dt = np.diff(t, prepend=t[0])

    def drift(sd: float, leak_s: float) -> NDArray:
        # Smooth drift (deg): OU velocity (sd deg/s, correlation 0.5 s) integrated with a
        # leak back to 0 (time constant leak_s; inf = plain integration).
        a = np.exp(-dt / 0.5)
        e = rng.normal(0.0, 1.0, t.size)
        v = 0.0
        x = np.zeros_like(t)
        for i in range(1, t.size):
            v = a[i] * v + sd * math.sqrt(1 - a[i] ** 2) * e[i]
            x[i] = x[i - 1] + dt[i] * (v - x[i - 1] / leak_s)
        return x

    yaw = yaw + drift(c["drift_sd_dps"], math.inf)
    pitch = np.clip(pitch + drift(c["drift_sd_dps"] * 0.6, 2.0), -85, 85)
    roll = c["roll_sd_deg"] * np.sin(2 * np.pi * 0.05 * t + rng.uniform(0, 2 * np.pi))
    roll = roll + drift(1.0, 2.0)
    if t.size > 1:  # the scripted angles (not wrapped): the turn between two samples
        step = np.abs(np.diff(yaw)) + np.abs(np.diff(pitch)) + np.abs(np.diff(roll))
        big = float(step.max())
        _check_step("look-around", big, rate_hz, "a scripted head turn", rate_hz * big / 180)
    return HeadPath.from_angles_deg(t, yaw, pitch, roll, source="synth:look-around")


def _synth_keyframes(seconds: float, rate_hz: float, g: dict) -> HeadPath:
    path = g.get("keyframes")
    if not path:
        raise InputError(
            "keyframes: give the keyframe file (JSON or CSV of time_s,yaw_deg,pitch_deg,roll_deg)"
        )
    p = check_input_file(path, "keyframes")
    fmt = detect_format(p)
    if fmt not in ("keyframes-json", "canonical"):
        raise InputError(
            f"{p}: keyframes must be a JSON list or a CSV with header {','.join(CANONICAL_COLUMNS)}"
        )
    kf = load_headpath(p, fmt)
    end = float(seconds) if seconds and seconds > 0 else kf.end_s
    if not math.isfinite(end) or end <= 0:
        raise InputError(f"{p}: keyframes end at {kf.end_s} s; give --seconds > 0")
    t = _sample_times(end, rate_hz, "synth keyframes")
    return HeadPath(t, kf.sample(t, hold=True), f"synth:keyframes:{p}")


def plot_headpath(path: str | os.PathLike, hp: HeadPath, *, title: str = "") -> None:
    """Plot yaw, pitch and roll (degrees) over time into a PNG (atomic)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    y, p, r = hp.angles_deg()
    fig, axs = plt.subplots(3, 1, figsize=(9, 5.5), dpi=110, sharex=True)
    for ax, v, name in zip(
        axs, (y, p, r), ("yaw (deg, + right)", "pitch (deg, + up)", "roll (deg)")
    ):
        if name.startswith("yaw"):  # break the line at the +-180 wrap
            v = v.copy()
            v[1:][np.abs(np.diff(v)) > 180] = np.nan
        ax.plot(hp.times_s, v, lw=1.0)
        ax.set_ylabel(name, fontsize=8)
        ax.grid(alpha=0.3)
    axs[0].set_ylim(-180, 180)
    axs[1].set_ylim(-90, 90)
    axs[-1].set_xlabel("time (s)")
    axs[0].set_title(title or f"head path {hp.source}", fontsize=9)
    fig.tight_layout()
    with atomic_output(path) as tmp:
        fig.savefig(tmp)
    plt.close(fig)
