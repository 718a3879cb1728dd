"""Checks that a source's frames look like what they are read as: a dual-fisheye frame read as equirect, the projections whose layout fits a size.

A dual-fisheye frame (two lens images side by side, 2:1 like an equirect) read as equirect
gives plausible-looking but wrong flow and views. :func:`looks_dual_fisheye` tells one
from a frame: in each ``H x H`` half, the four corners outside the inscribed lens circle
are black (what a lens does not see; ffmpeg's ``v360`` writes 0 there), while a ring
just inside the circle holds the picture all the way round. An equirect with dark poles
(night sky, a black nadir patch, a masked band) has dark corners too, but its dark
region is a band across the top or bottom rows, so the ring's top and bottom sectors are
dark as well: it is not flagged. A dark frame (fade, night) is inconclusive.

:func:`fitting_projections` lists the projections whose frame layout fits a size (for
refusals: "its layout fits --projection eac").
"""

from __future__ import annotations

import functools
import math

import cv2
import numpy as np
from numpy.typing import NDArray

from simulator.core.errors import InputError
from simulator.sphere.geometry import check_equirect_aspect
from simulator.sphere.projections import PROJECTIONS

__all__ = [
    "DARK_LEVEL",
    "aspect_refusal",
    "check_not_dual_fisheye",
    "fitting_projections",
    "looks_dual_fisheye",
]

#: Analysis size of one lens half (pixels, square).
_SIDE = 128
#: A lens corner is "black" when 90 % of its pixels are at or below this luma (0..255):
#: codec noise and a lens's dark fall-off stay under it.
DARK_LEVEL = 24
#: A ring sector "holds picture" when its mean luma is this far above the corners'.
_CONTRAST = 20
#: Ring sectors (of 16: 8 per lens) that must hold picture.
_SECTORS_NEEDED = 14
#: Lens FOVs (degrees) tried for lenses filling their squares, and the correlation of the
#: two lens images where they overlap from which they are one dual fisheye.
_LENS_FOVS_DEG = (185, 190, 195, 200, 210, 220, 230)
_AGREE = 0.9


@functools.lru_cache(maxsize=1)
def _regions() -> tuple[list[NDArray], list[NDArray]]:
    """Masks of one ``_SIDE`` square: its 4 corners outside the inscribed circle
    (radius > 1.06 of the half side) and 8 sectors of the ring 0.7..0.95 inside it."""
    c = (_SIDE - 1) / 2.0
    y, x = np.mgrid[0:_SIDE, 0:_SIDE]
    dx, dy = x - c, y - c
    r = np.hypot(dx, dy) / (_SIDE / 2.0)
    ang = np.arctan2(dy, dx)
    corners = [(r > 1.06) & (np.sign(dx) == sx) & (np.sign(dy) == sy)
               for sx in (-1, 1) for sy in (-1, 1)]  # fmt: skip
    ring = (r > 0.7) & (r < 0.95)
    k = np.floor((ang + math.pi) / (2 * math.pi) * 8).astype(int) % 8
    sectors = [ring & (k == i) for i in range(8)]
    return corners, sectors


def looks_dual_fisheye(frame: NDArray[np.uint8]) -> bool | None:
    """Whether a stored 2:1 frame ``(H, W)`` gray or ``(H, W, 3)`` RGB uint8 is two lens
    circles with black outside (True), not (False), or cannot tell (None: a dark frame,
    or not 2:1)."""
    h, w = frame.shape[:2]
    if h < 16 or abs(w / (2.0 * h) - 1.0) > 0.02:
        return None
    gray = (
        frame if frame.ndim == 2 else cv2.cvtColor(np.ascontiguousarray(frame), cv2.COLOR_RGB2GRAY)
    )
    small = cv2.resize(gray, (2 * _SIDE, _SIDE), interpolation=cv2.INTER_AREA).astype(np.float32)
    corners, sectors = _regions()
    dark_p90, ring_means = [], []
    for half in (small[:, :_SIDE], small[:, _SIDE:]):
        dark_p90 += [float(np.percentile(half[m], 90)) for m in corners]
        ring_means += [float(half[m].mean()) for m in sectors]
    if max(ring_means) < DARK_LEVEL + _CONTRAST:  # a dark frame: nothing to tell by
        return None
    if max(dark_p90) <= DARK_LEVEL:  # a camera's lens circles, black outside
        floor = max(max(dark_p90), 8.0) + _CONTRAST
        if sum(m >= floor for m in ring_means) >= _SECTORS_NEEDED:
            return True
    return _lenses_agree(gray)


def _lenses_agree(gray: NDArray[np.uint8]) -> bool:
    """Lenses that fill their squares (ffmpeg ``v360``'s dfisheye: no black corners): with
    lenses over 180 deg, the directions near 90 deg from both axes are seen by both lenses;
    read as dual fisheye (vimsim's model, as v360's) the two images agree there. Two places
    of an equirect do not (correlation of the row-detrended images where both have picture:
    v360 dual fisheye >= 0.977, real equirects <= 0.53: bench/projection_guard.py). The
    azimuths near the four axes are left out: there the two places are neighbours in an
    equirect too (its seams at longitude 0 and 180, its poles)."""
    h, w = gray.shape
    if w > 1024:
        gray = cv2.resize(gray, (1024, 512), interpolation=cv2.INTER_AREA)
        h, w = gray.shape
    raw = cv2.GaussianBlur(gray.astype(np.float32), (0, 0), 1.5)
    g = raw - raw.mean(axis=1, keepdims=True)  # an equirect's horizontal layering (sky, ground)
    ew = w / 2.0
    phi = np.linspace(0.0, 2 * math.pi, 720, endpoint=False)
    off_axis = np.abs((phi + math.pi / 4) % (math.pi / 2) - math.pi / 4) > math.radians(20)
    c, s = np.cos(phi[off_axis])[:, None], np.sin(phi[off_axis])[:, None]
    for lens_deg in _LENS_FOVS_DEG:
        d = math.radians(lens_deg)
        theta = np.linspace(math.pi - d / 2, d / 2, 6)[None, :]  # angle from the front axis
        rf, rb = theta / d, (math.pi - theta) / d  # radii in each lens image (0.5: its rim)
        front = (ew + (rf * c + 0.5) * ew - 0.5, (0.5 - rf * s) * h - 0.5)
        back = (ew - (rb * c + 0.5) * ew - 0.5, (0.5 - rb * s) * h - 0.5)
        # pairs with picture on both sides: black on both (a region a projection does not
        # cover, e.g. a VR180 copy's back half) would agree without telling anything
        lit = (_sample(raw, *front) > DARK_LEVEL) & (_sample(raw, *back) > DARK_LEVEL)
        if lit.mean() < 0.5:
            continue
        a, b = _sample(g, *front)[lit], _sample(g, *back)[lit]
        if a.std() > 3.0 and b.std() > 3.0 and float(np.corrcoef(a, b)[0, 1]) >= _AGREE:
            return True
    return False


def _sample(img: NDArray[np.float32], x: NDArray, y: NDArray) -> NDArray[np.float32]:
    return cv2.remap(img, x.astype(np.float32), y.astype(np.float32), cv2.INTER_LINEAR).ravel()


def fitting_projections(width: int, height: int, sar: float = 1.0) -> list[str]:
    """The projections (``equirect`` and ffmpeg ``v360``'s) whose layout fits one eye of
    ``width x height`` stored pixels (``sar``: the sample aspect ratio, for equirect)."""
    out = []
    try:
        check_equirect_aspect(width, height, "mono", sar)
        out.append("equirect")
    except ValueError:
        pass
    out += [name for name, p in PROJECTIONS.items() if p.check(int(width), int(height)) is None]
    return out


#: Frames looked at (fractions of the video) until one tells: the first, then later ones
#: (a clip may fade in from black).
_AT = (0.0, 0.34, 0.67)
_verdicts: dict[tuple, bool] = {}


def check_not_dual_fisheye(path: str, read, n_frames: int, key: tuple) -> None:
    """InputError when a source read as equirect (its projection not given) looks like dual
    fisheye in the first frame that tells (:func:`looks_dual_fisheye`). ``read(index)``:
    the stored eye frame ``index``; ``key``: identifies the file's contents (a verdict is
    kept per key)."""
    if n_frames < 1:  # nothing to look at: the command names the empty stream itself
        return
    if key not in _verdicts:
        verdict = False
        for i in sorted({min(int(f * n_frames), n_frames - 1) for f in _AT}):
            try:
                frame = read(i)
            except InputError:  # a frame the stream does not hold: its reader says so later
                break
            v = looks_dual_fisheye(frame)
            if v is not None:
                verdict = v
                break
        _verdicts[key] = verdict
    if _verdicts[key]:
        raise InputError(
            f"{path}: looks like dual fisheye (two lens circles, black outside), not "
            "equirect: pass --projection dfisheye --lens-fov D (each lens's field of view in "
            "degrees, e.g. 190); --projection equirect reads it as equirect anyway"
        )


def aspect_refusal(path: str, err: Exception, size: tuple[int, int], sar: float) -> str:
    """The one-line refusal of a frame size that does not fit the projection read: the
    error ``err`` naming ``path``, and the projections whose layout fits that size."""
    text = str(err)
    if not text.startswith(str(path)):
        text = f"{path}: {text}"
    fits = fitting_projections(*size, sar)
    opts = ", ".join(f"--projection {p}" for p in fits)
    return text + (f"; its layout fits {opts}" if fits else "; no projection's layout fits it")
