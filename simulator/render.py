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

import importlib.resources
import math
import re
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from simulator.errors import InputError
from simulator.geometry import check_fov, head_rotation
from simulator.grf import GrainField, GrfConfig

__all__ = [
    "EGL_PACKAGES",
    "OUTDIR_FILES",
    "EyeRenderer",
    "RenderConfig",
    "ShaderError",
    "VideoRenderResult",
    "create_context",
    "load_shader_source",
    "render_video",
    "render_view",
    "render_viewing",
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
        if len(lines) > 1 and lines[1] == "#line 2":
            del lines[1]  # the marker load_shader_source adds: back to the file's numbering
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
        hfov, vfov = check_fov(self.hfov_deg, self.vfov_deg)  # the one FOV rule
        object.__setattr__(self, "hfov_deg", hfov)
        object.__setattr__(self, "vfov_deg", vfov)

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
        self._moderngl = moderngl
        grf = config.grf
        self.grain_mask = None
        grain_lod = False
        if grf is not None:
            self.grain_mask, grain_lod = _grain_mask(
                ctx, grf, config.pixel_angle_rad, self._outer_fbo
            )
        self._defines = {
            "GRF": int(grf is not None),
            "GRAIN_LOD": int(grain_lod),
            "GRAIN_PARALLAX": int(grf is not None and grf.distance_m is not None),
        }
        # Keyed by MIPMAP; the general variant (cubic or trilinear per pixel) is built now,
        # the cubic-only one on the first frame that needs no mipmaps.
        self._progs: dict[bool, tuple] = {}
        self._program(True)
        # eye.frag's outputs: RGB (a texture: chroma420.frag reads it) and luma (Y plane).
        self._color = ctx.texture((w, h), 4, dtype="f1")
        self._luma = ctx.renderbuffer((w, h), 1, dtype="f1")
        self.fbo = ctx.framebuffer(color_attachments=[self._color, self._luma])
        self._buf = np.empty((2, h, w, 4), np.uint8)  # readback: preallocated, one per eye
        self._yuv = None  # chroma pass and yuv420p buffers, built on first use
        self._tex: dict[str, object] = {}
        _check_gl(ctx, "after setting up the eye renderer")

    def _program(self, mipmap: bool):
        """eye.frag for ``MIPMAP = mipmap`` with its constant uniforms set: (program, vao)."""
        pv = self._progs.get(mipmap)
        if pv is not None:
            return pv
        cfg, grf = self.config, self.config.grf
        prog = _program(
            self.ctx, "fullscreen.vert", "eye.frag", {**self._defines, "MIPMAP": int(mipmap)}
        )
        values = {
            "u_tan_half": (
                math.tan(math.radians(cfg.hfov_deg) / 2),
                math.tan(math.radians(cfg.vfov_deg) / 2),
            ),
            "u_size": (float(cfg.eye_size[0]), float(cfg.eye_size[1])),
            "u_equirect": 0,
        }
        if grf is not None:
            values |= {
                "u_grains": 1,
                "u_cutout": (math.radians(grf.inner_deg), math.radians(grf.outer_deg)),
                "u_eye_offset": (0.0, 0.0, 0.0),
                "u_opacity": 0.0,
            }
        for name, value in values.items():
            if name in prog:
                prog[name].value = value
        pv = self._progs[mipmap] = (prog, self.ctx.vertex_array(prog, []))
        return pv

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
        # Mipmaps only when some pixel is larger than a texel row (minification).
        mips = self.config.pixel_angle_rad > 0.95 * math.pi / h
        if tex is None or tex.size != (w, h) or tex.extra != mips:
            if tex is not None:
                tex.release()
            mgl = self._moderngl
            tex = self.ctx.texture((w, h), 3, dtype="f1", alignment=1)
            tex.repeat_x = True  # longitude wraps at the seam
            tex.repeat_y = False  # latitude is clamped at the poles
            tex.filter = (mgl.LINEAR_MIPMAP_LINEAR if mips else mgl.LINEAR, mgl.LINEAR)
            tex.extra = mips
            self._tex[eye] = tex
        tex.write(np.ascontiguousarray(frame))
        if mips:
            tex.build_mipmaps()

    def _draw(self, rotation, eye, source, opacity, eye_offset) -> None:
        tex = self._tex.get(source or eye)
        if tex is None:
            raise RuntimeError(f"no frame uploaded for eye {source or eye!r}")
        prog, vao = self._program(bool(tex.extra))
        R = np.asarray(rotation, np.float32).reshape(3, 3)
        prog["u_head"].write(R.T.tobytes())  # GLSL mat3 is column-major
        if self.config.grf is not None:
            prog["u_opacity"].value = float(np.clip(opacity, 0.0, 1.0))
            if "u_eye_offset" in prog:
                prog["u_eye_offset"].value = tuple(float(v) for v in eye_offset)
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
        eye: EyeName = "left",
        *,
        source: EyeName | None = None,
        opacity: float = 0.0,
        eye_offset: tuple[float, float, float] = (0.0, 0.0, 0.0),
        pix_fmt: Literal["rgb24", "yuv420p"] = "rgb24",
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
        pix_fmt : ``"rgb24"``, or ``"yuv420p"`` (even eye sizes): converted on the GL
            side (Y from ``eye.frag``, U and V from ``shaders/chroma420.frag``; BT.601
            limited range, 2 x 2 chroma means, as swscale's rgb24 -> yuv420p) into the
            planar layout of ``av.VideoFrame.from_ndarray(..., format="yuv420p")``

        Returns
        -------
        rgb24: ndarray, shape (height, width, 3), uint8, a view (rows top first);
        yuv420p: ndarray, shape (height * 3 // 2, width), uint8, contiguous (Y rows, then
        U, then V, each top first)
        """
        if pix_fmt not in ("rgb24", "yuv420p"):
            raise ValueError(f"pix_fmt must be 'rgb24' or 'yuv420p'; got {pix_fmt!r}")
        self._draw(rotation, eye, source, opacity, eye_offset)
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
        if self.grain_mask is not None:
            self.grain_mask.release()
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


# --------------------------------------------------------------------------- videos
@dataclass(frozen=True)
class VideoRenderResult:
    """What :func:`render_video` did: frames written per eye and wall-clock seconds."""

    n_frames: int
    eye_size: tuple[int, int]
    fps: float
    timings_s: dict[str, float]

    @property
    def frames_per_s(self) -> float:
        t = self.timings_s.get("total", 0.0)
        return self.n_frames / t if t > 0 else float("nan")


def _write_yuv420p(writer, frame: NDArray[np.uint8]) -> None:
    """Encode one frame already in yuv420p (``(h * 3 // 2, w)`` uint8, the layout of
    :meth:`EyeRenderer.render` ``pix_fmt="yuv420p"``) with a ``simulator.video.VideoWriter``,
    skipping its rgb24 -> yuv420p conversion (the stream is yuv420p: x264 takes it as is)."""
    import av

    w, h = writer.size
    if frame.shape != (h * 3 // 2, w) or frame.dtype != np.uint8:
        raise ValueError(
            f"frame must be ({h * 3 // 2}, {w}) uint8 yuv420p; got {frame.shape} {frame.dtype}"
        )
    vf = av.VideoFrame.from_ndarray(frame, format="yuv420p")
    for pkt in writer._stream.encode(vf):
        writer._container.mux(pkt)
    writer.n_written += 1


class _Worker:
    """A thread draining a bounded queue into ``fn``; errors resurface in :meth:`join`."""

    def __init__(self, fn, maxsize: int = 3, name: str = "worker"):
        import queue
        import threading

        self.q: queue.Queue = queue.Queue(maxsize=maxsize)
        self.fn = fn
        self.error: BaseException | None = None
        self.busy_s = 0.0
        self.t = threading.Thread(target=self._run, name=name, daemon=True)
        self.t.start()

    def _run(self) -> None:
        import time

        while True:
            item = self.q.get()
            if item is None:
                return
            if self.error is not None:
                continue  # drain after a failure
            t0 = time.perf_counter()
            try:
                self.fn(item)
            except BaseException as e:  # noqa: BLE001 - re-raised in join()
                self.error = e
            self.busy_s += time.perf_counter() - t0

    def put(self, item) -> None:
        if self.error is not None:
            raise self.error
        self.q.put(item)

    def join(self) -> None:
        self.q.put(None)
        self.t.join()
        if self.error is not None:
            raise self.error


def render_video(
    ctx,
    video_path: str,
    out_paths: tuple[str, str],
    angles_deg: NDArray[np.float64],
    *,
    opacity: NDArray[np.float64] | None = None,
    config: RenderConfig = RenderConfig(),
    layout: str = "mono",
    fps: float | None = None,
    n_frames: int | None = None,
    preset: str = "veryfast",
    crf: int = 18,
    progress: bool = True,
) -> VideoRenderResult:
    """Render per-eye H.264 videos of a (mono or stereo) equirect video along a head path.

    Parameters
    ----------
    ctx : moderngl.Context from :func:`create_context`
    video_path : equirect video (or image: one frame)
    out_paths : (left.mp4, right.mp4); each appears only when complete (atomic rename)
    angles_deg : ndarray, shape (N, 3), float64
        (yaw, pitch, roll) in degrees for video frame ``i`` (time ``i / fps``); frames
        beyond N hold the last pose
    opacity : ndarray, shape (N,), GRF opacity 0..1 per frame (ignored without ``config.grf``)
    layout : ``mono`` (both eyes see the frame), ``top-bottom`` (left eye top) or
        ``side-by-side`` (left eye left)
    fps, n_frames : the video's rate and frame count (from :func:`simulator.video.probe`)
    preset, crf : x264 speed preset and quality

    A mono video with grains at infinity gives the same image to both eyes: it is
    rendered and encoded once and ``right.mp4`` is a copy of ``left.mp4``. Frames are
    converted to yuv420p on the GL side (:meth:`EyeRenderer.render` ``pix_fmt``) and
    handed to x264 as they are.

    Returns
    -------
    VideoRenderResult with timings (seconds): ``decode_wait``, ``upload``, ``render``
    (draw, yuv420p conversion and readback of both eyes), ``encode_wait`` (blocked on the encoders),
    ``encode_busy`` (encoder threads' busy time, both eyes), ``total``.
    """
    import contextlib
    import functools
    import time

    from simulator.geometry import split_eye
    from simulator.video import VideoWriter, iter_frames, prefetch, probe

    info = probe(video_path)
    fps = float(fps or info.fps)
    total = int(n_frames or info.n_frames)
    ang = np.asarray(angles_deg, float).reshape(-1, 3)
    if ang.shape[0] < 1:
        raise InputError(f"{video_path}: no head orientations to render")
    op = None if opacity is None else np.clip(np.asarray(opacity, float).reshape(-1), 0.0, 1.0)
    rots = head_rotation(ang[:, 0], ang[:, 1], ang[:, 2]).as_matrix()
    stereo = layout != "mono"
    # Mono video with grains at infinity: both eyes see exactly the same image, so it is
    # rendered and encoded once and the file copied (halves the work; same output).
    same = not stereo and (config.grf is None or config.grf.distance_m is None)
    eyes = ("left",) if same else ("left", "right")
    renderer = EyeRenderer(ctx, config)
    w, h = config.eye_size
    timings = dict.fromkeys(("decode_wait", "upload", "render", "encode_wait"), 0.0)
    t_start = time.perf_counter()
    n = 0
    try:
        with contextlib.ExitStack() as stack:
            writers = [
                stack.enter_context(VideoWriter(p, fps, (w, h), crf=crf, preset=preset))
                for p in out_paths[: len(eyes)]
            ]
            workers = [
                _Worker(functools.partial(_write_yuv420p, wr), name=f"encode-{i}")
                for i, wr in enumerate(writers)
            ]
            try:
                from tqdm import tqdm

                # Decoding overlaps rendering; decoder buffers are reused, so copy there.
                frames = stack.enter_context(
                    contextlib.closing(
                        prefetch(
                            (np.array(f) for f in iter_frames(video_path, layout="mono")),
                            depth=3,
                        )
                    )
                )
                bar = tqdm(
                    total=total, unit="frame", disable=not progress, desc="render", leave=False
                )
                t0 = time.perf_counter()
                for frame in frames:
                    t1 = time.perf_counter()
                    timings["decode_wait"] += t1 - t0
                    i = min(n, len(rots) - 1)
                    if stereo:
                        renderer.upload(split_eye(frame, layout, "left", source=video_path), "left")
                        renderer.upload(
                            split_eye(frame, layout, "right", source=video_path), "right"
                        )
                    else:
                        renderer.upload(frame, "left")
                    t2 = time.perf_counter()
                    o = 0.0 if op is None else float(op[min(n, len(op) - 1)])
                    outs = []
                    for eye in eyes:
                        img = renderer.render(
                            rots[i],
                            eye,
                            source=eye if stereo else "left",
                            opacity=o,
                            eye_offset=renderer.eye_offset(rots[i], eye),
                            pix_fmt="yuv420p",
                        )
                        outs.append(img.copy())  # the buffer is reused
                    t3 = time.perf_counter()
                    for wk, img in zip(workers, outs):
                        wk.put(img)
                    t0 = time.perf_counter()
                    timings["upload"] += t2 - t1
                    timings["render"] += t3 - t2
                    timings["encode_wait"] += t0 - t3
                    n += 1
                    bar.update(1)
                bar.close()
            finally:
                errors = []
                for wk in workers:
                    try:
                        wk.join()
                    except BaseException as e:  # noqa: BLE001
                        errors.append(e)
                timings["encode_busy"] = sum(wk.busy_s for wk in workers)
            if errors:
                raise errors[0]
            if n == 0:
                raise InputError(f"{video_path}: no frames decoded")
        if same:
            import shutil

            from simulator.fileio import atomic_output

            with atomic_output(out_paths[1]) as tmp:
                shutil.copyfile(out_paths[0], tmp)
    finally:
        renderer.release()
    timings["total"] = time.perf_counter() - t_start
    return VideoRenderResult(n, (w, h), fps, timings)


#: What :func:`render_viewing` writes into OUTDIR, in this order; ``summary.json`` last.
OUTDIR_FILES = ("left.mp4", "right.mp4", "epof.csv", "summary.json")


def _clear_outputs(out) -> None:
    """Remove a previous run's :data:`OUTDIR_FILES` from ``out`` (only those names)."""
    for name in OUTDIR_FILES:
        p = out / name
        try:
            p.unlink(missing_ok=True)
        except OSError as e:
            raise InputError(
                f"{p}: cannot remove the previous run's output ({e.strerror})"
            ) from None


def render_viewing(
    video,
    headpath,
    outdir,
    *,
    grid=None,
    config: RenderConfig = RenderConfig(),
    opacity: float | Literal["auto"] = "auto",
    layout: str = "mono",
    hold: bool = False,
    preset: str = "veryfast",
    crf: int = 18,
    progress: bool = True,
    note: str | None = None,
    ctx=None,
) -> dict:
    """Render one viewing into ``outdir``: what ``vimsim render`` (and the demo) runs.

    Head path -> (with a grid) EPOF and GRF opacity -> both eyes rendered and encoded ->
    ``epof.csv`` -> ``summary.json``, i.e. :data:`OUTDIR_FILES`.

    Parameters
    ----------
    video : path of the equirect video (mono or stereo, see ``layout``)
    headpath : :class:`simulator.headpath.HeadPath`, or the path of a head path file
        (read with :func:`simulator.headpath.load_headpath`, format detected)
    outdir : output folder (created)
    grid : :class:`simulator.gridfile.GridFile`, a grid file's path, or None. With a grid
        the EPOF is computed and ``opacity="auto"`` follows it.
    config : eye size, exact FOVs (degrees) and GRF (``config.grf=None``: no overlay)
    opacity : ``"auto"`` (from the EPOF, needs ``grid``) or a constant in [0, 1]; ignored
        without ``config.grf``
    layout : ``mono``, ``top-bottom`` (left eye top) or ``side-by-side`` (left eye left)
    hold : hold the head path's first/last pose where it does not cover the video
    preset, crf : x264 speed preset and quality
    note : one line for the user, printed on stderr once the inputs are checked and kept
        in ``summary.json``
    ctx : moderngl.Context, or None to create one (:func:`create_context`)

    The inputs (video, head path, grid, options) and the GL context are checked before
    OUTDIR is touched (GL size limits only once rendering starts). Then the previous run's
    :data:`OUTDIR_FILES` (only those names) are removed, each output appears only when
    complete (temporary name, then rename), and ``summary.json`` is written last: a run
    is complete when it exists.

    Returns
    -------
    dict, the summary (also ``OUTDIR/summary.json``): settings, grain count, opacity
    thresholds, EPOF and opacity percentiles, timings (seconds), frames/s, GL renderer.
    """
    import sys
    import time
    from pathlib import Path

    from simulator.epof import EpofResult, compute_epof, write_epof_csv
    from simulator.fileio import atomic_output, check_output_dir, json_text
    from simulator.grf import grain_count
    from simulator.gridfile import GridFile, load_grid
    from simulator.headpath import HeadPath, load_headpath
    from simulator.video import probe

    t0 = time.perf_counter()
    w, h = config.eye_size
    hfov, vfov = config.hfov_deg, config.vfov_deg
    grf = config.grf
    if isinstance(opacity, str):
        if opacity != "auto":
            raise InputError(
                f"opacity must be 'auto' or a number in [0, 1], e.g. 0.5; got {opacity!r}"
            )
    elif not (0.0 <= float(opacity) <= 1.0):
        raise InputError(f"opacity must be 'auto' or a number in [0, 1], e.g. 0.5; got {opacity!r}")
    if w % 2 or h % 2:
        raise InputError(
            f"--eye-size must be even for H.264 (yuv420p); got {w}x{h}, e.g. {w + w % 2}x{h + h % 2}"
        )

    info = probe(video)
    info.eye_size(layout)  # 2:1 per eye (or squeezed stereo), else InputError
    if not info.is_video:
        raise InputError(
            f"{video}: a still image; render needs a video (vimsim viewport renders images)"
        )
    hp = headpath if isinstance(headpath, HeadPath) else load_headpath(headpath)
    duration = (info.n_frames - 1) / info.fps  # time of the last frame
    hp.check_covers(duration, hold=hold, video=str(video))
    nf = info.n_frames
    times = np.arange(nf) / info.fps

    if grid is not None and not isinstance(grid, GridFile):
        grid = load_grid(grid)
    if grid is not None:
        grid.check_video(info, source=grid.path)
    if grf is not None and opacity == "auto" and grid is None:
        raise InputError(
            "--opacity auto follows the EPOF and needs --grid GRID.npz; or give --opacity 0..1"
        )

    # Per-frame head angles and opacity (EPOF rows when a grid is given).
    yaw, pitch, roll = hp.sample_angles_deg(times, hold=hold)
    epof_dps = np.full(nf, np.nan)
    thresholds = (float("nan"), float("nan"))
    op_auto = None
    if grid is not None:
        res = compute_epof(grid, hp, hfov_deg=hfov, vfov_deg=vfov, hold=hold)
        n = min(len(res.epof_dps), nf)
        epof_dps[:n] = res.epof_dps[:n]
        epof_dps[n:] = res.epof_dps[-1]
        op_auto = np.empty(nf)
        op_auto[:n] = res.opacity[:n]
        op_auto[n:] = res.opacity[-1]
        thresholds = tuple(float(v) for v in res.thresholds_dps)
    if grf is None:
        op = np.zeros(nf)
    elif opacity == "auto":
        op = op_auto
    else:
        op = np.full(nf, float(opacity))

    if ctx is None:
        ctx = create_context()
    out = check_output_dir(outdir)
    _clear_outputs(out)  # a failed run must not leave the previous run's files beside new ones
    if note:
        print(f"vimsim render: note: {note}", file=sys.stderr)
    t_setup = time.perf_counter() - t0
    result = render_video(
        ctx,
        str(video),
        (str(out / "left.mp4"), str(out / "right.mp4")),
        np.stack([yaw, pitch, roll], axis=-1),
        opacity=op,
        config=config,
        layout=layout,
        fps=info.fps,
        n_frames=nf,
        preset=preset,
        crf=crf,
        progress=progress,
    )

    # epof.csv: one row per video frame.
    write_epof_csv(
        out / "epof.csv",
        EpofResult(np.arange(nf), times, yaw, pitch, roll, epof_dps, op, thresholds),
    )

    def pct(a):
        a = np.asarray(a, float)
        a = a[np.isfinite(a)]
        return {f"p{q}": float(np.percentile(a, q)) for q in (10, 50, 90)} if a.size else None

    timings = dict(result.timings_s, setup=t_setup, total_with_setup=time.perf_counter() - t0)
    summary = {
        "video": str(video),
        "headpath": hp.source or str(headpath),
        "grid": None if grid is None else (grid.path or None),
        "layout": layout,
        "fps": info.fps,
        "frames_video": nf,
        "frames_written": result.n_frames,
        "eye_size": [w, h],
        "hfov_deg": hfov,
        "vfov_deg": vfov,
        "grf": None
        if grf is None
        else {
            "grain_deg": grf.grain_deg,
            "density": grf.density,
            "inner_deg": grf.inner_deg,
            "outer_deg": grf.outer_deg,
            "seed": grf.seed,
            "distance_m": grf.distance_m,
            "n_grains": grain_count(grf),
        },
        "opacity": "off" if grf is None else opacity,
        "opacity_thresholds_dps": list(thresholds),
        "epof_dps_percentiles": pct(epof_dps),
        "opacity_percentiles": pct(op),
        "x264": {"preset": preset, "crf": crf},
        "timings_s": timings,
        "frames_per_s": result.frames_per_s,
        "renderer": ctx.info.get("GL_RENDERER"),
        "outdir": str(out),
    }
    if note:
        summary["note"] = note
    # Last: the completion marker.
    with atomic_output(out / "summary.json") as tmp:
        Path(tmp).write_text(json_text(summary) + "\n")
    return summary
