"""The cao2021-code rule in the exported C# (Mono) and JS (node) runtimes equals the Python rule
to 1e-7 (frames 0, 1, 2, past the end; the +-165..180 yaw wraps; the poles), read from the
folder ``vimsim export --format cao-csv`` writes, and from ``DIR/cao2021/`` of ``vimsim export
--format unity|web --preset cao2021-code`` (whose header records the preset)."""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from simulator.cli import main
from simulator.export.caocsv import window_file_name
from simulator.media.gridfile import load_grid
from simulator.mitigation.cao2021 import FixedPxRule, nearest_flow

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module", params=["cao-csv", "unity", "web"])
def exported(tmp_path_factory, request):
    """A 24 x 13 folder of 12 frames (random float32 values), imported and exported again
    (cao-csv: the folder itself; unity / web: the package's cao2021/ folder)."""
    d = tmp_path_factory.mktemp("cao")
    src = d / "src"
    src.mkdir()
    rng = np.random.default_rng(7)
    for p in range(-90, 91, 15):
        for y in range(-180, 180, 15):
            v = rng.uniform(0, 70, 12).astype(np.float32)
            rows = "".join(f"{t},{float(x)!r}\n" for t, x in enumerate(v))
            (src / window_file_name(y, p)).write_text(",0\n" + rows)
    assert main(["grid", "import", str(src), "-o", str(d / "g.npz"), "--fps", "30"]) == 0
    assert main(["export", str(d / "g.npz"), "--format", request.param, "--preset",
                 "cao2021-code", "-o", str(d / "out")]) == 0  # fmt: skip
    if request.param == "cao-csv":
        return load_grid(d / "g.npz"), d / "out"
    from simulator.export.unity import read_export

    h, _ = read_export(d / "out" / "vimsim_epof.bin")
    assert h["preset"]["name"] == "cao2021-code" and h["preset"]["folder"] == "cao2021"
    assert (h["preset"]["low_px"], h["preset"]["high_px"]) == (0.18, 53.73)
    assert h["grf"]["n_grains"] == 129_600  # their grains, in the file
    return load_grid(d / "g.npz"), d / "out" / "cao2021"


def _queries(n=2000, seed=3):
    rng = np.random.default_rng(seed)
    k = rng.integers(-1, 16, n)
    yaw = rng.uniform(-400, 400, n)
    pitch = rng.uniform(-90, 90, n)
    edge = np.array([165, 170, 179.999, 180, -180, -165, -170, -179.999, 7.5, -7.5, 352.5])
    yaw[: edge.size], k[: edge.size] = edge, 2
    pitch[edge.size : edge.size + 4] = [90, -90, 89.9, -89.9]
    k[-5:] = [0, 1, 2, 13, 14]  # 12 rows: frame 13 is the last row, 14 is past the list
    return k, yaw, pitch


def _python(grid, k, yaw, pitch):
    flow = nearest_flow(grid.pof_px, k, yaw, pitch, grid.yaw_deg, grid.pitch_deg)
    return flow, FixedPxRule()(flow)


def test_csharp_runtime_equals_python(exported, tmp_path):
    mcs, mono = shutil.which("mcs"), shutil.which("mono")
    if mcs is None or mono is None:
        pytest.skip("Mono (mcs, mono) not found; `make sysdeps` installs it")
    grid, out = exported
    exe = tmp_path / "cao.exe"
    r = subprocess.run([mcs, "-warnaserror+", f"-out:{exe}", str(out / "VimsimCao2021.cs"),
                        str(REPO / "tests/export/cs/Cao2021Harness.cs")],
                       capture_output=True, text=True, check=False)  # fmt: skip
    assert r.returncode == 0, r.stdout + r.stderr
    k, yaw, pitch = _queries()
    q = tmp_path / "q.txt"
    q.write_text("".join(f"{a} {b!r} {c!r}\n" for a, b, c in zip(k, yaw.tolist(), pitch.tolist())))
    r = subprocess.run([mono, str(exe), str(out), str(q), str(tmp_path / "r.txt")],
                       capture_output=True, text=True, check=False)  # fmt: skip
    assert r.returncode == 0, r.stdout + r.stderr
    got = np.loadtxt(tmp_path / "r.txt")
    flow, op = _python(grid, k, yaw, pitch)
    np.testing.assert_allclose(got[:, 0], flow, rtol=0, atol=1e-7)
    np.testing.assert_allclose(got[:, 1], op, rtol=0, atol=1e-7)
    assert np.all(got[k < 2, 0] == 0) and np.all(got[k > 13, 0] == 0)


_NODE = """
import { readFileSync, readdirSync } from "node:fs";
const [dir, qpath] = process.argv.slice(1);
const mod = await import(dir + "/vimsim_cao2021.js");
const files = {};
for (const n of readdirSync(dir)) if (n.endsWith(".csv")) files[n] = readFileSync(dir + "/" + n, "utf8");
const rt = new mod.Cao2021Runtime(files);
const q = JSON.parse(readFileSync(qpath, "utf8"));
const out = q.map(([k, y, p]) => [rt.flow(k, y, p), rt.opacity(k, y, p)]);
process.stdout.write(JSON.stringify(out));
"""


def test_js_runtime_equals_python(exported, tmp_path):
    node = shutil.which("node")
    if node is None:
        pytest.skip("node not found")
    grid, out = exported
    k, yaw, pitch = _queries(seed=4)
    q = tmp_path / "q.json"
    q.write_text(json.dumps([[int(a), float(b), float(c)] for a, b, c in zip(k, yaw, pitch)]))
    r = subprocess.run([node, "--input-type=module", "-e", _NODE, str(out.resolve()), str(q)],
                       capture_output=True, text=True, check=False)  # fmt: skip
    assert r.returncode == 0, r.stdout + r.stderr
    got = np.asarray(json.loads(r.stdout))
    flow, op = _python(grid, k, yaw, pitch)
    np.testing.assert_allclose(got[:, 0], flow, rtol=0, atol=1e-7)
    np.testing.assert_allclose(got[:, 1], op, rtol=0, atol=1e-7)


_BROWSER = """
const [names, q] = args;
const mod = await import(new URL("cao2021/vimsim_cao2021.js", location.href).href);
const files = {};
for (const n of names) files[n] = await (await fetch("cao2021/" + n)).text();
const rt = new mod.Cao2021Runtime(files);
return q.map(([k, y, p]) => [rt.flow(k, y, p), rt.opacity(k, y, p)]);
"""


@pytest.mark.browser
def test_web_export_rule_in_chromium_equals_python(browser, exported, tmp_path):
    """The web export's cao2021/ rule in Chromium, served beside example.html."""
    grid, folder = exported
    if folder.name != "cao2021" or not (folder.parent / "example.html").is_file():
        pytest.skip("the web export's folder only")
    k, yaw, pitch = _queries(n=500, seed=5)
    names = sorted(n.name for n in folder.glob("*.csv"))
    q = [[int(a), float(b), float(c)] for a, b, c in zip(k, yaw, pitch)]
    got = np.asarray(browser.run_served(folder.parent, "example.html", _BROWSER, names, q))
    flow, op = _python(grid, k, yaw, pitch)
    np.testing.assert_allclose(got[:, 0], flow, rtol=0, atol=1e-7)
    np.testing.assert_allclose(got[:, 1], op, rtol=0, atol=1e-7)
