"""The web runtime's drawing in headless Chromium against vimsim's renderer: the grain layout
from the seed, the grain coverage mask, and ``EyeRenderer`` vs ``vimsim frames`` for every
mitigation (same equirect image, same pose, same opacity)."""

from __future__ import annotations

import base64
import io
import math
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from simulator.export.web import JS_FILES, js_source
from simulator.mitigation.grf import GrainField, GrfConfig
from simulator.report.serve import start_server

EYE = (200, 150)
PANO = Path(__file__).resolve().parents[2] / "simulator" / "data" / "panorama.jpg"


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    d = tmp_path_factory.mktemp("webgl")
    for n in (*JS_FILES, "example.html"):
        (d / n).write_bytes(js_source(n))
    Image.open(PANO).convert("RGB").resize((512, 256), Image.LANCZOS).save(d / "pano.png")
    srv = start_server(d)
    yield d, srv
    srv.close()


_SEED = """
const [cfg] = args;
const m = await import('./vimsim.js');
const g = m.GrainLayout.fromSeed(cfg);
return {z: Array.from(g.draws.z.slice(0, 50)), lon: Array.from(g.draws.lon.slice(-50)),
        centres: Array.from(g.centres), count: g.count};
"""


@pytest.mark.browser
@pytest.mark.parametrize("cfg", [GrfConfig(), GrfConfig(grain_deg=3.0, density=0.3, seed=12345)])
def test_grain_layout_from_seed(browser, site, cfg):
    _, srv = site
    browser.get(srv.url + "example.html")
    got = browser.run_async(_SEED, {"grain_deg": cfg.grain_deg, "density": cfg.density,
                                    "inner_deg": cfg.inner_deg, "outer_deg": cfg.outer_deg,
                                    "seed": cfg.seed})  # fmt: skip
    ref = GrainField.from_config(cfg).centers
    rng = np.random.default_rng(cfg.seed)
    z = rng.uniform(-1.0, 1.0, len(ref))
    lon = rng.uniform(-math.pi, math.pi, len(ref))
    assert got["count"] == len(ref)
    assert (
        got["z"] == z[:50].tolist() and got["lon"] == lon[-50:].tolist()
    )  # numpy's draws, bit for bit
    c = np.asarray(got["centres"]).reshape(-1, 3)
    assert np.abs(c - ref).max() <= 1e-15  # sin/cos of two libms: an ulp at most


_MASK = """
const [cfg, w] = args;
const m = await import('./vimsim.js');
return Array.from(m.GrainLayout.fromSeed(cfg).coverageMask(w));
"""


@pytest.mark.browser
@pytest.mark.gl
def test_coverage_mask_matches_the_renderer(browser, site, ctx):
    from simulator.render.eye import _grain_mask

    _, srv = site
    cfg = GrfConfig()
    # Eye pixels of 2 pi / 1024 rad: the renderer's mask is 1024 x 512, level 0 (no mips).
    tex, lod = _grain_mask(ctx, cfg, 2 * math.pi / 1024, ctx.detect_framebuffer(0))
    assert not lod
    ref = np.frombuffer(tex.read(), np.uint8).reshape(tex.size[1], tex.size[0])
    tex.release()
    browser.get(srv.url + "example.html")
    js = np.asarray(browser.run_async(_MASK, {"grain_deg": 1.5, "density": 0.5, "inner_deg": 18,
                                              "outer_deg": 40, "seed": 0}, ref.shape[1]), np.uint8)  # fmt: skip
    js = js.reshape(ref.shape)
    diff = np.abs(js.astype(int) - ref.astype(int))
    print(f"\ncoverage mask {ref.shape[1]}x{ref.shape[0]}: max diff {diff.max()} levels, "
          f"{(diff > 0).mean():.2%} texels differ; blocked {ref.mean() / 255:.3f} (renderer) "
          f"{js.mean() / 255:.3f} (JS)")  # fmt: skip
    assert diff.max() <= 1 and (diff > 0).mean() < 0.01


_DRAW = """
const [opts, pose] = args;
const m = await import('./vimsim.js');
const gl_ = await import('./vimsim_gl.js');
const img = new Image(); img.src = 'pano.png'; await img.decode();
const canvas = document.createElement('canvas');
canvas.width = opts.width; canvas.height = opts.height;
const gl = canvas.getContext('webgl2', {preserveDrawingBuffer: true, antialias: false});
const grains = m.GrainLayout.fromSeed({grain_deg: 1.5, density: 0.5, inner_deg: 18, outer_deg: 40, seed: 0});
const eye = new gl_.EyeRenderer(gl, {...opts, grains});
eye.upload(img);
eye.render(pose[0], pose[1], pose[2], pose[3]);
return canvas.toDataURL('image/png');
"""


def _psnr(a: np.ndarray, b: np.ndarray) -> float:
    mse = float(np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2))
    return 99.0 if mse == 0 else 10 * np.log10(255.0**2 / mse)


CASES = [("grf", (179.0, 20.0, 15.0)), ("grf", (-30.0, 85.0, -40.0)),
         ("vignette", (179.0, 20.0, 15.0)), ("grf+vignette", (10.0, -30.0, 5.0)),
         ("none", (-179.5, 0.0, 0.0))]  # fmt: skip

_DRAW_ALL = (
    """
const [cases] = args;
const out = [];
for (const [opts, pose] of cases) out.push(await (async () => {"""
    + _DRAW.replace("const [opts, pose] = args;", "")
    + """})());
return out;
"""
)


@pytest.mark.browser
@pytest.mark.gl
def test_eye_renderer_matches_vimsim_renderer(browser, site, ctx):
    """The same image, pose and opacity through vimsim's renderer (what vimsim frames and
    render draw: ``simulator.render.eye``) and through vimsim_gl.js, for every mitigation,
    with roll, at the seam and near a pole."""
    from simulator.mitigation.kinds import Mitigation
    from simulator.render.eye import RenderConfig, render_view

    d, srv = site
    opacity = 0.7
    img = np.asarray(Image.open(d / "pano.png").convert("RGB"))
    cases, refs = [], []
    for kind, pose in CASES:
        cfg = RenderConfig(eye_size=EYE, hfov_deg=100, vfov_deg=80, grf=GrfConfig(),
                           mitigation=Mitigation(kind))  # fmt: skip
        refs.append(render_view(ctx, img, *pose, config=cfg, opacity=opacity))
        opts = {"width": EYE[0], "height": EYE[1], "hfovDeg": 100, "vfovDeg": 80,
                "mitigation": {"kind": kind, "apertureMinDeg": 60, "featherDeg": 10,
                               "color": [0, 0, 0]}}  # fmt: skip
        cases.append([opts, [*pose, opacity]])
    browser.get(srv.url + "example.html")
    urls = browser.run_async(_DRAW_ALL, cases)
    scores = []
    for (kind, pose), ref, url in zip(CASES, refs, urls):
        js = np.asarray(
            Image.open(io.BytesIO(base64.b64decode(url.split(",", 1)[1]))).convert("RGB")
        )
        scores.append(_psnr(js, ref))
        print(f"\n{kind} at {pose}: EyeRenderer vs vimsim's renderer PSNR {scores[-1]:.1f} dB")
    assert min(scores) >= 30.0, scores


_QUAT = """
const [qs] = args;
const m = await import('./vimsim.js');
return qs.map((q) => m.headRotation(...m.anglesFromQuaternion({x: q[0], y: q[1], z: q[2], w: q[3]})));
"""


@pytest.mark.browser
def test_angles_from_a_minus_z_forward_quaternion(browser, site):
    """three.js / WebXR orientation -> vimsim angles: the view axis and the up vector equal the
    quaternion's, mirrored in z (the video's centre at the frame's -z)."""
    from scipy.spatial.transform import Rotation

    _, srv = site
    rng = np.random.default_rng(3)
    q = Rotation.random(200, random_state=rng)
    browser.get(srv.url + "example.html")
    got = np.asarray(browser.run_async(_QUAT, q.as_quat().tolist())).reshape(-1, 3, 3)
    fwd, up = q.apply([0.0, 0.0, -1.0]), q.apply([0.0, 1.0, 0.0])
    flip = np.array([1.0, 1.0, -1.0])
    assert np.allclose(got[:, :, 2], fwd * flip, atol=1e-9)
    assert np.allclose(got[:, :, 1], up * flip, atol=1e-9)


_OVERLAY = """
const [opts, pose, grey] = args;
const m = await import('./vimsim.js');
const gl_ = await import('./vimsim_gl.js');
const canvas = document.createElement('canvas');
canvas.width = opts.width; canvas.height = opts.height;
const gl = canvas.getContext('webgl2', {preserveDrawingBuffer: true, antialias: false});
const grains = m.GrainLayout.fromSeed({grain_deg: 1.5, density: 0.5, inner_deg: 18, outer_deg: 40, seed: 0});
const eye = new gl_.EyeRenderer(gl, {...opts, grains, video: false});
gl.clearColor(grey, grey, grey, 1); gl.clear(gl.COLOR_BUFFER_BIT);
eye.render(pose[0], pose[1], pose[2], pose[3]);
return canvas.toDataURL('image/png');
"""


@pytest.mark.browser
@pytest.mark.gl
@pytest.mark.parametrize("kind", ["grf", "grf+vignette"])
def test_overlay_over_a_scene_matches_the_renderer(browser, site, ctx, kind):
    """The overlay alone (video: false, premultiplied, blended over what is drawn) over a
    uniform grey scene = vimsim's renderer on a uniform grey panorama."""
    from simulator.mitigation.kinds import Mitigation
    from simulator.render.eye import RenderConfig, render_view

    _, srv = site
    grey, pose, opacity = 120, (40.0, 10.0, -20.0), 0.8
    img = np.full((256, 512, 3), grey, np.uint8)
    cfg = RenderConfig(eye_size=EYE, hfov_deg=100, vfov_deg=80, grf=GrfConfig(),
                       mitigation=Mitigation(kind))  # fmt: skip
    ref = render_view(ctx, img, *pose, config=cfg, opacity=opacity)
    opts = {"width": EYE[0], "height": EYE[1], "hfovDeg": 100, "vfovDeg": 80,
            "mitigation": {"kind": kind, "apertureMinDeg": 60, "featherDeg": 10, "color": [0, 0, 0]}}  # fmt: skip
    browser.get(srv.url + "example.html")
    url = browser.run_async(_OVERLAY, opts, [*pose, opacity], grey / 255)
    js = np.asarray(Image.open(io.BytesIO(base64.b64decode(url.split(",", 1)[1]))).convert("RGB"))
    assert (ref < grey - 30).mean() > 0.05  # grains (and the vignette) are drawn
    assert _psnr(js, ref) >= 40.0, _psnr(js, ref)
