"""Headless OpenGL (EGL, moderngl) renderer: what each eye saw, with the GRF overlay.

Per eye, one full-screen pass (``shaders/fullscreen.vert`` + ``shaders/eye.frag``)
computes each pixel's view ray from the eye's perspective projection (exact hfov/vfov,
pixel centres as :func:`simulator.geometry.perspective_rays`) and the head rotation
(the 3x3 head->world matrix of :func:`simulator.geometry.head_rotation`, passed as a
uniform), converts it to lon/lat with the project's conventions and samples the eye's
equirect frame:

* magnification (a texel covers more than a pixel): bicubic, ffmpeg v360's 4-point
  Lagrange kernel, with longitude wrap-around at the +-180 deg seam and continuation
  across the poles;
* minification (e.g. a 4K frame into a small eye): mipmaps, trilinear, at the level of
  detail of the pixel's angular footprint on the sphere against the equirect's angular
  row height (``pi / H``). No texture-coordinate derivatives are used, so there is no
  seam line at +-180 deg and no blur or anisotropic-filter artefacts near the poles
  (llvmpipe's anisotropic filter speckles there; the equirect is oversampled in
  longitude near the poles anyway).

Granulated rest frames (:mod:`simulator.grf`) are drawn in the same pass: world-fixed
black discs looked up per pixel in a lat-band bucket grid (shader storage buffers),
antialiased over the pixel's angular footprint, times the head-fixed cutout and the
frame's opacity.

Images are ``(H, W, 3)`` uint8 RGB, origin top-left; the GL readback (origin
bottom-left) is flipped once, in :meth:`EyeRenderer.render`. The EGL context is created
in exactly one function, :func:`create_context`.
"""

from __future__ import annotations

import importlib.resources
import math
import re
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from simulator.errors import InputError
from simulator.geometry import head_rotation
from simulator.grf import GrainField, GrfConfig

__all__ = [
    "EGL_PACKAGES",
    "EyeRenderer",
    "RenderConfig",
    "ShaderError",
    "create_context",
    "load_shader_source",
    "render_view",
]

#: Debian packages that provide headless EGL + OpenGL (Mesa llvmpipe without a GPU).
EGL_PACKAGES = "libegl1 libgl1-mesa-dri"

EyeName = Literal["left", "right"]


class ShaderError(RuntimeError):
    """A shader failed to compile or link; the message names the file and quotes the line."""


def create_context():
    """The one place an OpenGL context is created: standalone moderngl over EGL (headless).

    Returns a ``moderngl.Context`` (OpenGL >= 4.3 core: storage buffers). Raises InputError
    naming the Debian packages to install when EGL or a GL driver is missing.
    """
    try:
        import moderngl
    except ImportError as e:  # pragma: no cover - a dependency of the package
        raise InputError(f"moderngl is not installed ({e}); pip install moderngl") from None
    try:
        ctx = moderngl.create_context(standalone=True, backend="egl", require=430)
    except Exception as e:  # noqa: BLE001 - glcontext raises plain Exceptions
        msg = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        raise InputError(
            f"no headless OpenGL 4.3 over EGL ({msg}); on Debian/Ubuntu install {EGL_PACKAGES} "
            f"(apt-get install {EGL_PACKAGES})"
        ) from None
    return ctx


def load_shader_source(name: str, defines: dict[str, object] | None = None) -> str:
    """Source of ``simulator/shaders/<name>`` with ``#define``s injected after ``#version``.

    The injected block is followed by ``#line 2`` so that compiler line numbers match
    the file's.
    """
    src = importlib.resources.files("simulator").joinpath("shaders", name).read_text()
    first, _, rest = src.partition("\n")
    if not first.startswith("#version"):
        raise ShaderError(f"shaders/{name}:1: first line must be #version; got {first!r}")
    block = "".join(f"#define {k} {v}\n" for k, v in (defines or {}).items())
    return f"{first}\n{block}#line 2\n{rest}"


_LINE_RE = re.compile(r"^\s*\d+:(\d+)\(\d+\)|^\s*ERROR:\s*\d+:(\d+)|^\s*\d+\((\d+)\)", re.MULTILINE)


def _shader_error(err: Exception, files: dict[str, str]) -> ShaderError:
    """Turn a moderngl compile/link error into one naming the file and quoting the line."""
    text = str(err)
    kind = "fragment" if "fragment_shader" in text or "GL_FRAGMENT_SHADER" in text else "vertex"
    name = next((n for n in files if n.endswith(".frag" if kind == "fragment" else ".vert")), "?")
    m = _LINE_RE.search(text.split("\n", 3)[-1] if "\n" in text else text) or _LINE_RE.search(text)
    detail = next(
        (ln.strip() for ln in text.splitlines() if "error" in ln.lower() and ":" in ln),
        text.strip(),
    )
    if m:
        line = int(next(g for g in m.groups() if g))
        lines = files.get(name, "").splitlines()
        quoted = lines[line - 1].strip() if 0 < line <= len(lines) else "?"
        return ShaderError(f"shaders/{name}:{line}: {detail} -- `{quoted}`")
    return ShaderError(f"shaders/{name}: {detail}")


def _program(ctx, vert: str, frag: str, defines: dict[str, object]):
    files = {vert: load_shader_source(vert), frag: load_shader_source(frag)}
    try:
        return ctx.program(
            vertex_shader=load_shader_source(vert, defines),
            fragment_shader=load_shader_source(frag, defines),
        )
    except Exception as e:  # noqa: BLE001 - moderngl.Error
        raise _shader_error(e, files) from None


@dataclass(frozen=True)
class RenderConfig:
    """What one eye sees: image size, exact FOVs, filtering, and the GRF.

    eye_size : (width, height), pixels (default 1440x1440, the paper's HMD per eye)
    hfov_deg, vfov_deg : exact horizontal / vertical FOV, degrees (default 107 x 107)
    grf : GRF parameters, or None for no overlay
    """

    eye_size: tuple[int, int] = (1440, 1440)
    hfov_deg: float = 107.0
    vfov_deg: float = 107.0
    grf: GrfConfig | None = field(default_factory=GrfConfig)

    def __post_init__(self) -> None:
        try:
            w, h = (int(v) for v in self.eye_size)
        except (TypeError, ValueError):
            raise InputError(
                f"eye size must be (width, height) pixels, e.g. 1440x1440; got {self.eye_size!r}"
            ) from None
        if w <= 0 or h <= 0:
            raise InputError(f"eye size must be positive, e.g. 1440x1440; got {w}x{h}")
        object.__setattr__(self, "eye_size", (w, h))
        for name in ("hfov_deg", "vfov_deg"):
            v = float(getattr(self, name))
            if not (0.0 < v < 180.0):
                raise InputError(f"{name[:4]} must be degrees in (0, 180), e.g. 107; got {v}")

    @property
    def pixel_angle_rad(self) -> float:
        """Largest angular size of one pixel (at the view centre), radians."""
        w, h = self.eye_size
        return max(
            2.0 * math.tan(math.radians(self.hfov_deg) / 2.0) / w,
            2.0 * math.tan(math.radians(self.vfov_deg) / 2.0) / h,
        )


def _gl_limit(ctx, key: str) -> int:
    v = ctx.info.get(key)
    if isinstance(v, tuple):
        return int(min(v))
    return int(v) if v else 1 << 30


def _check_gl(ctx, where: str) -> None:
    err = ctx.error
    if err != "GL_NO_ERROR":
        raise RuntimeError(f"OpenGL error {err} {where}")


class EyeRenderer:
    """Renders eye views of equirect frames into an offscreen framebuffer.

    Parameters
    ----------
    ctx : moderngl.Context from :func:`create_context`
    config : RenderConfig

    Use :meth:`upload` once per video frame and eye (``"left"``, ``"right"``; for mono
    upload to ``"left"`` only and render both eyes from it), then :meth:`render`.
    """

    def __init__(self, ctx, config: RenderConfig = RenderConfig()):
        import moderngl

        self.ctx = ctx
        self.config = config
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
        grf = config.grf
        self.prog = _program(ctx, "fullscreen.vert", "eye.frag", {"GRF": int(grf is not None)})
        self.vao = ctx.vertex_array(self.prog, [])
        self.fbo = ctx.simple_framebuffer((w, h), components=4, dtype="f1")
        self._buf = np.empty((2, h, w, 4), np.uint8)  # readback: preallocated, one per eye
        self._tex: dict[str, object] = {}
        self._moderngl = moderngl
        self._set(
            "u_tan_half",
            (
                math.tan(math.radians(config.hfov_deg) / 2),
                math.tan(math.radians(config.vfov_deg) / 2),
            ),
        )
        self._set("u_size", (float(w), float(h)))
        self._set("u_equirect", 0)
        self._ssbos = []
        if grf is not None:
            field_ = GrainField.from_config(grf)
            # Lookup reach: half the largest pixel footprint, plus slack for float32 edges.
            b = field_.buckets(0.5 * config.pixel_angle_rad + 1e-4)
            for i, arr in enumerate((b.bands, b.cell_start, b.entries)):
                ssbo = ctx.buffer(np.ascontiguousarray(arr).tobytes())
                ssbo.bind_to_storage_buffer(i)
                self._ssbos.append(ssbo)
            self._set("u_cell", b.cell_rad)
            self._set("u_n_bands", b.n_bands)
            self._set("u_cutout", (math.radians(grf.inner_deg), math.radians(grf.outer_deg)))
            self._set("u_eye_offset", (0.0, 0.0, 0.0))
            self._set("u_opacity", 0.0)
        _check_gl(ctx, "after setting up the eye renderer")

    def _set(self, name: str, value) -> None:
        if name in self.prog:
            self.prog[name].value = value

    def upload(self, frame: NDArray[np.uint8], eye: EyeName = "left") -> None:
        """Upload one eye's equirect frame ``(h, w, 3)`` uint8 RGB (top row first) and
        rebuild its mipmaps. The texture is (re)allocated when the size changes."""
        h, w = frame.shape[:2]
        if frame.ndim != 3 or frame.shape[2] != 3 or frame.dtype != np.uint8:
            raise ValueError(f"frame must be (h, w, 3) uint8; got {frame.shape} {frame.dtype}")
        if w > self._max_tex or h > self._max_tex:
            raise InputError(
                f"equirect frame {w}x{h} exceeds this OpenGL's texture limit of {self._max_tex} pixels"
            )
        tex = self._tex.get(eye)
        if tex is None or tex.size != (w, h):
            if tex is not None:
                tex.release()
            mgl = self._moderngl
            tex = self.ctx.texture((w, h), 3, dtype="f1", alignment=1)
            tex.repeat_x = True  # longitude wraps at the seam
            tex.repeat_y = False  # latitude is clamped at the poles
            tex.filter = (mgl.LINEAR_MIPMAP_LINEAR, mgl.LINEAR)
            self._tex[eye] = tex
        tex.write(np.ascontiguousarray(frame))
        tex.build_mipmaps()

    def render(
        self,
        rotation: NDArray,
        eye: EyeName = "left",
        *,
        source: EyeName | None = None,
        opacity: float = 0.0,
        eye_offset: tuple[float, float, float] = (0.0, 0.0, 0.0),
    ) -> NDArray[np.uint8]:
        """Render one eye and read it back.

        Parameters
        ----------
        rotation : ndarray, shape (3, 3)
            Head -> world rotation matrix (``head_rotation(yaw, pitch, roll).as_matrix()``).
        eye : which readback buffer to use ("left" / "right"); the result stays valid
            until the next render of the same eye
        source : texture to sample (default ``eye``; mono: "left" for both eyes)
        opacity : GRF opacity (0..1) for this frame
        eye_offset : eye position in the world frame in units of the grain distance
            (parallax of finite-distance grains; zeros = grains at infinity)

        Returns
        -------
        ndarray, shape (height, width, 3), uint8, a view (rows top first)
        """
        tex = self._tex.get(source or eye)
        if tex is None:
            raise RuntimeError(f"no frame uploaded for eye {source or eye!r}")
        R = np.asarray(rotation, np.float32).reshape(3, 3)
        self.prog["u_head"].write(R.T.tobytes())  # GLSL mat3 is column-major
        if self.config.grf is not None:
            self.prog["u_opacity"].value = float(np.clip(opacity, 0.0, 1.0))
            self.prog["u_eye_offset"].value = tuple(float(v) for v in eye_offset)
        tex.use(0)
        self.fbo.use()
        self.vao.render(self._moderngl.TRIANGLES, vertices=3)
        slot = 0 if eye == "left" else 1
        self.fbo.read_into(self._buf[slot], components=4, alignment=1)
        # The one flip: GL rows are bottom first, images top first.
        return self._buf[slot, ::-1, :, :3]

    def eye_offset(self, rotation: NDArray, eye: EyeName) -> tuple[float, float, float]:
        """World-frame eye offset / grain distance for stereo grain parallax (zeros when the
        GRF has no finite distance). Left eye at -ipd/2 on the head's +x axis."""
        grf = self.config.grf
        if grf is None or grf.distance_m is None:
            return (0.0, 0.0, 0.0)
        sign = -1.0 if eye == "left" else 1.0
        off = np.asarray(rotation, float) @ np.array([sign * grf.ipd_m / 2.0, 0.0, 0.0])
        return tuple(float(v) for v in off / grf.distance_m)

    def release(self) -> None:
        for t in self._tex.values():
            t.release()
        for b in self._ssbos:
            b.release()
        self._outer_fbo.use()
        self.fbo.release()
        self.vao.release()
        self.prog.release()


def render_view(
    ctx,
    img: NDArray[np.uint8],
    yaw_deg: float,
    pitch_deg: float,
    roll_deg: float = 0.0,
    *,
    config: RenderConfig = RenderConfig(eye_size=(256, 256), grf=None),
    opacity: float = 1.0,
) -> NDArray[np.uint8]:
    """One eye's view of an equirect image ``(h, w, 3)`` uint8 (a copy).

    Orientation in degrees (yaw + right, pitch + up, roll + right ear down; applied yaw,
    pitch, roll). ``opacity`` is the GRF opacity when ``config.grf`` is set.
    """
    r = EyeRenderer(ctx, config)
    try:
        r.upload(img)
        R = head_rotation(yaw_deg, pitch_deg, roll_deg).as_matrix()
        return np.array(r.render(R, opacity=opacity))
    finally:
        r.release()
