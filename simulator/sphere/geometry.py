"""Sphere, equirectangular and perspective geometry: the project's conventions, once.

Conventions (SPEC.md; every function here follows them and says so)
-------------------------------------------------------------------
World frame
    +x right, +y up, +z forward. The direction (lon = 0, lat = 0) is +z, the centre of
    the equirect frame. ``lon = atan2(x, z)`` (increases to the right, toward +x),
    ``lat = asin(y)`` (+ up).
Equirect pixels
    Frame ``W x H`` (``W = 2H`` in display pixels). Pixel column ``x`` covers the
    continuous interval ``[x, x + 1)``; its centre ``x + 0.5`` maps to
    ``lon = (x + 0.5) / W * 360 deg - 180 deg``. Row ``y`` maps to
    ``lat = 90 deg - (y + 0.5) / H * 180 deg`` (top row is up). Longitude wraps at the
    +-180 deg seam; crossing a pole continues on the meridian 180 deg away.
Head orientation
    yaw (+ turns right, toward +lon), pitch (+ looks up), roll (+ tilts the head
    clockwise as the user sees it, right ear down). ``yaw = pitch = roll = 0`` looks at
    the frame centre. Applied yaw, then pitch, then roll (intrinsic), as ffmpeg's v360
    filter does (``rorder=ypr``). As a rotation of head-frame vectors (head frame: +x
    right, +y up, +z forward) into the world frame::

        R = Ry(yaw) * Rx(-pitch) * Rz(-roll)        (right-handed axis rotations)

    i.e. ``Rotation.from_euler("YXZ", [yaw, -pitch, -roll])``.
Perspective (flat) views
    ``size = (width, height)`` pixels, exact FOVs ``hfov``/``vfov`` (not the paper's
    linear ``h_FOV = FOV * H / W``). Pixel ``(col i, row j)`` has its centre on the image
    plane ``z = 1`` at ``u = ((i + 0.5) / width * 2 - 1) * tan(hfov / 2)`` (right) and
    ``v = (1 - (j + 0.5) / height * 2) * tan(vfov / 2)`` (up).

Angles are degrees at every public boundary (``*_deg``) and radians inside.
Images are ``(H, W)`` or ``(H, W, C)`` arrays with the origin at the top-left.

The paper's window conversion (section 3.2, eqs 3-16) is :func:`perspective_map`
with its errata fixed (SPEC.md): ``lon = atan2(x, z)`` (eq. 14), the normalised and
y-flipped equirect coordinates of eqs. 15/16, exact vertical FOV (eq. 6) and bicubic
sampling with longitude wrap-around and pole crossing (:func:`sample_equirect`).
"""

from __future__ import annotations

import functools
import math

import cv2
import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from simulator.core.choices import EYES, INTERPS, LAYOUTS, Interp
from simulator.core.errors import InputError

__all__ = [
    "EYES",
    "INTERPS",
    "LAYOUTS",
    "check_equirect_aspect",
    "check_fov",
    "dir_to_lonlat",
    "equirect_pixel_lonlat",
    "equirect_remap_coords",
    "extract_view",
    "head_angles_deg",
    "head_rotation",
    "lonlat_to_dir",
    "lonlat_to_equirect_xy",
    "pad_equirect",
    "perspective_map",
    "perspective_rays",
    "rotate_equirect",
    "sample_equirect",
    "split_eye",
]


#: Extra rows/columns added around an equirect frame before bicubic sampling, so that
#: the 4x4 kernel sees the wrapped seam and the other side of each pole.
_PAD = 4


def head_rotation(yaw_deg, pitch_deg, roll_deg=0.0) -> Rotation:
    """Rotation taking head-frame vectors to world-frame vectors.

    Parameters
    ----------
    yaw_deg, pitch_deg, roll_deg : float or array_like, degrees
        Head yaw (+ turns right, toward +lon), pitch (+ looks up) and roll (+ right ear
        down, the head tilts clockwise as the user sees it). Applied yaw, then pitch,
        then roll (intrinsic), matching ffmpeg v360's ``rorder=ypr``.

    Returns
    -------
    scipy.spatial.transform.Rotation
        ``R = Ry(yaw) Rx(-pitch) Rz(-roll)``; single or stacked like the inputs.
        Head frame and world frame: +x right, +y up, +z forward.
    """
    yaw, pitch, roll = np.broadcast_arrays(
        np.asarray(yaw_deg, float), np.asarray(pitch_deg, float), np.asarray(roll_deg, float)
    )
    angles = np.stack([yaw, -pitch, -roll], axis=-1)
    if angles.ndim == 2 and len(angles) > 1 << 16:  # a long path: scipy's temporaries per chunk
        return Rotation.concatenate([Rotation.from_euler("YXZ", angles[i : i + (1 << 16)], degrees=True)
                                     for i in range(0, len(angles), 1 << 16)])  # fmt: skip
    return Rotation.from_euler("YXZ", angles, degrees=True)


def head_angles_deg(
    rot: Rotation,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Inverse of :func:`head_rotation`: ``(yaw_deg, pitch_deg, roll_deg)``.

    yaw in (-180, 180], pitch in [-90, 90], roll in (-180, 180]. At pitch = +-90 deg
    (gimbal lock) yaw and roll are not unique; scipy puts the ambiguity in roll (warns).
    """
    a = rot.as_euler("YXZ", degrees=True)
    return a[..., 0], -a[..., 1], -a[..., 2]


def lonlat_to_dir(lon, lat) -> NDArray[np.float64]:
    """Unit directions, shape ``(..., 3)``, from longitude/latitude in **radians**
    (broadcast against each other).

    World frame: +x right, +y up, +z forward (lon = 0, lat = 0).
    """
    lon, lat = np.broadcast_arrays(np.asarray(lon, float), np.asarray(lat, float))
    c = np.cos(lat)
    return np.stack([c * np.sin(lon), np.sin(lat), c * np.cos(lon)], axis=-1)


def dir_to_lonlat(d) -> tuple[NDArray, NDArray]:
    """Longitude (-pi, pi] and latitude [-pi/2, pi/2], **radians**, of directions ``(..., 3)``.

    ``lon = atan2(x, z)`` (the paper's eq. 14 with its erratum fixed), ``lat = asin(y)``
    after normalising; world frame +x right, +y up, +z forward.
    """
    d = np.asarray(d)
    x, y, z = d[..., 0], d[..., 1], d[..., 2]
    n = np.sqrt(x * x + y * y + z * z)
    lon = np.arctan2(x, z)
    lat = np.arcsin(np.clip(y / n, -1.0, 1.0))
    return lon, lat


def equirect_pixel_lonlat(width: int, height: int) -> tuple[NDArray, NDArray]:
    """Longitude ``(W,)`` and latitude ``(H,)`` in **radians** of equirect pixel centres.

    ``lon = (x + 0.5) / W * 2 pi - pi``, ``lat = pi / 2 - (y + 0.5) / H * pi``.
    """
    lon = (np.arange(width) + 0.5) / width * 2 * np.pi - np.pi
    lat = np.pi / 2 - (np.arange(height) + 0.5) / height * np.pi
    return lon, lat


def lonlat_to_equirect_xy(lon, lat, width: int, height: int) -> tuple[NDArray, NDArray]:
    """Continuous equirect image coordinates of lon/lat in **radians** (eqs. 15/16, fixed).

    ``x = lon / pi * W/2 + W/2`` and ``y = H/2 - lat / (pi/2) * H/2``: pixel column ``x``
    covers ``[x, x + 1)``, so the centre of pixel ``(0, 0)`` is at ``(0.5, 0.5)``.
    Subtract 0.5 for array-index coordinates (OpenCV's ``remap`` convention).
    """
    x = np.asarray(lon) / np.pi * (width / 2.0) + width / 2.0
    y = height / 2.0 - np.asarray(lat) / (np.pi / 2.0) * (height / 2.0)
    return x, y


def check_fov(
    hfov_deg: float, vfov_deg: float | None = None, *, source: str = ""
) -> tuple[float, float]:
    """The one FOV rule: ``(hfov_deg, vfov_deg)`` as floats, each in degrees strictly
    inside (0, 180) (NaN and inf refused); ``vfov_deg`` defaults to ``hfov_deg``.
    InputError (prefixed by ``source`` when given) otherwise."""
    vfov_deg = hfov_deg if vfov_deg is None else vfov_deg
    out = []
    for name, v in (("hfov", hfov_deg), ("vfov", vfov_deg)):
        try:
            f = float(v)
        except (TypeError, ValueError):
            f = float("nan")
        if not (0.0 < f < 180.0):  # also False for NaN
            pre = f"{source}: " if source else ""
            raise InputError(f"{pre}{name} must be degrees in (0, 180); got {v}")
        out.append(f)
    return out[0], out[1]


def _check_size(size: tuple[int, int]) -> tuple[int, int]:
    try:
        w, h = int(size[0]), int(size[1])
    except (TypeError, ValueError, IndexError):
        raise InputError(
            f"size must be (width, height) in pixels, e.g. (256, 256); got {size!r}"
        ) from None
    if w <= 0 or h <= 0:
        raise InputError(f"size must be positive (width, height) in pixels; got {size!r}")
    return w, h


@functools.lru_cache(maxsize=32)
def _perspective_rays_cached(w: int, h: int, hfov_deg: float, vfov_deg: float):
    tx = math.tan(math.radians(hfov_deg) / 2.0)
    ty = math.tan(math.radians(vfov_deg) / 2.0)
    u = ((np.arange(w) + 0.5) / w * 2.0 - 1.0) * tx
    v = (1.0 - (np.arange(h) + 0.5) / h * 2.0) * ty
    uu, vv = np.meshgrid(u, v)
    r2 = 1.0 + uu * uu + vv * vv
    rn = np.sqrt(r2)
    dirs = np.stack([uu / rn, vv / rn, 1.0 / rn], axis=-1).astype(np.float32)
    # Solid angle of a pixel of the plane z = 1: du dv cos(theta) / r^2 = du dv / r^3.
    du = 2.0 * tx / w
    dv = 2.0 * ty / h
    sa = (du * dv / (r2 * rn)).astype(np.float32)
    dirs.setflags(write=False)
    sa.setflags(write=False)
    return dirs, sa


def perspective_rays(size: tuple[int, int], hfov_deg: float, vfov_deg: float | None = None):
    """Head-frame ray directions and solid angles of the pixels of a perspective view.

    Parameters
    ----------
    size : (width, height), pixels
    hfov_deg, vfov_deg : float, degrees in (0, 180)
        Exact horizontal and vertical fields of view; ``vfov_deg`` defaults to
        ``hfov_deg``.

    Returns
    -------
    dirs : ndarray, shape (height, width, 3), float32, read-only
        Unit ray of each pixel centre in the head frame (+x right, +y up, +z forward);
        row 0 is the top of the image.
    solid_angle : ndarray, shape (height, width), float32, read-only
        Solid angle of each pixel in steradians (``du dv / (1 + u^2 + v^2)^(3/2)``); sums
        to the view's solid angle ``4 asin(sin(hfov/2) sin(vfov/2))`` up to the midpoint rule.
    """
    w, h = _check_size(size)
    vfov_deg = hfov_deg if vfov_deg is None else vfov_deg
    check_fov(hfov_deg, vfov_deg)
    return _perspective_rays_cached(w, h, float(hfov_deg), float(vfov_deg))


def equirect_remap_coords(
    dirs: NDArray, width: int, height: int
) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """Where world directions fall in a padded equirect frame, as ``cv2.remap`` maps.

    Parameters
    ----------
    dirs : ndarray, shape (..., 3)
        Directions in the world frame (+x right, +y up, +z forward; need not be unit).
    width, height : int, pixels of the (unpadded) equirect frame

    Returns
    -------
    map_x, map_y : ndarray, shape (...), float32
        Array-index coordinates (OpenCV convention: pixel centres at integers) into the
        frame padded by :func:`pad_equirect`: pixel column ``x`` (centre ``x + 0.5`` in the
        continuous convention of the module docstring) sits at ``x + PAD``.
    """
    lon, lat = dir_to_lonlat(dirs)
    x, y = lonlat_to_equirect_xy(lon, lat, width, height)
    return (x - 0.5 + _PAD).astype(np.float32), (y - 0.5 + _PAD).astype(np.float32)


def perspective_map(
    equirect_size: tuple[int, int],
    size: tuple[int, int],
    yaw_deg: float,
    pitch_deg: float,
    roll_deg: float = 0.0,
    hfov_deg: float = 107.0,
    vfov_deg: float | None = None,
) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """Sampling maps of a perspective view into an equirect frame (the paper's eqs. 3-16).

    Parameters
    ----------
    equirect_size : (W, H), pixels of the source equirect frame (one eye)
    size : (width, height), pixels of the perspective view
    yaw_deg, pitch_deg, roll_deg : float, degrees
        View orientation (yaw + right, pitch + up, roll + right ear down; yaw, then
        pitch, then roll).
    hfov_deg, vfov_deg : float, degrees; exact FOVs, ``vfov_deg`` defaults to ``hfov_deg``

    Returns
    -------
    map_x, map_y : ndarray, shape (height, width), float32
        Coordinates in the frame padded by :func:`sample_equirect` (array-index
        convention), ready for ``cv2.remap``.
    """
    W, H = _check_size(equirect_size)
    dirs, _ = perspective_rays(size, hfov_deg, vfov_deg)
    R = head_rotation(yaw_deg, pitch_deg, roll_deg).as_matrix()
    world = dirs.astype(np.float64) @ R.T
    return equirect_remap_coords(world, W, H)


def pad_equirect(img: NDArray) -> NDArray:
    """An equirect frame padded for sampling across the seam and the poles.

    Parameters
    ----------
    img : ndarray, shape (H, W) or (H, W, C)
        One eye's equirect frame; ``W`` even (crossing a pole shifts by ``W / 2``).

    Returns
    -------
    ndarray, shape (H + 2 PAD, W + 2 PAD[, C]), same dtype, C-contiguous
        ``PAD = 4`` pixels on every side (enough for a 4x4 bicubic kernel): columns wrap
        around the +-180 deg seam; rows beyond a pole continue on the meridian 180 deg
        away (rows mirrored, columns shifted by ``W / 2``). Index it with the maps of
        :func:`equirect_remap_coords`. InputError for an odd width or fewer than PAD rows.
    """
    H, W = img.shape[:2]
    p = _PAD
    if W % 2 or H < p:
        raise InputError(f"equirect frame must have an even width and >= {p} rows; got {W}x{H}")
    top = np.roll(img[p - 1 :: -1], W // 2, axis=1)
    bottom = np.roll(img[: H - p - 1 : -1], W // 2, axis=1)
    tall = np.concatenate([top, img, bottom], axis=0)
    return np.concatenate([tall[:, -p:], tall, tall[:, :p]], axis=1)


def sample_equirect(
    img: NDArray,
    map_x: NDArray[np.float32],
    map_y: NDArray[np.float32],
    *,
    interp: Interp = "cubic",
) -> NDArray:
    """Sample an equirect frame at maps from :func:`perspective_map` (or any like them).

    Bicubic by default (the paper's 4x4 neighbourhood), with longitude wrap-around at the
    +-180 deg seam and correct continuation across the poles. ``interp`` is one of
    :data:`INTERPS` (``lagrange`` = ffmpeg v360's cubic kernel, exact but slower). ``img`` is ``(H, W)`` or
    ``(H, W, C)`` with C <= 4; the result has the maps' shape (+ channels), same dtype.
    """
    if interp not in INTERPS:
        raise InputError(f"unknown interpolation {interp!r}; expected one of {', '.join(INTERPS)}")
    padded = pad_equirect(np.ascontiguousarray(img))
    if interp == "lagrange":
        return _remap_lagrange(padded, map_x, map_y)
    flags = {"cubic": cv2.INTER_CUBIC, "linear": cv2.INTER_LINEAR, "nearest": cv2.INTER_NEAREST}[
        interp
    ]
    return cv2.remap(padded, map_x, map_y, flags, borderMode=cv2.BORDER_REPLICATE)


def _lagrange_weights(t: NDArray[np.float32]) -> tuple[NDArray, NDArray, NDArray, NDArray]:
    """Weights of taps at offsets -1, 0, 1, 2 for fraction ``t`` in [0, 1): the cubic
    through 4 samples (Lagrange); v360's ``calculate_bicubic_coeffs``. Sum to 1."""
    tt = t * t
    ttt = tt * t
    return (
        -t / 3 + tt / 2 - ttt / 6,
        1 - t / 2 - tt + ttt / 2,
        t + tt / 2 - ttt / 2,
        (ttt - t) / 6,
    )


def _remap_lagrange(padded: NDArray, map_x: NDArray, map_y: NDArray) -> NDArray:
    """Separable 4x4 Lagrange-cubic sampling of ``padded`` at array-index coordinates
    (pixel centres at integers, as ``cv2.remap``), exact fractional positions, float32
    accumulation, rounded and clipped back to the input dtype (integers)."""
    Hp, Wp = padded.shape[:2]
    C = 1 if padded.ndim == 2 else padded.shape[2]
    flat = padded.reshape(Hp * Wp, C)
    fx = np.floor(map_x)
    fy = np.floor(map_y)
    cx = _lagrange_weights((map_x - fx).astype(np.float32).reshape(-1, 1))
    cy = _lagrange_weights((map_y - fy).astype(np.float32).reshape(-1, 1))
    # Tap (i, j) = (row fy - 1 + i, col fx - 1 + j); the pad keeps every tap in range,
    # the clip only guards maps that leave the padded frame (edge replicated there).
    ix = np.clip(fx.astype(np.int64) - 1, 0, Wp - 4).reshape(-1)
    iy = np.clip(fy.astype(np.int64) - 1, 0, Hp - 4).reshape(-1)
    base = iy * Wp + ix
    out = np.zeros((base.size, C), np.float32)
    row = np.empty_like(out)
    for i in range(4):
        row.fill(0.0)
        bi = base + i * Wp
        for j in range(4):
            row += cx[j] * np.take(flat, bi + j, axis=0)
        out += cy[i] * row
    shape = map_x.shape + padded.shape[2:]
    if np.issubdtype(padded.dtype, np.integer):
        info = np.iinfo(padded.dtype)
        out = np.clip(np.rint(out), info.min, info.max)
    return out.astype(padded.dtype).reshape(shape)


def extract_view(
    img: NDArray,
    yaw_deg: float,
    pitch_deg: float,
    roll_deg: float = 0.0,
    *,
    hfov_deg: float = 107.0,
    vfov_deg: float | None = None,
    size: tuple[int, int] = (256, 256),
    interp: Interp = "cubic",
) -> NDArray:
    """One perspective view of an equirect frame (one eye, any dtype cv2 can remap).

    Orientation and FOVs in degrees (conventions in this module's docstring);
    ``size = (width, height)``. Returns ``(height, width[, C])`` with ``img``'s dtype.
    """
    H, W = img.shape[:2]
    mx, my = perspective_map((W, H), size, yaw_deg, pitch_deg, roll_deg, hfov_deg, vfov_deg)
    return sample_equirect(img, mx, my, interp=interp)


def rotate_equirect(img: NDArray, rot: Rotation, *, interp: Interp = "cubic") -> NDArray:
    """Equirect frame of the scene rotated by ``rot`` (a world-frame rotation).

    A scene point at direction ``d`` moves to ``rot.apply(d)``; output pixel with
    direction ``d'`` therefore shows the input at ``rot.inv().apply(d')``. Used to build
    videos with analytic motion (a point's angular speed under rotation at omega about
    unit axis ``a`` is ``omega |a x d|``).
    """
    H, W = img.shape[:2]
    lon, lat = equirect_pixel_lonlat(W, H)
    d = lonlat_to_dir(lon[None, :], lat[:, None])
    src = rot.inv().apply(d.reshape(-1, 3)).reshape(H, W, 3)
    mx, my = equirect_remap_coords(src, W, H)
    return sample_equirect(img, mx, my, interp=interp)


def split_eye(
    frame: NDArray, layout: str = "mono", eye: str = "left", *, source: str = "frame"
) -> NDArray:
    """The part of a (possibly stereo) equirect frame that one eye sees (a view, no copy).

    ``top-bottom``: left eye on top; ``side-by-side``: left eye on the left; ``mono``:
    the whole frame for both eyes. ``source`` names the file in error messages.
    """
    if layout not in LAYOUTS:
        raise InputError(
            f"{source}: unknown stereo layout {layout!r}; expected one of {', '.join(LAYOUTS)}"
        )
    if eye not in EYES:
        raise InputError(f"{source}: unknown eye {eye!r}; expected left or right")
    H, W = frame.shape[:2]
    if layout == "mono":
        return frame
    if layout == "top-bottom":
        if H % 2:
            raise InputError(f"{source}: top-bottom layout needs an even height; got {W}x{H}")
        return frame[: H // 2] if eye == "left" else frame[H // 2 :]
    if W % 2:
        raise InputError(f"{source}: side-by-side layout needs an even width; got {W}x{H}")
    return frame[:, : W // 2] if eye == "left" else frame[:, W // 2 :]


def check_equirect_aspect(
    width: int,
    height: int,
    layout: str = "mono",
    sar: float = 1.0,
    *,
    source: str = "input",
    tol: float = 0.01,
) -> tuple[int, int]:
    """Check that a stored ``width x height`` frame holds 2:1 equirect eye(s).

    Accepted: each eye displays as 2:1, or (stereo only) the whole frame displays as
    2:1 with each eye squeezed (half side-by-side / half top-bottom).

    ``sar`` is the sample (pixel) aspect ratio (e.g. 9/8 for three.js ``pano.mp4``,
    stored 1920x1080 and displayed 2160x1080). Returns the stored per-eye size
    ``(w, h)``; raises InputError naming ``source`` otherwise. Sampling uses stored
    pixels (longitude is linear in the column whatever the pixel shape).
    """
    if layout not in LAYOUTS:
        raise InputError(
            f"{source}: unknown stereo layout {layout!r}; expected one of {', '.join(LAYOUTS)}"
        )
    w, h = width, height
    if layout == "top-bottom":
        if height % 2:
            raise InputError(
                f"{source}: top-bottom stereo needs an even height; got {width}x{height}"
            )
        h = height // 2
    elif layout == "side-by-side":
        if width % 2:
            raise InputError(
                f"{source}: side-by-side stereo needs an even width; got {width}x{height}"
            )
        w = width // 2
    if w % 2 or h < _PAD:
        raise InputError(
            f"{source}: equirect width must be even (to cross the poles) and at least {_PAD} rows "
            f"per eye; got {w}x{h}"
        )
    aspect = w * sar / h
    # Stereo is also stored "half": each eye squeezed so the whole frame displays as 2:1
    # (three.js MaryOculus.mp4: side-by-side, 1:1 per eye). Longitude and latitude are
    # linear in stored columns and rows either way, so both forms are accepted.
    whole = width * sar / height
    half_ok = layout != "mono" and abs(whole / 2.0 - 1.0) <= tol
    if abs(aspect / 2.0 - 1.0) > tol and not half_ok:
        extra = "" if sar == 1.0 else f" (sample aspect ratio {sar:.4g})"
        hint = ""
        if layout == "mono" and abs(whole - 1.0) < tol:
            hint = "; a 1:1 frame may be top-bottom stereo: try --layout top-bottom"
        elif layout == "mono" and abs(whole - 4.0) < tol:
            hint = "; a 4:1 frame may be side-by-side stereo: try --layout side-by-side"
        raise InputError(
            f"{source}: expected an equirectangular image displaying 2:1 per eye "
            f"(or 2:1 for the whole frame with squeezed stereo eyes); got {width}x{height}"
            f"{extra}, {aspect:.3f}:1 per eye with layout {layout}{hint}"
        )
    return w, h
