"""The exported overlay without Unity: ``VimsimOverlay.hlsl`` compiled by Debian's glslang
(HLSL -> SPIR-V), translated to GLSL by spirv-cross, drawn by moderngl over the eye view
vimsim renders without a mitigation, against vimsim's own eye renders with the mitigation
(PSNR), with the grain mask built by the exported C# (``VimsimGrainMask.Build``); the C# grain
layout against Python's; the tools' absence skips with the packages to install
(``make sysdeps``)."""

from __future__ import annotations

import math
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from simulator.export import export_unity
from simulator.export.unity import read_grain_layout
from simulator.media.gridfile import save_grid
from simulator.mitigation.grf import GrainField, GrfConfig
from simulator.mitigation.kinds import Mitigation, full_radius_rad
from simulator.render import RenderConfig
from simulator.render.eye import EyeRenderer
from simulator.render.gl import load_shader_source
from simulator.sphere.geometry import head_rotation
from simulator.sphere.windows import grid_preset

REPO = Path(__file__).resolve().parents[2]
HLSL = REPO / "simulator" / "export" / "unity" / "VimsimOverlay.hlsl"
GRF = GrfConfig(grain_deg=2.0, density=0.4, inner_deg=15.0, outer_deg=35.0, seed=7)
VIGNETTE = {"aperture_min_deg": 50.0, "feather_deg": 12.0, "color": (0.1, 0.2, 0.6)}
POSE = (-120.0, 35.0, 25.0)  # an eye with roll
OPACITIES = (0.2, 0.6, 1.0)


def _tool(name: str) -> str:
    path = shutil.which(name)
    if path is None:
        pytest.skip(f"{name} not found; `make sysdeps` installs Debian's glslang-tools spirv-cross")
    return path


@pytest.fixture(scope="module")
def overlay_glsl(tmp_path_factory) -> str:
    """The HLSL core compiled standalone (entry point frag) and translated to GLSL 430."""
    glslang, spirv_cross = _tool("glslangValidator"), _tool("spirv-cross")
    d = tmp_path_factory.mktemp("hlsl")
    spv = d / "overlay.spv"
    # glslang 12 compiles HLSL only with SPIR-V generation (-V); -D: HLSL input.
    r = subprocess.run([glslang, "-D", "-V", "-e", "frag", "-S", "frag", str(HLSL), "-o", str(spv)],
                       capture_output=True, text=True, check=False)  # fmt: skip
    assert r.returncode == 0, r.stdout + r.stderr
    r = subprocess.run([spirv_cross, str(spv), "--version", "430", "--no-es"],
                       capture_output=True, text=True, check=False)  # fmt: skip
    assert r.returncode == 0, r.stdout + r.stderr
    assert "buffer" not in r.stdout.replace("uniform", "")  # GLES3-safe: no storage buffers
    return r.stdout


@pytest.fixture(scope="module")
def export_dir(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("x")
    g = grid_preset("default")
    pof = np.full((4, *g.shape), 30.0, np.float32)
    meta = {"fps": 30.0, "n_frames": 4, "flow": {"method": "test"}, "layout": "mono",
            "eye": "left", "video": {"path": "v.mp4", "content_hash": "sha256:ab"}}  # fmt: skip
    save_grid(d / "g.npz", pof, pof / 10, g, meta)
    export_unity(d / "g.npz", d / "x", grf=GRF, mitigation=Mitigation("grf+vignette", **VIGNETTE))
    return d / "x"


def _panorama() -> np.ndarray:
    """A smooth colourful equirect with some edges (1024 x 512)."""
    y, x = np.mgrid[0:512, 0:1024] / 512.0
    img = np.stack([0.5 + 0.4 * np.sin(3 * x + 1), 0.5 + 0.4 * np.cos(5 * y), 0.5 + 0.3 * np.sin(4 * x * y)], -1)
    img[(np.floor(x * 8) + np.floor(y * 8)) % 2 == 0] *= 0.8
    return (img * 255).round().astype(np.uint8)


def _psnr(a, b) -> float:
    mse = np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2)
    return float("inf") if mse == 0 else 10 * math.log10(255.0**2 / mse)


class _Overlay:
    """The translated overlay shader in a float framebuffer, with the C# grain mask."""

    def __init__(self, ctx, glsl: str, mask: np.ndarray, lod: bool, size: tuple[int, int]):
        import moderngl

        self.ctx, self.size = ctx, size
        self.prog = ctx.program(vertex_shader=load_shader_source("fullscreen.vert"), fragment_shader=glsl)
        self.vao = ctx.vertex_array(self.prog, [])
        h, w = mask.shape
        self.mask = ctx.texture((w, h), 1, np.ascontiguousarray(mask).tobytes(), dtype="f1")
        self.mask.repeat_x, self.mask.repeat_y = True, False
        if lod:
            self.mask.filter = (moderngl.LINEAR_MIPMAP_LINEAR, moderngl.LINEAR)
            self.mask.build_mipmaps()
        else:
            self.mask.filter = (moderngl.LINEAR, moderngl.LINEAR)
        self.lod = lod
        self.fbo = ctx.framebuffer(color_attachments=[ctx.texture(size, 4, dtype="f4")])
        self.ubo = [ctx.buffer(reserve=7 * 16), ctx.buffer(reserve=2 * 16)]
        self.prog["UnityPerMaterial"].binding = 0
        self.prog["VimsimTest"].binding = 1
        sampler = next(k for k in self.prog if k.startswith("SPIRV_Cross_Combined"))
        self.prog[sampler].value = 0

    def draw(self, R, kind: str, opacity: float, config: RenderConfig) -> np.ndarray:
        m = Mitigation(kind, **VIGNETTE)
        (hx, hy), (cx, cy) = config.image_plane()
        w, h = self.size
        per_mat = [
            [*R[:, 0], 0], [*R[:, 1], 0], [*R[:, 2], 0],  # head axes in the world (columns)
            [math.radians(GRF.inner_deg), math.radians(GRF.outer_deg), float(m.grains), opacity],
            [full_radius_rad(config.frustum), math.radians(m.aperture_min_deg) / 2,
             math.radians(m.feather_deg), float(m.vignette)],
            [*m.color, 1.0], [self.mask.height, float(self.lod), 0.0, 0.0],
        ]  # fmt: skip
        self.ubo[0].write(np.asarray(per_mat, "<f4").tobytes())
        self.ubo[1].write(np.asarray([[hx, hy, cx, cy], [w, h, 0, 0]], "<f4").tobytes())
        for i, b in enumerate(self.ubo):
            b.bind_to_uniform_block(i)
        self.mask.use(0)
        self.fbo.use()
        self.fbo.viewport = (0, 0, w, h)
        self.vao.render(vertices=3)
        # Image row 0 is GL row 0 (as eye.frag): the readback comes out top row first.
        out = np.frombuffer(self.fbo.read(components=4, dtype="f4"), "<f4").reshape(h, w, 4)
        return out.copy()

    def release(self) -> None:
        for o in (self.fbo, self.mask, self.vao, self.prog, *self.ubo):
            o.release()


@pytest.mark.gl
@pytest.mark.parametrize("eye", [320, 160])  # 160 px: the grain mask is mipmapped
def test_overlay_matches_vimsim_render(ctx, harness, overlay_glsl, export_dir, eye):
    """Grains, vignette and both, at three opacities, for an eye with roll: the translated HLSL
    core composited (premultiplied) over vimsim's unmitigated view equals vimsim's own
    render with the mitigation, PSNR >= 40 dB each (and the overlay is not empty)."""
    pano = _panorama()
    R = head_rotation(*POSE).as_matrix()
    plain = EyeRenderer(ctx, RenderConfig(eye_size=(eye, eye), hfov_deg=100, vfov_deg=90, grf=None,
                                          mitigation=Mitigation("none")))  # fmt: skip
    plain.upload(pano)
    base = np.array(plain.render(R)).astype(np.float64) / 255.0
    plain.release()
    overlay = None
    worst = math.inf
    try:
        for kind in ("grf", "vignette", "grf+vignette"):
            cfg = RenderConfig(eye_size=(eye, eye), hfov_deg=100, vfov_deg=90, grf=GRF,
                               mitigation=Mitigation(kind, **VIGNETTE))  # fmt: skip
            ref = EyeRenderer(ctx, cfg)
            ref.upload(pano)
            if overlay is None:  # the mask vimsim renders for this eye: its size and mip rule
                (tmp := export_dir.parent / f"mask{eye}").unlink(missing_ok=True)
                w, h = ref.grain_mask.size
                subprocess.run(["mono", str(harness), "mask", str(export_dir), str(w), str(tmp)], check=True)
                mask = np.fromfile(tmp, np.uint8).reshape(h, w)
                overlay = _Overlay(ctx, overlay_glsl, mask, bool(ref._defines["GRAIN_LOD"]), (eye, eye))
            for op in OPACITIES:
                want = np.array(ref.render(R, opacity=op))
                o = overlay.draw(R, kind, op, cfg)
                got = np.clip(base * (1 - o[..., 3:]) + o[..., :3], 0, 1) * 255
                got = np.floor(got + 0.5).astype(np.uint8)
                psnr = _psnr(got, want)
                assert psnr >= 40.0, (kind, op, psnr)
                # The overlay matters: without it the frames differ far more.
                plain_psnr = _psnr(np.floor(base * 255 + 0.5), want)
                assert o[..., 3].max() >= 0.5 * op and plain_psnr < psnr - 10, (kind, op, plain_psnr)
                worst = min(worst, psnr)
                print(f"eye {eye} {kind} opacity {op}: PSNR {psnr:.1f} dB (without the overlay {plain_psnr:.1f})")
            ref.release()
    finally:
        if overlay is not None:
            overlay.release()
    print(f"eye {eye}: worst PSNR {worst:.1f} dB")


@pytest.mark.gl
def test_grain_layout_and_mask_in_csharp_equal_vimsim(tmp_path, harness, export_dir, ctx):
    """The layout read by the C# runtime = the Python renderer's (1e-6 rad); the C# mask =
    vimsim's GL mask within one 8-bit step at almost every texel."""
    want = GrainField.from_config(GRF).centers
    got_py = read_grain_layout(export_dir).astype(np.float64)
    subprocess.run(["mono", str(harness), "grains", str(export_dir), str(tmp_path / "g")], check=True)
    got_cs = np.fromfile(tmp_path / "g", "<f4").reshape(-1, 3).astype(np.float64)
    for got in (got_py, got_cs):
        assert got.shape == want.shape
        ang = np.arccos(np.clip((got * want).sum(-1) / np.linalg.norm(got, axis=-1), -1, 1))
        assert ang.max() <= 1e-6, ang.max()
    r = EyeRenderer(ctx, RenderConfig(eye_size=(320, 320), hfov_deg=100, vfov_deg=90, grf=GRF))
    w, h = r.grain_mask.size
    gl = np.frombuffer(r.grain_mask.read(), np.uint8).reshape(h, w)
    r.release()
    subprocess.run(["mono", str(harness), "mask", str(export_dir), str(w), str(tmp_path / "m")], check=True)
    cs = np.fromfile(tmp_path / "m", np.uint8).reshape(h, w)
    diff = np.abs(cs.astype(int) - gl.astype(int))
    assert (diff > 1).mean() < 1e-4 and diff.max() <= 8, (diff.max(), (diff > 1).mean())
    assert 0.3 < (gl / 255.0).mean() < 0.5  # density 0.4 (sphere-mean, equirect-weighted)
