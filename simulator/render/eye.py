"""The eye renderer: one eye's view of a frame (equirect or another projection), with the GRF overlay, in one GL pass.

Per eye, one full-screen pass (``shaders/fullscreen.vert`` + ``shaders/eye.frag``)
computes each pixel's view ray from the eye's perspective projection (exact hfov/vfov,
pixel centres as :func:`simulator.sphere.geometry.perspective_rays`) and the head rotation
(the 3x3 head->world matrix of :func:`simulator.sphere.geometry.head_rotation`, passed as a
uniform), converts it to lon/lat with the project's conventions and samples the eye's
equirect frame (another projection's frame is sampled as stored, no CPU conversion: the
ray is carried into its face or lens, each tap kept inside it, :mod:`simulator.render.sampling`):

* magnification (a texel covers more than a pixel): bicubic, ffmpeg v360's 4-point
  Lagrange kernel, with longitude wrap-around at the +-180 deg seam and continuation
  across the poles;
* minification (e.g. a 4K frame into a small eye): mipmaps, trilinear, at the level of
  detail of the pixel's angular footprint on the sphere against the equirect's angular
  row height (``pi / H``). No texture-coordinate derivatives are used, so there is no
  seam line at +-180 deg and no blur or anisotropic-filter artefacts near the poles
  (llvmpipe's anisotropic filter speckles there; the equirect is oversampled in
  longitude near the poles anyway).

Granulated rest frames (:mod:`simulator.mitigation.grf`) are drawn in the same pass: world-fixed
grain coverage, rendered once per renderer into an equirect texture from a lat-band
bucket grid of the grains (shader storage buffers, ``shaders/grf_mask.frag``) and looked
up per pixel, times the head-fixed cutout and the frame's opacity.

The shader is compiled in variants (defines) so that llvmpipe, which runs both sides of
a branch, never pays for a path that cannot be taken: cubic only when no pixel minifies,
no grain-mask mip level when no pixel outside the cutout is larger than a mask texel, no
parallax ray for grains at infinity. For the encoder the same pass writes the luma (Y)
plane and ``shaders/chroma420.frag`` the U and V planes, so that frames leave the GPU as
yuv420p (no CPU flip, alpha drop or swscale conversion per frame).

Images are ``(H, W, 3)`` uint8 RGB, origin top-left; the one flip is at the framebuffer
boundary: eye.frag draws image row 0 into GL row 0, so the readback (GL row 0 first)
comes out top row first. The EGL context is created in exactly one function,
:func:`create_context`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from simulator.core.choices import Eye
from simulator.core.errors import InputError
from simulator.mitigation.grf import GrainField, GrfConfig
from simulator.mitigation.kinds import Mitigation
from simulator.render import sampling
from simulator.render.gl import _check_gl, _gl_limit, _program
from simulator.sphere.cells import Frustum
from simulator.sphere.geometry import check_fov, head_rotation

__all__ = ["EyeRenderer", "RenderConfig", "render_view"]


@dataclass(frozen=True)
class RenderConfig:
    """What one eye sees: image size, the view frustum, filtering, and the GRF.

    eye_size : (width, height), pixels (default 1440x1440, the paper's HMD per eye)
    hfov_deg, vfov_deg : exact horizontal / vertical FOV, degrees (default 107 x 107), for
        a symmetric view; ignored when ``frustum`` is given
    grf : GRF parameters, or None for no grains
    mitigation : :class:`simulator.mitigation.kinds.Mitigation`: what is drawn (default ``grf``:
        the paper's grains); grains are drawn when it has grains and ``grf`` is set, the
        vignette when it has one
    frustum : :class:`simulator.sphere.cells.Frustum` of the **left** eye (the right eye mirrors
        left and right), e.g. a headset's asymmetric per-eye frustum
        (``Frustum.from_headset``); default the symmetric ``hfov_deg x vfov_deg`` view.
        After construction it is always set, and ``hfov_deg``/``vfov_deg`` are its totals.
    """

    eye_size: tuple[int, int] = (1440, 1440)
    hfov_deg: float = 107.0
    vfov_deg: float = 107.0
    grf: GrfConfig | None = field(default_factory=GrfConfig)
    frustum: Frustum | None = None
    mitigation: Mitigation = field(default_factory=Mitigation)

    def __post_init__(self) -> None:
        if not isinstance(self.mitigation, Mitigation):
            raise InputError(
                f"render mitigation must be a Mitigation; got {type(self.mitigation).__name__}"
            )
        try:
            w, h = (int(v) for v in self.eye_size)
        except (TypeError, ValueError):
            raise InputError(
                f"eye size must be (width, height) pixels, e.g. 1440x1440; got {self.eye_size!r}"
            ) from None
        if w <= 0 or h <= 0:
            raise InputError(f"eye size must be positive, e.g. 1440x1440; got {w}x{h}")
        object.__setattr__(self, "eye_size", (w, h))
        fr = self.frustum
        if fr is None:
            hfov, vfov = check_fov(self.hfov_deg, self.vfov_deg)  # the one FOV rule
            fr = Frustum.symmetric(hfov, vfov)
        elif not isinstance(fr, Frustum):
            raise InputError(f"render frustum must be a Frustum; got {type(fr).__name__}")
        object.__setattr__(self, "frustum", fr)
        object.__setattr__(self, "hfov_deg", fr.hfov_deg)
        object.__setattr__(self, "vfov_deg", fr.vfov_deg)
        self.mitigation.check_view(fr)

    @property
    def grains(self) -> GrfConfig | None:
        """The grain parameters when grains are drawn, else None."""
        return self.grf if self.mitigation.grains else None

    def image_plane(self, eye: str = "left") -> tuple[tuple[float, float], tuple[float, float]]:
        """``((half_width, half_height), (centre_x, centre_y))`` of the eye's image on the
        plane z = 1: pixel ``(i, j)`` has its ray through ``((i + 0.5) / w * 2 - 1) *
        half_width + centre_x`` (right) and ``(1 - (j + 0.5) / h * 2) * half_height +
        centre_y`` (up). Symmetric views have centre 0 (``perspective_rays``); the right
        eye mirrors the left eye's frustum."""
        fr = self.frustum.for_eye(eye)
        lf, rt = math.tan(math.radians(fr.left_deg)), math.tan(math.radians(fr.right_deg))
        dn, up = math.tan(math.radians(fr.down_deg)), math.tan(math.radians(fr.up_deg))
        return ((rt + lf) / 2.0, (up + dn) / 2.0), ((rt - lf) / 2.0, (up - dn) / 2.0)

    @property
    def pixel_angle_rad(self) -> float:
        """Largest angular size of one pixel (at the view centre), radians."""
        w, h = self.eye_size
        (hx, hy), _ = self.image_plane()
        return max(2.0 * hx / w, 2.0 * hy / h)


def _grain_mask(ctx, grf: GrfConfig, pixel_angle_rad: float, outer_fbo):
    """Render the GRF's world-fixed grain coverage once, as an equirect R8 texture
    (``shaders/grf_mask.frag``), with texels no larger than the eye's largest pixel
    (capped at 8192 x 4096, at least 512 x 256); magnified bilinearly, its 1-texel
    antialiased edges stay within about a pixel.

    Returns ``(texture, lod)``. ``lod``: some pixel where grains can show (eccentricity
    >= ``grf.inner_deg``) may be larger than a texel row (small eyes, against the
    512-texel floor), so the texture is mipmapped and eye.frag picks the level from the
    pixel's footprint; otherwise (e.g. 1440 px eyes) every such pixel magnifies and level
    0 alone gives the same result. A perspective pixel at eccentricity e spans at most
    ``pixel_angle_rad * cos(e)``; 1 deg of slack covers llvmpipe's per-quad derivatives.
    """
    import moderngl

    limit = min(8192, _gl_limit(ctx, "GL_MAX_TEXTURE_SIZE"))
    w = math.ceil(2.0 * math.pi / pixel_angle_rad)
    w = min(max(512, w + (w % 2)), limit)
    h = w // 2
    reach = math.radians(max(grf.inner_deg - 1.0, 0.0))
    lod = pixel_angle_rad * math.cos(reach) > 0.99 * math.pi / h
    field_ = GrainField.from_config(grf)
    # Lookup reach: half a texel row (the antialiasing ramp) plus slack for float32 edges.
    b = field_.buckets(0.5 * math.pi / h + 1e-4)
    prog = _program(ctx, "fullscreen.vert", "grf_mask.frag", {})
    vao = ctx.vertex_array(prog, [])
    ssbos = [
        ctx.buffer(np.ascontiguousarray(arr).tobytes())
        for arr in (b.bands, b.cell_start, b.entries)
    ]
    tex = ctx.texture((w, h), 1, dtype="f1")
    fbo = ctx.framebuffer(color_attachments=[tex])
    try:
        for i, sb in enumerate(ssbos):
            sb.bind_to_storage_buffer(i)
        prog["u_size"].value = (float(w), float(h))
        prog["u_cell"].value = b.cell_rad
        prog["u_n_bands"].value = b.n_bands
        fbo.use()
        fbo.viewport = (0, 0, w, h)
        vao.render(moderngl.TRIANGLES, vertices=3)
        tex.repeat_x = True
        tex.repeat_y = False
        if lod:
            tex.filter = (moderngl.LINEAR_MIPMAP_LINEAR, moderngl.LINEAR)
            tex.build_mipmaps()
        else:
            tex.filter = (moderngl.LINEAR, moderngl.LINEAR)
    finally:
        outer_fbo.use()
        fbo.release()
        for sb in ssbos:
            sb.release()
        vao.release()
        prog.release()
    _check_gl(ctx, "after rendering the grain mask")
    return tex, lod


class EyeRenderer:
    """Renders eye views of equirect frames into an offscreen framebuffer.

    Parameters
    ----------
    ctx : moderngl.Context from :func:`create_context`
    config : RenderConfig
    projection, lens_fov_deg : the uploaded frames' projection (``equirect``, or one of
        :data:`simulator.sphere.projections.PROJECTIONS`, sampled as stored) and a dual
        fisheye's lens FOV (degrees; None: the default)

    Use :meth:`upload` once per video frame and eye (``"left"``, ``"right"``; for mono
    upload to ``"left"`` only and render both eyes from it), then :meth:`render`.
    """

    def __init__(self, ctx, config: RenderConfig = RenderConfig(), *,
                 projection: str = "equirect", lens_fov_deg: float | None = None):  # fmt: skip
        import moderngl

        if projection not in sampling.PROJ_DEFINE:
            raise InputError(f"--projection {projection!r}: unknown to the renderer")
        self.ctx = ctx
        self.config = config
        self.projection, self.lens_fov_deg = projection, lens_fov_deg
        # Bound again on release: releasing the bound FBO leaves moderngl restoring a dead
        # name on the next framebuffer creation (GL_INVALID_OPERATION).
        self._outer_fbo = ctx.fbo if ctx.fbo is not None else ctx.detect_framebuffer(0)
        w, h = config.eye_size
        limit = min(
            _gl_limit(ctx, "GL_MAX_TEXTURE_SIZE"),
            _gl_limit(ctx, "GL_MAX_VIEWPORT_DIMS"),
            _gl_limit(ctx, "GL_MAX_RENDERBUFFER_SIZE"),
        )
        if w > limit or h > limit:
            raise InputError(
                f"eye size {w}x{h} exceeds this OpenGL's limit of {limit} pixels per side"
            )
        self._max_tex = _gl_limit(ctx, "GL_MAX_TEXTURE_SIZE")
        self._moderngl = moderngl
        grf = config.grains
        mit = config.mitigation
        self.grain_mask = None
        grain_lod = False
        if grf is not None:
            self.grain_mask, grain_lod = _grain_mask(
                ctx, grf, config.pixel_angle_rad, self._outer_fbo
            )
        self._defines = {
            "PROJ": sampling.PROJ_DEFINE[projection],
            "GRF": int(grf is not None),
            "GRAIN_LOD": int(grain_lod),
            "GRAIN_PARALLAX": int(grf is not None and grf.distance_m is not None),
            **mit.shader_defines(grains=grf is not None),  # the kind's (mitigation.kinds.KINDS)
        }
        self._cell_tex = None  # local-grf: per-cell grain opacity, uploaded per frame
        # Keyed by MIPMAP; the general variant (cubic or trilinear per pixel) is built now,
        # the cubic-only one on the first frame that needs no mipmaps.
        self._progs: dict[bool, tuple] = {}
        self._frame_uniforms: dict = {}  # the uploaded frame's (sampling.uniforms)
        self._program(True)
        # eye.frag's outputs: RGB (a texture: chroma420.frag reads it) and luma (Y plane).
        self._color = ctx.texture((w, h), 4, dtype="f1")
        self._luma = ctx.renderbuffer((w, h), 1, dtype="f1")
        self.fbo = ctx.framebuffer(color_attachments=[self._color, self._luma])
        self._buf = np.empty((2, h, w, 4), np.uint8)  # readback: preallocated, one per eye
        self._yuv = None  # chroma pass and yuv420p buffers, built on first use
        self._tex: dict[str, object] = {}
        self._atlas_buf = None  # a cubemap's face atlas, reused frame after frame
        _check_gl(ctx, "after setting up the eye renderer")

    def _program(self, mipmap: bool):
        """eye.frag for ``MIPMAP = mipmap`` with its constant uniforms set: (program, vao)."""
        pv = self._progs.get(mipmap)
        if pv is not None:
            return pv
        cfg, grf = self.config, self.config.grains
        prog = _program(
            self.ctx, "fullscreen.vert", "eye.frag", {**self._defines, "MIPMAP": int(mipmap)}
        )
        values = {
            "u_tan_half": cfg.image_plane()[0],
            "u_size": (float(cfg.eye_size[0]), float(cfg.eye_size[1])),
            "u_frame": 0,
        }
        if grf is not None:
            values |= {
                "u_grains": 1,
                "u_cutout": (math.radians(grf.inner_deg), math.radians(grf.outer_deg)),
                "u_eye_offset": (0.0, 0.0, 0.0),
                "u_opacity": 0.0,
                "u_cell_opacity": 2,
            }
        if cfg.mitigation.vignette:
            values |= {"u_vignette_color": cfg.mitigation.color}
        for name, value in (values | self._frame_uniforms).items():
            if name in prog:
                prog[name].value = value
        pv = self._progs[mipmap] = (prog, self.ctx.vertex_array(prog, []))
        return pv

    def _set_uniforms(self, values: dict) -> None:
        """Set the frame's projection uniforms in every program (and later ones)."""
        self._frame_uniforms = values
        for prog, _vao in self._progs.values():
            for name, value in values.items():
                if name in prog:
                    prog[name].value = value

    @property
    def max_texture_size(self) -> int:
        """The largest frame side :meth:`upload` takes (``GL_MAX_TEXTURE_SIZE``)."""
        return self._max_tex

    def upload(self, frame: NDArray[np.uint8], eye: Eye = "left") -> None:
        """Upload one eye's frame ``(h, w, 3)`` uint8 RGB (top row first; in the renderer's
        projection, as stored) and rebuild its mipmaps. The texture is (re)allocated when
        the size changes."""
        h0, w0 = frame.shape[:2]
        if frame.ndim != 3 or frame.shape[2] != 3 or frame.dtype != np.uint8:
            raise ValueError(f"frame must be (h, w, 3) uint8; got {frame.shape} {frame.dtype}")
        w, h = sampling.texture_size(self.projection, w0, h0)
        if w > self._max_tex or h > self._max_tex:
            raise InputError(
                f"{self.projection} frame {w}x{h} exceeds this OpenGL's texture limit of "
                f"{self._max_tex} pixels"
            )
        tex = self._tex.get(eye)
        # Mipmaps only when some pixel is larger than the largest texel (minification).
        texel = sampling.texel_angle_rad(self.projection, w0, h0, self.lens_fov_deg)
        mips = self.config.pixel_angle_rad > 0.95 * texel
        if tex is None or tex.size != (w, h) or tex.extra != mips:
            if tex is not None:
                tex.release()
            mgl = self._moderngl
            tex = self.ctx.texture((w, h), 3, dtype="f1", alignment=1)
            tex.repeat_x = self.projection == "equirect"  # longitude wraps at the seam
            tex.repeat_y = False  # latitude is clamped at the poles
            tex.filter = (mgl.LINEAR_MIPMAP_LINEAR if mips else mgl.LINEAR, mgl.LINEAR)
            tex.extra = mips
            self._tex[eye] = tex
            self._set_uniforms(sampling.uniforms(self.projection, w0, h0, self.lens_fov_deg))
        if (w, h) != (w0, h0):  # a cubemap: its faces bordered by their neighbours
            atlas = sampling.face_atlas(self.projection, w0, h0)
            frame = self._atlas_buf = atlas(frame, out=self._atlas_buf)  # written at once
        tex.write(np.ascontiguousarray(frame))
        if mips:
            tex.build_mipmaps()

    def _upload_cell_opacity(self, cell_opacity) -> None:
        """local-grf: the frame's per-cell grain opacity ``(n_lat, n_lon)`` (row 0 north,
        column 0 at lon -180 deg), sampled nearest along each ray."""
        a = np.ascontiguousarray(np.clip(np.asarray(cell_opacity, np.float32), 0.0, 1.0))
        if a.ndim != 2:
            raise ValueError(f"cell opacity must be (n_lat, n_lon); got {a.shape}")
        h, w = a.shape
        tex = self._cell_tex
        if tex is None or tex.size != (w, h):
            if tex is not None:
                tex.release()
            mgl = self._moderngl
            tex = self.ctx.texture((w, h), 1, dtype="f4")
            tex.filter = (mgl.NEAREST, mgl.NEAREST)
            tex.repeat_x = True
            tex.repeat_y = False
            self._cell_tex = tex
        tex.write(a.tobytes())

    def _draw(self, rotation, eye, source, opacity, eye_offset, cell_opacity=None) -> None:
        tex = self._tex.get(source or eye)
        if tex is None:
            raise RuntimeError(f"no frame uploaded for eye {source or eye!r}")
        prog, vao = self._program(bool(tex.extra))
        R = np.asarray(rotation, np.float32).reshape(3, 3)
        prog["u_head"].write(R.T.tobytes())  # GLSL mat3 is column-major
        prog["u_tan_offset"].value = self.config.image_plane(eye)[1]
        mit = self.config.mitigation
        if self.config.grains is not None:
            if "u_opacity" in prog:  # local-grf: unused (each cell's own opacity)
                prog["u_opacity"].value = float(np.clip(opacity, 0.0, 1.0))
            if "u_eye_offset" in prog:
                prog["u_eye_offset"].value = tuple(float(v) for v in eye_offset)
            if mit.local:
                if cell_opacity is None and self._cell_tex is None:
                    raise ValueError("local-grf needs cell_opacity (n_lat, n_lon) per frame")
                if cell_opacity is not None:
                    self._upload_cell_opacity(cell_opacity)
                self._cell_tex.use(2)
        if mit.vignette:
            r = mit.aperture_radius_rad(float(np.clip(opacity, 0.0, 1.0)), self.config.frustum)
            prog["u_vignette"].value = (r, math.radians(mit.feather_deg))
        tex.use(0)
        if self.grain_mask is not None:
            self.grain_mask.use(1)
        self.fbo.use()
        vao.render(self._moderngl.TRIANGLES, vertices=3)

    def _yuv_pass(self):
        if self._yuv is None:
            w, h = self.config.eye_size
            if w % 2 or h % 2:
                raise InputError(f"yuv420p needs an even eye size, e.g. 1440x1440; got {w}x{h}")
            prog = _program(self.ctx, "fullscreen.vert", "chroma420.frag", {})
            prog["u_rgb"].value = 0
            vao = self.ctx.vertex_array(prog, [])
            planes = [self.ctx.renderbuffer((w // 2, h // 2), 1, dtype="f1") for _ in range(2)]
            fbo = self.ctx.framebuffer(color_attachments=planes)
            bufs = np.empty((2, h * 3 // 2, w), np.uint8)
            self._yuv = (prog, vao, fbo, planes, bufs)
        return self._yuv

    def render(
        self,
        rotation: NDArray,
        eye: Eye = "left",
        *,
        source: Eye | None = None,
        opacity: float = 0.0,
        eye_offset: tuple[float, float, float] = (0.0, 0.0, 0.0),
        pix_fmt: Literal["rgb24", "yuv420p"] = "rgb24",
        cell_opacity: NDArray | None = None,
    ) -> NDArray[np.uint8]:
        """Render one eye and read it back.

        Parameters
        ----------
        rotation : ndarray, shape (3, 3)
            Head -> world rotation matrix (``head_rotation(yaw, pitch, roll).as_matrix()``).
        eye : which readback buffer to use ("left" / "right"); the result stays valid
            until the next render of the same eye
        source : texture to sample (default ``eye``; mono: "left" for both eyes)
        opacity : GRF opacity (0..1) for this frame (grains and vignette)
        eye_offset : eye position in the world frame in units of the grain distance
            (parallax of finite-distance grains; zeros = grains at infinity)
        pix_fmt : ``"rgb24"``, or ``"yuv420p"`` (even eye sizes): converted on the GL
            side (Y from ``eye.frag``, U and V from ``shaders/chroma420.frag``; BT.601
            limited range, 2 x 2 chroma means, as swscale's rgb24 -> yuv420p) into the
            planar layout of ``av.VideoFrame.from_ndarray(..., format="yuv420p")``
        cell_opacity : local-grf only: this frame's per-cell grain opacity ``(n_lat,
            n_lon)`` (:func:`simulator.mitigation.kinds.cell_opacity`); None keeps the last one

        Returns
        -------
        rgb24: ndarray, shape (height, width, 3), uint8, a view (rows top first);
        yuv420p: ndarray, shape (height * 3 // 2, width), uint8, contiguous (Y rows, then
        U, then V, each top first)
        """
        if pix_fmt not in ("rgb24", "yuv420p"):
            raise ValueError(f"pix_fmt must be 'rgb24' or 'yuv420p'; got {pix_fmt!r}")
        self._draw(rotation, eye, source, opacity, eye_offset, cell_opacity)
        slot = 0 if eye == "left" else 1
        # eye.frag draws image row 0 into GL row 0 (the one flip), so the readback, bottom
        # GL row first, comes out top row first.
        if pix_fmt == "yuv420p":
            _prog, vao, fbo, _, bufs = self._yuv_pass()
            w, h = self.config.eye_size
            out = bufs[slot]
            self.fbo.read_into(out, components=1, attachment=1, alignment=1)  # Y
            self._color.use(0)
            fbo.use()
            vao.render(self._moderngl.TRIANGLES, vertices=3)
            for k in (0, 1):  # U, V
                fbo.read_into(
                    out, components=1, attachment=k, alignment=1, write_offset=w * h * (4 + k) // 4
                )
            return out
        self.fbo.read_into(self._buf[slot], components=4, alignment=1)
        return self._buf[slot, :, :, :3]

    def eye_offset(self, rotation: NDArray, eye: Eye) -> tuple[float, float, float]:
        """World-frame eye offset / grain distance for stereo grain parallax (zeros when the
        GRF has no finite distance). Left eye at -ipd/2 on the head's +x axis."""
        grf = self.config.grains
        if grf is None or grf.distance_m is None:
            return (0.0, 0.0, 0.0)
        sign = -1.0 if eye == "left" else 1.0
        off = np.asarray(rotation, float) @ np.array([sign * grf.ipd_m / 2.0, 0.0, 0.0])
        return tuple(float(v) for v in off / grf.distance_m)

    def release(self) -> None:
        for t in self._tex.values():
            t.release()
        if self.grain_mask is not None:
            self.grain_mask.release()
        if self._cell_tex is not None:
            self._cell_tex.release()
        self._outer_fbo.use()
        self.fbo.release()
        self._color.release()
        self._luma.release()
        if self._yuv is not None:
            prog, vao, fbo, planes, _ = self._yuv
            fbo.release()
            for rb in planes:
                rb.release()
            vao.release()
            prog.release()
        for prog, vao in self._progs.values():
            vao.release()
            prog.release()


def render_view(
    ctx,
    img: NDArray[np.uint8],
    yaw_deg: float,
    pitch_deg: float,
    roll_deg: float = 0.0,
    *,
    config: RenderConfig = RenderConfig(eye_size=(256, 256), grf=None),
    opacity: float = 1.0,
    cell_opacity: NDArray | None = None,
    projection: str = "equirect",
    lens_fov_deg: float | None = None,
) -> NDArray[np.uint8]:
    """One eye's view of an image ``(h, w, 3)`` uint8 (a copy), equirect or of
    ``projection`` (as stored; ``lens_fov_deg``: a dual fisheye's).

    Orientation in degrees (yaw + right, pitch + up, roll + right ear down; applied yaw,
    pitch, roll). ``opacity`` is the GRF (and vignette) opacity; ``cell_opacity`` the
    per-cell grain opacity of local-grf (``(n_lat, n_lon)``).
    """
    r = EyeRenderer(ctx, config, projection=projection, lens_fov_deg=lens_fov_deg)
    try:
        r.upload(img)
        R = head_rotation(yaw_deg, pitch_deg, roll_deg).as_matrix()
        return np.array(r.render(R, opacity=opacity, cell_opacity=cell_opacity))
    finally:
        r.release()
