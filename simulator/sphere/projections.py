"""Input projections (ffmpeg ``v360``'s names): where each sphere direction lies in a frame of that projection, and the conversion to the equirect working frame.

One table entry per projection (:data:`PROJECTIONS`): its working equirect size, the check
of a frame size against its layout, and ``to_image(dirs, w, h, lens_fov)`` giving the
array-index position (pixel centres at integers) and whether the projection covers the
direction. A new projection is one entry here plus its name in
:data:`simulator.core.choices.PROJECTIONS`.

Face order and rotations follow ``libavfilter/vf_v360.c`` exactly (v360 works in
x right, y DOWN, z forward; here y is up, so v360's ``y`` is ``-y``):

- ``c3x2``: faces in v360's default order ``rludfb`` (right, left, up on the top row;
  down, front, back below), no rotation; ``c6x1``: the same six in one row.
  Face coordinates ``uf, vf`` in [-1, 1] (u right, v down on the image):
  right ``(-z/x, y_v/x)``, left ``(-z/x, -y_v/x)``, up ``(-x/y_v, -z/y_v)``, down
  ``(x/y_v, -z/y_v)``, front ``(x/z, y_v/z)``, back ``(x/z, -y_v/z)``; pixel
  ``0.5 * F * (uf + 1) - 0.5`` within the face. Square faces are required.
- ``eac`` (YouTube's equi-angular cubemap): top row left, front, right; bottom row down,
  back, up, the bottom faces rotated (down 270, back 90, up 270 in v360's sense);
  ``uf -> 2/pi atan(uf) + 1/2``; a 2-pixel pad around the frame and between the rows
  (``u_pad = 2 / W``, ``v_pad = 2 / H``), as v360 reads it.
- ``dfisheye``: two equidistant circular fisheyes side by side, each ``H x H``: the front
  lens (z >= 0) on the right half, the back lens on the left half mirrored; radius
  ``r = angle_from_axis / lens_fov`` of the half width.
- ``hequirect`` (VR180 per eye): longitude and latitude -90..90 deg; the back half is not
  covered.

Working frame: every projection is converted once per frame to an equirect frame of
:meth:`Projection.equirect_size` (``cv2.remap``, bicubic; cube layouts through a face atlas
padded with the neighbouring faces' pixels, so the kernel never mixes unrelated faces).
Uncovered directions are black and reported by :meth:`EquirectConverter.covered`.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from simulator.core.errors import InputError
from simulator.sphere.geometry import equirect_pixel_lonlat, lonlat_to_dir

__all__ = [
    "DEFAULT_LENS_FOV_DEG",
    "PROJECTIONS",
    "EquirectConverter",
    "FaceAtlas",
    "Projection",
    "converter",
    "face_grid",
    "image_to_dirs",
]

#: Dual-fisheye lens FOV when none is given (degrees; GoPro / Insta360-like lenses).
DEFAULT_LENS_FOV_DEG = 190.0

# v360's directions and their index in the default face order "rludfb".
RIGHT, LEFT, UP, DOWN, FRONT, BACK = range(6)
_ROT = {0: lambda u, v: (u, v), 90: lambda u, v: (-v, u), 180: lambda u, v: (-u, -v),
        270: lambda u, v: (v, -u)}  # fmt: skip
_ROT_INV = {0: _ROT[0], 90: _ROT[270], 180: _ROT[180], 270: _ROT[90]}


def _cube_uv(d: NDArray) -> tuple[NDArray, NDArray, NDArray]:
    """v360's ``xyz_to_cube``: direction index and face coordinates of world directions."""
    x, yv, z = d[..., 0], -d[..., 1], d[..., 2]
    n = np.sqrt(x * x + yv * yv + z * z)
    x, yv, z = x / n, yv / n, z / n
    phi = np.arctan2(x, z)
    theta = np.arcsin(np.clip(yv, -1.0, 1.0))
    q = math.pi / 4
    dirn = np.select(
        [(phi >= -q) & (phi < q), (phi >= -3 * q) & (phi < -q), (phi >= q) & (phi < 3 * q)],
        [FRONT, LEFT, RIGHT],
        BACK,
    )
    phi_n = np.select(
        [dirn == FRONT, dirn == LEFT, dirn == RIGHT],
        [phi, phi + math.pi / 2, phi - math.pi / 2],
        phi + np.where(phi > 0, -math.pi, math.pi),
    )
    thr = np.arctan(np.cos(phi_n))
    dirn = np.where(theta > thr, DOWN, np.where(theta < -thr, UP, dirn))
    with np.errstate(divide="ignore", invalid="ignore"):
        u = np.select(
            [dirn == RIGHT, dirn == LEFT, dirn == UP, dirn == DOWN, dirn == FRONT],
            [-z / x, -z / x, -x / yv, x / yv, x / z],
            x / z,
        )
        v = np.select(
            [dirn == RIGHT, dirn == LEFT, dirn == UP, dirn == DOWN, dirn == FRONT],
            [yv / x, -yv / x, -z / yv, -z / yv, yv / z],
            -yv / z,
        )
    return dirn, u, v


def _face_dirs(direction: int, u: NDArray, v: NDArray) -> NDArray:
    """v360's ``cube_to_xyz`` (no rotation): world directions of face coordinates (any
    range: beyond [-1, 1] is the face plane extended)."""
    one = np.ones_like(u)
    xyz_v = {
        RIGHT: (one, v, -u),
        LEFT: (-one, v, u),
        UP: (u, -one, v),
        DOWN: (u, one, -v),
        FRONT: (u, v, one),
        BACK: (-u, v, -one),
    }[direction]
    x, yv, z = xyz_v
    return np.stack([x, -yv, z], axis=-1)


@dataclass(frozen=True)
class _CubeLayout:
    """Face grid of a cubemap: ``cols x rows`` faces, ``cell[direction] = (col, row)``,
    ``rot[direction]`` in degrees (v360's in_frot sense)."""

    cols: int
    rows: int
    cell: tuple[tuple[int, int], ...]
    rot: tuple[int, ...] = (0, 0, 0, 0, 0, 0)


_C3X2 = _CubeLayout(3, 2, ((0, 0), (1, 0), (2, 0), (0, 1), (1, 1), (2, 1)))
_C6X1 = _CubeLayout(6, 1, tuple((k, 0) for k in range(6)))
# eac: RIGHT=TOP_RIGHT, LEFT=TOP_LEFT, UP=BOTTOM_RIGHT, DOWN=BOTTOM_LEFT, FRONT=TOP_MIDDLE,
# BACK=BOTTOM_MIDDLE; bottom-left/right ROT_270, bottom-middle ROT_90.
_EAC = _CubeLayout(3, 2, ((2, 0), (0, 0), (2, 1), (0, 1), (1, 0), (1, 1)), (0, 0, 270, 270, 0, 90))


def _cube_to_image(
    layout: _CubeLayout, dirs: NDArray, w: int, h: int, eac: bool = False, cube=None
):
    dirn, u, v = _cube_uv(dirs) if cube is None else cube
    x = np.empty_like(u)
    y = np.empty_like(v)
    for k in range(6):
        m = dirn == k
        uk, vk = _ROT[layout.rot[k]](u[m], v[m])
        col, row = layout.cell[k]
        if eac:
            uk = 2 / math.pi * np.arctan(uk) + 0.5
            vk = 2 / math.pi * np.arctan(vk) + 0.5
            up, vp = 2.0 / w, 2.0 / h
            x[m] = ((uk + col) * (1 - 2 * up) / 3 + up) * w - 0.5
            y[m] = (vk * (0.5 - 2 * vp) + vp + 0.5 * row) * h - 0.5
        else:
            fw, fh = w / layout.cols, h / layout.rows
            x[m] = col * fw + 0.5 * fw * (uk + 1) - 0.5
            y[m] = row * fh + 0.5 * fh * (vk + 1) - 0.5
    return x, y, np.ones(x.shape, bool)


def _check_cube(layout: _CubeLayout, name: str) -> Callable[[int, int], str | None]:
    def check(w: int, h: int) -> str | None:
        if w % layout.cols or h % layout.rows or w // layout.cols != h // layout.rows:
            return (
                f"a {name} frame is {layout.cols} x {layout.rows} square faces; "
                f"{w}x{h} does not fit (e.g. {layout.cols * 512}x{layout.rows * 512})"
            )
        if w // layout.cols < 8:
            return f"{name} faces of {w // layout.cols} px are too small"
        return None

    return check


def _check_eac(w: int, h: int) -> str | None:
    if abs(w / h - 1.5) > 0.02 or h < 24:
        return f"an eac frame is 3 x 2 faces (3:2, e.g. 3072x2048); {w}x{h} does not fit"
    return None


def _dfisheye_to_image(dirs: NDArray, w: int, h: int, lens_fov_deg: float):
    x, yv, z = dirs[..., 0], -dirs[..., 1], dirs[..., 2]
    n = np.sqrt(x * x + yv * yv + z * z)
    x, yv, z = x / n, yv / n, z / n
    hh = np.hypot(x, yv)
    lh = np.where(hh > 0, hh, 1.0)
    r = np.arccos(np.clip(np.abs(z), 0, 1)) / math.radians(lens_fov_deg)  # 0.5 at the rim
    ew = w / 2.0
    u = (r * x / lh + 0.5) * ew
    v = (r * yv / lh + 0.5) * h
    px = np.where(z >= 0, u + ew, ew - u) - 0.5
    return px, v - 0.5, np.ones(px.shape, bool)


def _check_dfisheye(w: int, h: int) -> str | None:
    if w != 2 * h:
        return f"a dfisheye frame is two square lens images side by side (2:1); got {w}x{h}"
    return None


def _hequirect_to_image(dirs: NDArray, w: int, h: int):
    x, y, z = dirs[..., 0], dirs[..., 1], dirs[..., 2]
    lon = np.arctan2(x, z)
    lat = np.arcsin(np.clip(y / np.sqrt(x * x + y * y + z * z), -1, 1))
    px = (lon / math.pi + 0.5) * w - 0.5
    py = (0.5 - lat / math.pi) * h - 0.5
    return px, py, np.abs(lon) <= math.pi / 2


def _check_hequirect(w: int, h: int) -> str | None:
    if abs(w / h - 1.0) > 0.02:
        return f"a hequirect (VR180) eye is 180 x 180 deg (1:1 per eye); got {w}x{h}"
    return None


def _even(n: float) -> int:
    return max(2, round(n / 2) * 2)


@dataclass(frozen=True)
class Projection:
    """One input projection: ``to_image(dirs, w, h, lens_fov_deg) -> (x, y, covered)``
    (array-index positions in a ``w x h`` eye frame), ``check(w, h)`` (None or the
    problem), ``equirect(w, h)`` (working equirect size), ``cube`` (face grid, or None)."""

    name: str
    to_image: Callable
    check: Callable[[int, int], str | None]
    equirect: Callable[[int, int], tuple[int, int]]
    cube: _CubeLayout | None = None
    full: bool = True  # covers the whole sphere


PROJECTIONS: dict[str, Projection] = {
    "c3x2": Projection(
        "c3x2", lambda d, w, h, f: _cube_to_image(_C3X2, d, w, h), _check_cube(_C3X2, "c3x2"),
        lambda w, h: (_even(4 * w / 3), _even(2 * w / 3)), _C3X2,
    ),
    "c6x1": Projection(
        "c6x1", lambda d, w, h, f: _cube_to_image(_C6X1, d, w, h), _check_cube(_C6X1, "c6x1"),
        lambda w, h: (_even(4 * w / 6), _even(2 * w / 6)), _C6X1,
    ),
    "eac": Projection(
        "eac", lambda d, w, h, f: _cube_to_image(_EAC, d, w, h, eac=True), _check_eac,
        lambda w, h: (_even(4 * w / 3), _even(2 * w / 3)),
    ),
    "dfisheye": Projection(
        "dfisheye", _dfisheye_to_image, _check_dfisheye, lambda w, h: (_even(2 * h), _even(h)),
    ),
    "hequirect": Projection(
        "hequirect", lambda d, w, h, f: _hequirect_to_image(d, w, h), _check_hequirect,
        lambda w, h: (_even(2 * w), _even(h)), full=False,
    ),
}  # fmt: skip


def face_grid(name: str) -> _CubeLayout | None:
    """The face grid (``cols``, ``rows``, ``cell``, ``rot`` per v360 direction in the order
    right, left, up, down, front, back) of a cubemap projection (``eac`` included), else None."""
    return {"c3x2": _C3X2, "c6x1": _C6X1, "eac": _EAC}.get(name)


def image_to_dirs(proj: str, face_col: int, face_row: int, u: NDArray, v: NDArray) -> NDArray:
    """World directions of face coordinates ``(u, v)`` of the cube face at ``(col, row)``
    of a cubemap projection (the face plane extends beyond [-1, 1])."""
    lay = PROJECTIONS[proj].cube
    k = lay.cell.index((face_col, face_row))
    uu, vv = _ROT_INV[lay.rot[k]](u, v)
    return _face_dirs(k, uu, vv)


class FaceAtlas:
    """The faces of a ``c3x2`` / ``c6x1`` frame, each bordered by ``pad`` pixels of its
    neighbours (the face plane extended, nearest pixel): ``atlas(frame)`` for ``(h, w)`` or
    ``(h, w, C)`` frames of one size. The faces are copied as blocks and the borders
    gathered (about a frame copy)."""

    def __init__(self, name: str, w: int, h: int, pad: int):
        lay = face_grid(name)
        F = w // lay.cols
        P = self.pad = int(pad)
        A = F + 2 * P
        self.size, self.face = (w, h), F
        self.shape = (lay.rows * A, lay.cols * A)
        self.blocks = [(row * A + P, col * A + P, row * F, col * F) for col, row in lay.cell]
        ring = np.ones((A, A), bool)
        ring[P : P + F, P : P + F] = False
        ry, rx = np.nonzero(ring)
        t = (np.arange(A) - P + 0.5) / F * 2 - 1  # face coordinate of the cell's pixel centres
        dst_y, dst_x, src_y, src_x = [], [], [], []
        for col, row in lay.cell:  # a border pixel: the face plane extended, nearest pixel
            d = image_to_dirs(name, col, row, t[rx], t[ry])
            sx, sy, _ = PROJECTIONS[name].to_image(d, w, h, None)
            dst_y.append(ry + row * A)
            dst_x.append(rx + col * A)
            src_y.append(np.clip(np.rint(sy), 0, h - 1).astype(np.intp))
            src_x.append(np.clip(np.rint(sx), 0, w - 1).astype(np.intp))
        # flat pixel indices (a gather of whole pixels is 2x faster than of 2-d indices)
        self.dst = np.concatenate(dst_y) * self.shape[1] + np.concatenate(dst_x)
        self.src = np.concatenate(src_y) * w + np.concatenate(src_x)

    def __call__(self, frame: NDArray, out: NDArray | None = None) -> NDArray:
        """The atlas of ``frame``, written into ``out`` when it fits (an earlier result:
        reused, so that an 8K frame's atlas is not a fresh allocation per frame)."""
        F = self.face
        frame = np.ascontiguousarray(frame)
        shape = self.shape + frame.shape[2:]
        if out is None or out.shape != shape or out.dtype != frame.dtype:
            out = np.empty(shape, frame.dtype)
        for ay, ax, fy, fx in self.blocks:
            out[ay : ay + F, ax : ax + F] = frame[fy : fy + F, fx : fx + F]
        px = f"V{frame.itemsize * int(np.prod(frame.shape[2:]))}"  # one pixel, any channels
        out.reshape(-1).view(px)[self.dst] = frame.reshape(-1).view(px)[self.src]
        return out


class EquirectConverter:
    """Converts frames of one projection and eye size to the equirect working frame.

    ``(H, W)`` or ``(H, W, C)`` uint8 in, ``equirect_size`` out; :attr:`covered` is the
    ``(H_e, W_e)`` bool mask of directions the projection covers (uncovered pixels: 0).
    :meth:`sample` samples a frame at any directions (one resampling: ``vimsim viewport``).
    """

    PAD = 3  # atlas border of a cubemap face, pixels (bicubic reaches 2)

    def __init__(
        self, name: str, size: tuple[int, int], lens_fov_deg: float | None = None, pad: int = 3
    ):
        p = PROJECTIONS[name]
        self.PAD = max(self.PAD, int(pad))  # wider for a source downscaled after the atlas
        w, h = int(size[0]), int(size[1])
        problem = p.check(w, h)
        if problem:
            raise InputError(f"--projection {name}: {problem}")
        self.name, self.size, self._p = name, (w, h), p
        self.lens_fov_deg = DEFAULT_LENS_FOV_DEG if lens_fov_deg is None else float(lens_fov_deg)
        self._atlas = FaceAtlas(name, w, h, self.PAD) if p.cube is not None else None
        W, H = p.equirect(w, h)
        self.equirect_size = (W, H)
        lon, lat = equirect_pixel_lonlat(W, H)
        self._mx, self._my, self.covered = self.maps(lonlat_to_dir(lon[None, :], lat[:, None]))

    def maps(self, dirs: NDArray) -> tuple[NDArray, NDArray, NDArray]:
        """``cv2.remap`` maps (float32) of world directions ``(..., 3)`` into the frame (or
        its face atlas), and the bool mask of the covered ones (others map off the frame)."""
        w, h = self.size
        cube = _cube_uv(dirs) if self._atlas is not None else None  # once, not twice
        if cube is None:
            x, y, ok = self._p.to_image(dirs, w, h, self.lens_fov_deg)
        else:
            x, y, ok = _cube_to_image(self._p.cube, dirs, w, h, cube=cube)
        ok = np.asarray(np.broadcast_to(ok, np.shape(x)), bool)
        lim_w, lim_h = w - 1, h - 1
        if cube is not None:
            lay, P = self._p.cube, self.PAD
            dirn = cube[0]
            x = x + (2 * np.asarray([c for c, _ in lay.cell])[dirn] + 1) * P
            y = y + (2 * np.asarray([r for _, r in lay.cell])[dirn] + 1) * P
            lim_h, lim_w = (n - 1 for n in self._atlas.shape)
        x = np.clip(x, 0, lim_w)
        y = np.clip(y, 0, lim_h)
        x = np.where(ok, x, -16.0)  # constant border: black
        return x.astype(np.float32), y.astype(np.float32), ok

    def atlas(self, frame: NDArray) -> NDArray:
        """``frame`` as :meth:`maps` index it: the padded face atlas of a cubemap, else the
        frame itself (contiguous)."""
        return self._source(frame)

    def _source(self, frame: NDArray) -> NDArray:
        if frame.shape[1] != self.size[0] or frame.shape[0] != self.size[1]:
            raise InputError(
                f"--projection {self.name}: frame is {frame.shape[1]}x{frame.shape[0]}; "
                f"expected {self.size[0]}x{self.size[1]}"
            )
        src = np.ascontiguousarray(frame)
        return src if self._atlas is None else self._atlas(src)

    def sample(self, frame: NDArray, dirs: NDArray, *, interp: int = cv2.INTER_CUBIC) -> NDArray:
        """``frame`` (this projection) sampled at world directions ``(..., 3)``; black where
        the projection does not cover them."""
        mx, my, _ = self.maps(dirs)
        return cv2.remap(self._source(frame), mx, my, interp, borderMode=cv2.BORDER_CONSTANT)

    def __call__(self, frame: NDArray, *, interp: int | None = None) -> NDArray:
        """The equirect working frame of ``frame``: bicubic for colour frames (what the
        eye sees), bilinear for gray ones (the flow's input; 3x faster, the flow
        unchanged within 0.1%: ``bench/projection_flow.py``), unless ``interp`` says."""
        if interp is None:
            interp = cv2.INTER_LINEAR if frame.ndim == 2 else cv2.INTER_CUBIC
        return cv2.remap(
            self._source(frame), self._mx, self._my, interp,
            borderMode=cv2.BORDER_CONSTANT, borderValue=0,
        )  # fmt: skip


@functools.lru_cache(maxsize=8)
def converter(
    name: str, size: tuple[int, int], lens_fov_deg: float | None = None
) -> EquirectConverter:
    """The (cached) :class:`EquirectConverter` of a projection and eye size."""
    return EquirectConverter(name, tuple(size), lens_fov_deg)
