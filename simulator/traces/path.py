"""Head paths: times plus head orientations, their interpolation, and the scripted paths.

Conventions (SPEC.md, :mod:`simulator.sphere.geometry`)
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

Recorded paths are read by :mod:`simulator.traces.readers` (one module per dataset family;
:func:`simulator.traces.readers.load_headpath`).
"""

from __future__ import annotations

import math
import os
import warnings
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation, Slerp

from simulator.core.choices import SYNTH_KINDS
from simulator.core.errors import InputError
from simulator.core.fileio import atomic_output
from simulator.sphere.geometry import head_angles_deg, head_rotation

__all__ = [
    "MAX_SAMPLES",
    "SYNTH_KINDS",
    "CoarseSamplingWarning",
    "HeadPath",
    "RadiansWarning",
    "plot_headpath",
    "save_headpath_csv",
    "synth",
]


CANONICAL_COLUMNS: tuple[str, ...] = ("time_s", "yaw_deg", "pitch_deg", "roll_deg")


#: Time tolerance (s) when checking that a path covers a video.
_TIME_TOL = 1e-6


#: Most samples :func:`synth` makes (seconds x rate + 1); beyond, InputError.
MAX_SAMPLES = 10_000_000


#: A loaded path whose consecutive poses differ by more than this (deg) gives a
#: :class:`CoarseSamplingWarning`.
COARSE_STEP_DEG = 90.0


class RadiansWarning(UserWarning):
    """Angles in a file that should hold degrees all lie within +-2*pi: radians?"""


class MillisecondsWarning(UserWarning):
    """Times in a file that should hold seconds look like milliseconds."""


class CoarseSamplingWarning(UserWarning):
    """Consecutive poses differ by more than 90 deg: Slerp takes the shortest arc between
    them, which may not be the way the head turned."""


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
        r, out = self.rotations, np.empty(self.n - 1)
        for i in range(0, self.n - 1, 1 << 16):  # in chunks: no three copies of a long path
            j = min(i + (1 << 16), self.n - 1)
            out[i:j] = (r[i:j].inv() * r[i + 1 : j + 1]).magnitude()
        return np.degrees(out) / np.diff(self.times_s)


def save_headpath_csv(path: str | os.PathLike, hp: HeadPath) -> None:
    """Write the canonical CSV ``time_s,yaw_deg,pitch_deg,roll_deg`` atomically."""
    y, p, r = (np.round(a, 9) + 0.0 for a in hp.angles_deg())  # no 1e-16 noise, no -0
    with atomic_output(path) as tmp, open(tmp, "w") as fh:  # row by row: no copy of the text
        fh.write(",".join(CANONICAL_COLUMNS) + "\n")
        fh.writelines(",".join(f"{v:.10g}" for v in row) + "\n" for row in zip(hp.times_s, y, p, r))


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
    kf = g.get("keyframes")
    if not isinstance(kf, HeadPath):
        raise InputError(
            "keyframes: give the keyframes as a HeadPath "
            "(simulator.traces.readers.load_keyframes reads a JSON or CSV keyframe file)"
        )
    p = kf.source
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
