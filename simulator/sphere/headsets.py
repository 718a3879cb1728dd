"""Headset profiles by name: the per-eye field of view of real HMDs.

A profile gives one eye's rendered view frustum as four half-angles from the view axis
(left, right, down, up, degrees, all positive outward) for the **left** eye; the right eye
mirrors left and right. ``hfov_deg = left + right`` and ``vfov_deg = down + up`` are the
per-eye FOVs used wherever a symmetric viewport is wanted (paper-mode EPOF, windows);
sphere mode can use the exact asymmetric frustum (:meth:`Headset.half_angles_deg`).

Sources (each profile's ``source`` repeats its own)
---------------------------------------------------
``vive-pro-eye``
    HTC Vive Pro Eye as used by the paper (Cao & Kopper, SVR 2023, section 4: "The HMD
    had a horizontal FOV of 107 deg and a vertical FOV of 107 deg"); symmetric.
    Approximate: a nominal figure, not a measured frustum.
``vive-focus-3``, ``pimax-crystal``, ``quest-2``
    The per-eye render frustum reported by the headset's runtime, recorded with the
    ``hmdq`` tool and published in the HMD Geometry Database
    (https://risa2000.github.io/hmdgdb/, pages ``hmd_cfgs/ViveFocus3_Native_R90.html``,
    ``hmd_cfgs/PimaxCrystal_Native_R120.html``, ``hmd_cfgs/Quest2_Native_R72.html``;
    "Left eye head FOV" rows). These are the frusta the runtime asks applications to
    render; what a user actually sees through the lenses is somewhat smaller and depends
    on eye relief (Sauer et al., "Assessment of consumer VR-headsets' objective and
    subjective field of view", Virtual Reality 2022, measured e.g. the Vive Pro at
    ~87 deg x 91 deg per eye). Manufacturers' headline figures (e.g. "120 deg") are binocular
    or diagonal and are not used here.

All angles in degrees.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from simulator.core.errors import InputError
from simulator.sphere.geometry import check_fov

__all__ = ["HEADSETS", "Headset", "get_headset", "resolve_fov"]


@dataclass(frozen=True)
class Headset:
    """One HMD's per-eye view (left eye; the right eye mirrors left/right).

    name : str, the profile's key (``--headset NAME``)
    label : str, human-readable model name
    left_deg, right_deg, down_deg, up_deg : float, degrees in (0, 89.5]
        Half-angles of the left eye's frustum edges from its view axis, outward.
    source : str, where the numbers come from
    approximate : bool, True where the figure is nominal rather than a recorded frustum
    """

    name: str
    label: str
    left_deg: float
    right_deg: float
    down_deg: float
    up_deg: float
    source: str
    approximate: bool = False

    def __post_init__(self) -> None:
        for k in ("left_deg", "right_deg", "down_deg", "up_deg"):
            v = float(getattr(self, k))
            if not (0.0 < v <= 89.5) or not math.isfinite(v):
                raise InputError(f"headset {self.name}: {k} must be degrees in (0, 89.5]; got {v}")

    @property
    def hfov_deg(self) -> float:
        """Per-eye horizontal FOV, degrees (left + right half-angles)."""
        return self.left_deg + self.right_deg

    @property
    def vfov_deg(self) -> float:
        """Per-eye vertical FOV, degrees (down + up half-angles)."""
        return self.down_deg + self.up_deg

    def half_angles_deg(self, eye: str = "left") -> tuple[float, float, float, float]:
        """``(left, right, down, up)`` half-angles in degrees of ``eye``'s frustum."""
        if eye == "left":
            return self.left_deg, self.right_deg, self.down_deg, self.up_deg
        if eye == "right":
            return self.right_deg, self.left_deg, self.down_deg, self.up_deg
        raise InputError(f"unknown eye {eye!r}; expected left or right")


_HMDGDB = "HMD Geometry Database (hmdq), https://risa2000.github.io/hmdgdb/hmd_cfgs/"

HEADSETS: dict[str, Headset] = {
    h.name: h
    for h in (
        Headset(
            "vive-pro-eye",
            "HTC Vive Pro Eye (paper)",
            53.5,
            53.5,
            53.5,
            53.5,
            "Cao & Kopper, SVR 2023, section 4: 107 deg x 107 deg (nominal)",
            approximate=True,
        ),
        # Left eye head FOV: left -58.22, right 40.13, bottom -48.31, top 48.27 deg.
        Headset(
            "vive-focus-3",
            "HTC Vive Focus 3",
            58.22,
            40.13,
            48.31,
            48.27,
            _HMDGDB + "ViveFocus3_Native_R90.html (OpenVR render frustum)",
        ),
        # Left eye head FOV: left -51.65, right 41.65, bottom -51.88, top 51.88 deg.
        Headset(
            "pimax-crystal",
            "Pimax Crystal",
            51.65,
            41.65,
            51.88,
            51.88,
            _HMDGDB + "PimaxCrystal_Native_R120.html (OpenVR render frustum)",
        ),
        # Left eye head FOV: left -52, right 45, bottom -50, top 48 deg (default FOV).
        Headset(
            "quest-2",
            "Meta (Oculus) Quest 2",
            52.0,
            45.0,
            50.0,
            48.0,
            _HMDGDB + "Quest2_Native_R72.html (Oculus runtime default render frustum)",
        ),
    )
}


def get_headset(name: str) -> Headset:
    """The profile called ``name``; InputError listing the known names otherwise."""
    try:
        return HEADSETS[name]
    except KeyError:
        raise InputError(
            f"unknown headset {name!r}; expected one of {', '.join(HEADSETS)}"
        ) from None


def resolve_fov(
    *,
    headset: str | None = None,
    fov_deg: float | None = None,
    hfov_deg: float | None = None,
    vfov_deg: float | None = None,
    default: tuple[float, float] = (107.0, 107.0),
) -> tuple[float, float]:
    """Per-eye ``(hfov_deg, vfov_deg)`` from a headset name or explicit FOVs (CLI helper).

    At most one of ``headset``, ``fov_deg`` (square) and ``hfov_deg``/``vfov_deg`` may be
    given; ``vfov_deg`` defaults to ``hfov_deg``; nothing given -> ``default``. Explicit
    FOVs follow :func:`simulator.sphere.geometry.check_fov` (the one FOV rule).
    """
    given = [
        k
        for k, v in (
            ("--headset", headset),
            ("--fov", fov_deg),
            ("--hfov/--vfov", hfov_deg if hfov_deg is not None else vfov_deg),
        )
        if v is not None
    ]
    if len(given) > 1:
        raise InputError(f"give only one of {', '.join(given)}")
    if headset is not None:
        h = get_headset(headset)
        return h.hfov_deg, h.vfov_deg
    if fov_deg is not None:
        hfov_deg = vfov_deg = fov_deg
    if hfov_deg is None and vfov_deg is None:
        return default
    if hfov_deg is None:
        raise InputError("--vfov needs --hfov")
    return check_fov(hfov_deg, vfov_deg)
