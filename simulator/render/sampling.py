"""Where the eye shader finds a view ray in a frame of each input projection: its shader variant and uniforms.

The eye pass samples a non-equirect frame as stored (``shaders/eye.frag``, ``PROJ``), with
the maths of :mod:`simulator.sphere.projections` (v360's face order and rotations): this
module gives, per projection and stored eye size, the ``PROJ`` define, the uniforms (each
cube face's rectangle, the texel box its filter may read, its rotation; a dual fisheye's
lens FOV) and the frame's largest texel in radians (the filter's scale).

A ``c3x2`` / ``c6x1`` frame is uploaded as a face atlas
(:class:`simulator.sphere.projections.FaceAtlas`, the CPU converter's too): each face
bordered by at least 3 pixels of its neighbours (the face plane extended, nearest), so the bicubic taps across a face edge read the neighbouring face, not a repeated
edge (the faces are copied as blocks, the borders gathered: about a frame copy). A cell's
side is a multiple of 16 (even faces), so mip levels 1-4 halve it exactly and no mip
texel of them mixes two cells.
``eac`` needs none: a row of its faces is continuous and v360 writes the faces continued
into its 2-pixel pads; a dual fisheye's lenses are read inside their halves.
"""

from __future__ import annotations

import functools
import math

from simulator.render.gl import _gl_limit
from simulator.sphere.projections import DEFAULT_LENS_FOV_DEG, FaceAtlas, face_grid

__all__ = [
    "PROJ_DEFINE",
    "atlas_pad",
    "face_atlas",
    "sampled_projection",
    "texel_angle_rad",
    "texture_size",
    "uniforms",
]

#: ``PROJ`` of eye.frag per projection.
PROJ_DEFINE = {"equirect": 0, "c3x2": 1, "c6x1": 1, "eac": 2, "dfisheye": 3, "hequirect": 4}

# v360's in_frot rotation of face coordinates, (u', v') = (a u + b v, c u + d v)
# (projections._ROT: 90 -> (-v, u), 180 -> (-u, -v), 270 -> (v, -u)).
_ROT = {0: (1.0, 0.0, 0.0, 1.0), 90: (0.0, -1.0, 1.0, 0.0), 180: (-1.0, 0.0, 0.0, -1.0),
        270: (0.0, 1.0, -1.0, 0.0)}  # fmt: skip


def _lens(lens_fov_deg: float | None) -> float:
    return math.radians(DEFAULT_LENS_FOV_DEG if lens_fov_deg is None else float(lens_fov_deg))


def texel_angle_rad(name: str, w: int, h: int, lens_fov_deg: float | None = None) -> float:
    """The largest angular size of a texel of a ``w x h`` eye frame of projection ``name``
    (radians): equirect and hequirect a row (pi / h), a cube face's centre texel (2 / F),
    an eac face's (pi / 2 / its inner size), a fisheye's radial step (lens FOV / h). Mipmaps
    are built when a pixel is larger (as for the equirect, whose longitude texels shrink
    towards the poles: a cube face's towards its corners, where eye.frag's mip level then
    follows them)."""
    if name in ("equirect", "hequirect"):
        return math.pi / h
    if name == "dfisheye":
        return _lens(lens_fov_deg) / h
    lay = face_grid(name)
    if name == "eac":
        return 0.5 * math.pi / ((w - 4) / 3.0)
    return 2.0 / (w / lay.cols)


def uniforms(name: str, w: int, h: int, lens_fov_deg: float | None = None) -> dict:
    """eye.frag's uniforms for a ``w x h`` eye frame of projection ``name`` (none for
    equirect): ``u_texel_rad`` and, for a cubemap, per v360 direction (right, left, up,
    down, front, back) ``u_face_rect`` (origin x, y and size in texels: face coordinate
    t in [0, 1] lies at ``origin + size * t``, pixel centres at +0.5), ``u_face_box`` (first
    and last texel column and row its filter may read) and ``u_face_rot``; for a dual
    fisheye ``u_lens_fov`` (radians)."""
    if name == "equirect":
        return {}
    out: dict = {"u_texel_rad": texel_angle_rad(name, w, h, lens_fov_deg)}
    if name == "dfisheye":
        out["u_lens_fov"] = _lens(lens_fov_deg)
    lay = face_grid(name)
    if lay is None:
        return out
    rects, boxes = [], []
    for col, row in lay.cell:
        if name == "eac":  # v360: 2-pixel pads at the frame's edges and between the rows
            fw, fh = (w - 4) / 3.0, h / 2.0 - 4.0
            rects.append((2.0 + col * fw, 2.0 + row * h / 2.0, fw, fh))
            y0, y1 = (0, h // 2 - 1) if row == 0 else (h // 2, h - 1)
            boxes.append((0, y0, w - 1, y1))  # the row of faces, pads included
        else:  # the face in its FaceAtlas cell, the cell's border of neighbours readable
            f, P = w // lay.cols, atlas_pad(w // lay.cols)
            a = f + 2 * P
            rects.append((float(col * a + P), float(row * a + P), float(f), float(f)))
            boxes.append((col * a, row * a, col * a + a - 1, row * a + a - 1))
    out["u_face_rect"] = rects
    out["u_face_box"] = [tuple(float(v) for v in b) for b in boxes]
    out["u_face_rot"] = [_ROT[r] for r in lay.rot]
    return out


def texture_size(name: str, w: int, h: int) -> tuple[int, int]:
    """``(width, height)`` of the texture a ``w x h`` eye frame of ``name`` is uploaded as
    (its face atlas for ``c3x2`` / ``c6x1``, else the frame's)."""
    lay = face_grid(name) if name in ("c3x2", "c6x1") else None
    if lay is None:
        return w, h
    f = w // lay.cols
    a = f + 2 * atlas_pad(f)
    return lay.cols * a, lay.rows * a


def atlas_pad(face: int) -> int:
    """A face atlas's border (pixels) for faces of ``face`` pixels: at least 3 (the
    bicubic reaches 2 beyond the last face texel), widened so that the cell's side is a
    multiple of 16 when ``face`` is even."""
    return 3 + (-(face + 6) % 16) // 2


@functools.lru_cache(maxsize=4)
def face_atlas(name: str, w: int, h: int) -> FaceAtlas:
    """The (cached) :class:`simulator.sphere.projections.FaceAtlas` of a cubemap projection
    and eye size, its border :func:`atlas_pad` wide."""
    return FaceAtlas(name, w, h, atlas_pad(w // face_grid(name).cols))


def sampled_projection(ctx, source) -> str:
    """The projection the eye renderer samples ``source``'s frames in: the source's own
    (frames uploaded as stored: no CPU conversion), or ``equirect`` (converted on the CPU
    by ``source``'s funnel) when its stored eye frame, as uploaded (:func:`texture_size`),
    exceeds this OpenGL's ``GL_MAX_TEXTURE_SIZE`` or eye.frag has no ``PROJ`` for it."""
    name = source.projection
    if name not in PROJ_DEFINE or name == "equirect":  # a projection without GLSL: the CPU
        return "equirect"
    w, h = texture_size(name, *source.stored_eye_size)
    return name if max(w, h) <= _gl_limit(ctx, "GL_MAX_TEXTURE_SIZE") else "equirect"
