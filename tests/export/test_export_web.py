"""``vimsim export --format web``: the files (the Unity export's format-3 binary), the overlay
options, bad input, and the ES-module runtime in headless Chromium against the Python EPOF (1000
poses per mode), the exported range (NaN outside, as the C# runtime) and the stored grain layout."""

from __future__ import annotations

import json
import time

import numpy as np
import pytest

from simulator.cli import main
from simulator.epof.exact import shared_query
from simulator.epof.overlaps import epof_from_grid
from simulator.export.unity import VERSION, covers, frame_at, read_export, read_grain_layout
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


@pytest.fixture(scope="module")
def range_grid(grid_path):
    """A sphere-mode grid of frames 3..7 of the 10-frame clip (the source is longer)."""
    out = grid_path.parent / "range.npz"
    assert main(["preprocess", str(grid_path.parent / "clip.mp4"), "-o", str(out), "--method",
                 "sphere", "--window-size", "64", "--start", "0.3", "--end", "0.8",
                 "--no-progress"]) == 0  # fmt: skip
    return out


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
const edges = [rt.range.startS - 1e-3, rt.range.startS, rt.range.endS - 1e-3, rt.range.endS, -1, 1e6];
return {epof: out, us, mode: rt.mode, page, grains: {count: g.count, centres: Array.from(g.centres),
        config: g.config, expected: m.GrainLayout.grainCount(g.config.grain_deg, g.config.density)},
        edges, covers: edges.map((t) => rt.covers(t)), outside: edges.map((t) => rt.epof(t, 10, 5, 0)),
        range: rt.range, source: rt.source, mitigation: rt.mitigation, rule: [rt.opacityRule, rt.opacityScale],
        nanOpacity: [rt.opacity(NaN), rt.createEasing().update(NaN, 0.1)],
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
    # The grain layout stored in the file (float32), read bit for bit: the renderer's.
    gf = GrainField.from_config(GrfConfig())
    assert got["grains"]["count"] == len(gf.centers) == grain_count(GrfConfig())
    assert got["grains"]["expected"] == grain_count(GrfConfig())
    c = np.asarray(got["grains"]["centres"]).reshape(-1, 3)
    assert np.array_equal(c, read_grain_layout(res.out_dir).astype(np.float64))
    ang = np.arccos(np.clip(np.sum(c * gf.centers, 1) / np.linalg.norm(c, axis=1), -1, 1))
    assert ang.max() <= 1e-6, ang.max()
    cfg = got["grains"]["config"]
    assert (cfg["inner_deg"], cfg["outer_deg"], cfg["seed"]) == (18.0, 40.0, 0)
    assert got["mitigation"] == {"kind": "grf", "apertureMinDeg": 60.0, "featherDeg": 10.0,
                                 "color": [0.0, 0.0, 0.0]}  # fmt: skip
    # The exported range and the source's length: covered as covers() says; NaN outside.
    h = res.header
    assert got["covers"] == covers(h, np.asarray(got["edges"])).tolist() == [
        False, True, True, False, False, False]  # fmt: skip
    assert all(x is None for i, x in enumerate(got["outside"]) if not got["covers"][i])
    assert all(isinstance(x, float) for i, x in enumerate(got["outside"]) if got["covers"][i])
    assert got["range"]["endFrame"] == h["range"]["end_frame"] == grid.n_frames
    assert got["source"]["nFrames"] == h["source"]["n_frames"]
    assert got["nanOpacity"] == [None, None]  # NaN (JSON null)
    warnings = [c for c in browser.drain()[0] + console if "outside the export" in c["message"]]
    assert len(warnings) == 1, warnings  # once per runtime
    # The opacity rule (named as exported) and the comfort easing (OpacityRule.__call__ with fps).
    assert got["rule"] == ["comfort", "relative"]
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
    assert not (out / "vimsim_grains.bin").exists()  # the layout is in vimsim_epof.bin
    m = json.loads((out / "vimsim_web.json").read_text())
    assert m["mode"] == "paper" and m["overlaps"]["shape"][-1] == 24
    assert m["version"] == 2 and m["data_version"] == read_export(out)[0]["version"] == VERSION
    for n in ("vimsim.js", "vimsim_grains.js", "vimsim_gl.js", "example.html"):
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
@pytest.mark.parametrize("which", ["whole", "range"])
def test_web_data_file_is_the_unity_export(grid_path, range_grid, tmp_path, method, which):
    """vimsim_epof.bin of the web export (streamed from the grid for a float16 field) is
    byte for byte the Unity export's (format 3: range, source length, grain layout), for a
    grid of the whole clip and of a range of it."""
    from simulator.export.unity import export_unity

    grid = grid_path if which == "whole" else range_grid
    export_unity(grid, tmp_path / "u", method=method)
    res = export_web(grid, tmp_path / "w", method=method)
    a = (tmp_path / "u" / "vimsim_epof.bin").read_bytes()
    assert a == (tmp_path / "w" / "vimsim_epof.bin").read_bytes()
    h, data = read_export(tmp_path / "w")
    assert h == res.header and h["version"] == VERSION and data.shape[0] == h["n_frames"]
    start = 3 if which == "range" else 0
    assert (h["range"]["start_frame"], h["range"]["end_frame"]) == (start, start + h["n_frames"])
    assert h["source"]["n_frames"] == 10 and h["range"]["end_frame"] == (8 if start else 10)


@pytest.mark.browser
def test_example_from_the_file_system_says_to_serve_it(browser, grid_path, tmp_path):
    export_web(grid_path, tmp_path / "w", method="paper")
    browser.get((tmp_path / "w" / "example.html").as_uri())
    note = browser.driver.find_element("id", "note").text
    console, urls = browser.drain()
    assert "Serve this folder over http" in note
    assert not [c for c in console if c["level"] == "SEVERE"], console
    assert all(u.startswith(("file://", "data:")) for u in urls), urls


def test_web_export_takes_the_overlay_options(grid_path, tmp_path, capsys):
    """--format web takes --format unity's overlay options: the same settings and layout in the
    file; bad values are one line, exit 2, nothing written."""
    opts = ["--mitigation", "grf+vignette", "--grain-size", "3", "--density", "0.3", "--seed",
            "5", "--cutout", "10", "30", "--aperture-min", "50", "--feather", "8",
            "--vignette-color", "255,0,0", "--method", "paper"]  # fmt: skip
    for fmt in ("web", "unity"):
        assert main(["export", str(grid_path), "-o", str(tmp_path / fmt), "--format", fmt, *opts]) == 0
    assert "grf+vignette" in capsys.readouterr().out
    a = (tmp_path / "web" / "vimsim_epof.bin").read_bytes()
    assert a == (tmp_path / "unity" / "vimsim_epof.bin").read_bytes()
    h, _ = read_export(tmp_path / "web")
    assert h["mitigation"] == "grf+vignette" and h["vignette"]["color"] == [1.0, 0.0, 0.0]
    assert (h["grf"]["grain_deg"], h["grf"]["density"], h["grf"]["seed"]) == (3.0, 0.3, 5)
    assert (h["grf"]["inner_deg"], h["grf"]["outer_deg"]) == (10.0, 30.0)
    assert (h["vignette"]["aperture_min_deg"], h["vignette"]["feather_deg"]) == (50.0, 8.0)
    cfg = GrfConfig(grain_deg=3.0, density=0.3, seed=5, inner_deg=10.0, outer_deg=30.0)
    assert np.allclose(read_grain_layout(tmp_path / "web"), GrainField.from_config(cfg).centers, atol=1e-7)
    for bad, word in ((["--density", "1.5"], "--density"), (["--mitigation", "local-grf"], "local-grf"),
                      (["--cutout", "40", "18"], "--cutout")):  # fmt: skip
        assert main(["export", str(grid_path), "-o", str(tmp_path / "bad"), "--format", "web", *bad]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and word in err[0], err
        assert not (tmp_path / "bad").exists()


_JS_REFUSE = """
const m = await import('./vimsim.js');
const out = {};
for (const name of ['v2.bin', 'short.bin', 'density.bin', 'cutout.bin', 'vimsim_epof.bin']) {
  const buf = await (await fetch(name)).arrayBuffer();
  try { m.parseEpofBinary(buf, name); out[name] = 'ok'; } catch (e) { out[name] = e.message; }
}
try { await m.loadExport('old/'); out.old = 'ok'; } catch (e) { out.old = e.message; }
return out;
"""


@pytest.mark.browser
def test_js_refuses_old_and_bad_files(browser, grid_path, tmp_path):
    """The JS runtime reads format 3 only: a format-2 file (made before the grain layout) is
    refused with the fix; a truncated layout, a bad density and cutout radii in the wrong order
    are refused naming the field (as read_export and the C# loader)."""
    import struct

    d = tmp_path / "w"
    export_web(grid_path, d, method="sphere")
    good = (d / "vimsim_epof.bin").read_bytes()
    (d / "v2.bin").write_bytes(good[:8] + struct.pack("<I", 2) + good[12:])
    (d / "short.bin").write_bytes(good[:-12])

    def edited(old: bytes, new: bytes) -> bytes:
        assert good.count(old) == 1 and len(old) == len(new)
        return good.replace(old, new)

    (d / "old").mkdir()
    m = json.loads((d / "vimsim_web.json").read_text())
    (d / "old" / "vimsim_web.json").write_text(json.dumps({**m, "version": 1}))
    (d / "density.bin").write_bytes(edited(b'"density": 0.5', b'"density": 1.5'))
    (d / "cutout.bin").write_bytes(edited(b'"inner_deg": 18.0', b'"inner_deg": 48.0'))
    got = browser.run_served(d, "example.html", _JS_REFUSE)
    assert "version 2" in got["v2.bin"] and "export again" in got["v2.bin"], got
    assert "grain layout" in got["short.bin"], got
    assert "grf.density" in got["density.bin"] and "export again" in got["density.bin"], got
    assert "grf.inner_deg/outer_deg" in got["cutout.bin"], got
    assert got["vimsim_epof.bin"] == "ok"
    assert "version 1" in got["old"] and "export again" in got["old"], got


_JS_RANGE = """
const [times] = args;
const m = await import('./vimsim.js');
const rt = await m.loadExport('./');
return {covers: times.map((t) => rt.covers(t)), epof: times.map((t) => rt.epof(t, 30, -10, 5)),
        frames: times.map((t) => rt.frameAt(t)), range: rt.range, source: rt.source};
"""


@pytest.mark.browser
def test_js_range_of_a_partial_export(browser, range_grid, tmp_path):
    """An export of frames 3..7 of a 10-frame video: the JS runtime covers exactly those frames
    (as Python's covers), gives the Python EPOF inside and NaN before and after (within the
    source and beyond it), and knows the source's length."""
    res = export_web(range_grid, tmp_path / "w")
    h = res.header
    fps = h["fps"]
    times = np.array([0.0, 2.9, 3.0, 5.5, 7.999, 8.0, 9.5, 10.0, 1e6]) / fps
    got = browser.run_served(tmp_path / "w", "example.html", _JS_RANGE, times.tolist())
    inside = covers(h, times)
    assert got["covers"] == inside.tolist() == [False, False, True, True, True] + [False] * 4
    assert got["range"] == {"startFrame": 3, "endFrame": 8, "startS": 3 / fps, "endS": 8 / fps}
    assert got["source"] == {"nFrames": 10, "durationS": 10 / fps, "known": True}
    assert all(got["epof"][i] is None for i in np.flatnonzero(~inside))
    grid = load_grid(range_grid)
    poses = np.column_stack([times, np.full(9, 30.0), np.full(9, -10.0), np.full(9, 5.0)])[inside]
    ref = _reference(grid, h, poses)
    js = np.asarray([got["epof"][i] for i in np.flatnonzero(inside)])
    assert np.allclose(js, ref, rtol=1e-5), (js, ref)
    assert got["frames"][:3] == [3, 3, 3] and got["frames"][-1] == 7  # frameAt clamps
