"""``vimsim export --format web``: the files, bad input, and the ES-module runtime in headless
Chromium against the Python EPOF (1000 poses per mode) and the renderer's grain layout."""

from __future__ import annotations

import json
import time

import numpy as np
import pytest

from simulator.cli import main
from simulator.epof.exact import shared_query
from simulator.epof.overlaps import epof_from_grid
from simulator.export.unity import frame_at
from simulator.export.web import WEB_FILES, export_web
from simulator.media.gridfile import load_grid, require_field
from simulator.mitigation.grf import GrainField, GrfConfig, grain_count
from simulator.sphere.cells import Frustum


@pytest.fixture(scope="module")
def grid_path(tmp_path_factory):
    """A small sphere-mode grid (it has the window matrix too: both modes export from it)."""
    from simulator.synth import SynthConfig, synthesize

    d = tmp_path_factory.mktemp("webexp")
    synthesize(SynthConfig("coaster", seconds=1.0, fps=10, size=(128, 64)), d / "clip.mp4")
    assert main(["preprocess", str(d / "clip.mp4"), "-o", str(d / "grid.npz"), "--method",
                 "sphere", "--window-size", "64", "--no-progress"]) == 0  # fmt: skip
    return d / "grid.npz"


def _poses(n: int, seed: int, T: int, fps: float) -> np.ndarray:
    """time, yaw, pitch, roll: random with roll, plus the seam, the poles, between frames."""
    rng = np.random.default_rng(seed)
    t = rng.uniform(0, T / fps, n)
    yaw = rng.uniform(-540, 540, n)
    pitch = rng.uniform(-90, 90, n)
    roll = rng.uniform(-180, 180, n)
    k = n // 10
    yaw[:k] = rng.choice([-180.0, 180.0, 179.999, -179.999], k)  # the seam
    pitch[k : 2 * k] = rng.choice([-90.0, 90.0, 89.99, -89.99], k)  # the poles
    t[2 * k : 3 * k] = (rng.integers(0, T - 1, k) + rng.uniform(0.1, 0.9, k)) / fps  # between
    t[3 * k : 4 * k] = np.arange(k) % T / fps  # exact frame times
    return np.column_stack([t, yaw, pitch, roll])


def _reference(grid, header, poses: np.ndarray) -> np.ndarray:
    frames = frame_at(header, poses[:, 0]) - int(header["start_frame"])
    y, p, r = poses[:, 1], poses[:, 2], poses[:, 3]
    if header["mode"] == "paper":
        return epof_from_grid(grid, y, p, r, frames)
    field, cells = require_field(grid)
    vp = header["viewport"]
    q = shared_query(cells.cell_deg, Frustum.symmetric(vp["hfov_deg"], vp["vfov_deg"]))
    return q.many(np.asarray(field)[frames], y, p, r)


_JS_EPOF = """
const [poses] = args;
for (let i = 0; i < 200 && document.getElementById('epof').textContent === '-'; i++)
  await new Promise((r) => setTimeout(r, 25));   // example.html has drawn (or said why not)
const page = {note: document.getElementById('note').textContent, epof: document.getElementById('epof').textContent};
const m = await import('./vimsim.js');
const rt = await m.loadExport('./');
const out = poses.map((q) => rt.epof(q[0], q[1], q[2], q[3]));
const t0 = performance.now();
let n = 0, s = 0;
while (performance.now() - t0 < 150) { for (const q of poses) { s += rt.epof(q[0], q[1], q[2], q[3]); n++; } }
const us = (performance.now() - t0) * 1000 / n;
const g = rt.grains;
return {epof: out, us, mode: rt.mode, page, grains: {count: g.count, first: Array.from(g.centres.slice(0, 6)),
        last: Array.from(g.centres.slice(-3)), expected: m.GrainLayout.grainCount(g.config.grain_deg, g.config.density)},
        opacity: [rt.opacity(rt.lowDps), rt.opacity(rt.highDps), rt.opacity((rt.lowDps + rt.highDps) / 2)],
        eased: (() => { const e = rt.createEasing(); return [0, 1, 1, 1, 0, 0].map((x) => e.step(x)); })()};
"""


@pytest.mark.browser
@pytest.mark.parametrize("mode", ["paper", "sphere"])
def test_js_epof_matches_python(browser, grid_path, tmp_path, mode):
    from simulator.mitigation.grf import comfort_rule

    res = export_web(grid_path, tmp_path / mode, method=mode, rule=comfort_rule())
    grid = load_grid(grid_path)
    poses = _poses(1000, 7, grid.n_frames, grid.fps)
    ref = _reference(grid, res.header, poses)
    from simulator.report.serve import start_server

    srv = start_server(tmp_path / mode)
    try:
        browser.get(srv.url + "example.html")
        got = browser.run_async(_JS_EPOF, poses.tolist())
        console, urls = browser.drain()
    finally:
        srv.close()
    js = np.asarray(got["epof"])
    rel = np.abs(js - ref) / np.maximum(np.abs(ref), 1e-9)
    assert got["mode"] == mode
    assert got["page"]["note"] == "" and float(got["page"]["epof"]) >= 0, got[
        "page"
    ]  # example.html drew
    assert rel.max() <= 1e-5, f"{mode}: max rel diff {rel.max():.3g} at {poses[rel.argmax()]}"
    print(f"\n{mode}: JS EPOF max rel diff {rel.max():.2g}, {got['us']:.1f} us per call "
          f"({browser.gl_renderer()})")  # fmt: skip
    # The renderer's grain layout, read and counted alike.
    gf = GrainField.from_config(GrfConfig())
    assert got["grains"]["count"] == len(gf.centers) == grain_count(GrfConfig())
    assert got["grains"]["expected"] == grain_count(GrfConfig())
    assert np.array_equal(got["grains"]["first"], gf.centers[:2].ravel())
    assert np.array_equal(got["grains"]["last"], gf.centers[-1])
    # The opacity rule and the comfort easing (python: OpacityRule.__call__ with fps).
    assert np.allclose(got["opacity"], [0, 1, 0.5], atol=1e-12)
    lo, hi = res.header["opacity"]["low_dps"], res.header["opacity"]["high_dps"]
    rule = comfort_rule()
    x = np.array([0, 1, 1, 1, 0, 0], float) * (hi - lo) + lo
    assert np.allclose(got["eased"], rule(x, (lo, hi), fps=grid.fps), atol=1e-12)
    assert not [c for c in console if c["level"] == "SEVERE"], console
    assert all(u.startswith(srv.url) for u in urls), urls


def test_export_web_files_and_cli(grid_path, tmp_path, capsys):
    out = tmp_path / "w"
    assert main(["export", str(grid_path), "-o", str(out), "--format", "web", "--method",
                 "paper"]) == 0  # fmt: skip
    assert "vimsim_overlaps.bin" in capsys.readouterr().out
    assert {p.name for p in out.iterdir()} >= set(WEB_FILES)
    m = json.loads((out / "vimsim_web.json").read_text())
    assert m["mode"] == "paper" and m["overlaps"]["shape"][-1] == 24
    for n in ("vimsim.js", "vimsim_gl.js", "example.html"):
        assert "vimsim export" in (out / n).read_text().splitlines()[0]
    # Rerun over our own files: fine; a file we did not write: refused, nothing written.
    assert main(["export", str(grid_path), "-o", str(out), "--format", "web"]) == 0
    (tmp_path / "x").mkdir()
    (tmp_path / "x" / "vimsim.js").write_text("mine")
    before = sorted(p.name for p in (tmp_path / "x").iterdir())
    assert main(["export", str(grid_path), "-o", str(tmp_path / "x"), "--format", "web"]) == 2
    assert sorted(p.name for p in (tmp_path / "x").iterdir()) == before
    assert "was not written by vimsim" in capsys.readouterr().err


def test_export_unknown_format(grid_path, tmp_path, capsys):
    t0 = time.monotonic()
    with pytest.raises(SystemExit) as e:
        main(["export", str(grid_path), "-o", str(tmp_path / "o"), "--format", "webgl"])
    assert e.value.code == 2 and time.monotonic() - t0 < 5
    err = capsys.readouterr().err.strip().splitlines()
    assert "--format" in err[-1] and "invalid choice" in err[-1]
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("method", ["auto", "paper"])
def test_web_data_file_is_the_unity_export(grid_path, tmp_path, method):
    """vimsim_epof.bin of the web export (streamed from the grid for a float16 field) is
    byte for byte the Unity export's."""
    from simulator.export.unity import export_unity

    export_unity(grid_path, tmp_path / "u", method=method)
    export_web(grid_path, tmp_path / "w", method=method)
    a = (tmp_path / "u" / "vimsim_epof.bin").read_bytes()
    assert a == (tmp_path / "w" / "vimsim_epof.bin").read_bytes()


@pytest.mark.browser
def test_example_from_the_file_system_says_to_serve_it(browser, grid_path, tmp_path):
    export_web(grid_path, tmp_path / "w", method="paper")
    browser.get((tmp_path / "w" / "example.html").as_uri())
    note = browser.driver.find_element("id", "note").text
    console, urls = browser.drain()
    assert "Serve this folder over http" in note
    assert not [c for c in console if c["level"] == "SEVERE"], console
    assert all(u.startswith(("file://", "data:")) for u in urls), urls
