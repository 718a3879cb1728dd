"""A source whose spherical metadata carries an initial orientation (sv3d ``prhd``): the
export records it, and Python, the C# runtime (Mono) and the JS runtime (Chromium) turn the
head by it before every query, as ``vimsim epof`` does (view = R(orientation) R(head)); the
C# runtime's ApplyOrientation = false takes angles already in the video's frame."""

from __future__ import annotations

import struct
import subprocess

import numpy as np
import pytest
from media_helpers import with_pose

from simulator.cli import main
from simulator.epof.exact import shared_query
from simulator.export.unity import export_unity, frame_at
from simulator.export.web import export_web
from simulator.media.gridfile import load_grid, require_field
from simulator.media.spherical import view_angles_deg
from simulator.sphere.cells import Frustum

POSE = (30.0, 20.0, -10.0)


@pytest.fixture(scope="module")
def posed(tmp_path_factory):
    """Sphere-mode grids of the same forward-motion clip with and without the pose."""
    d = tmp_path_factory.mktemp("posexp")
    assert main(["synth", str(d / "plain.mp4"), "--scene", "forward", "--seconds", "0.5", "--fps",
                 "30", "--size", "128x64"]) == 0  # fmt: skip
    with_pose(d / "plain.mp4", d / "posed.mp4", *POSE)
    for name in ("plain", "posed"):
        assert main(["preprocess", str(d / f"{name}.mp4"), "-o", str(d / f"{name}.npz"), "--method",
                     "sphere", "--cell", "10", "--no-progress"]) == 0  # fmt: skip
    return d


def _queries(header):
    t0, fps = header["range"]["start_s"], header["fps"]
    n = header["range"]["end_frame"] - header["range"]["start_frame"]
    t = t0 + (np.arange(n) + 0.5) / fps
    rng = np.random.default_rng(4)
    return t, rng.uniform(-180, 180, n), rng.uniform(-60, 60, n), rng.uniform(-20, 20, n)


def _reference(grid, header, t, y, p, r, pose):
    field, cells = require_field(grid)
    vp = header["viewport"]
    q = shared_query(cells.cell_deg, Frustum.symmetric(vp["hfov_deg"], vp["vfov_deg"]))
    rows = frame_at(header, t) - int(header["start_frame"])
    vy, vpi, vr = view_angles_deg(pose, y, p, r)
    return q.many(np.asarray(field)[rows], vy, vpi, vr)


def test_export_records_the_orientation(posed, tmp_path):
    h = export_unity(posed / "posed.npz", tmp_path / "a").header
    assert h["source"]["orientation_deg"] == pytest.approx(list(POSE))
    assert "orientation_deg" not in export_unity(posed / "plain.npz", tmp_path / "b").header["source"]
    # the pose matters for this clip: the reference with and without it differ
    grid = load_grid(posed / "posed.npz")
    q = _queries(h)
    with_pose_ = _reference(grid, h, *q, POSE)
    without = _reference(grid, h, *q, None)
    assert np.median(np.abs(with_pose_ - without) / np.maximum(without, 1e-6)) > 0.05


def _run_cs(harness, folder, q, tmp_path):
    t, y, p, r = q
    n = len(t)
    rec = np.zeros(n, dtype=[("t", "<f8"), ("y", "<f4"), ("p", "<f4"), ("r", "<f4")])
    rec["t"], rec["y"], rec["p"], rec["r"] = t, y, p, r
    (tmp_path / "q").write_bytes(struct.pack("<i", n) + rec.tobytes())
    res = subprocess.run(["mono", str(harness), "covers", str(folder), str(tmp_path / "q"),
                          str(tmp_path / "o")], capture_output=True, text=True, check=False)  # fmt: skip
    assert res.returncode == 0, res.stdout + res.stderr
    return np.fromfile(tmp_path / "o", dtype=[("c", "<i4"), ("e", "<f4")])["e"]


def test_csharp_runtime_turns_the_head_by_the_orientation(posed, tmp_path, harness):
    grid = load_grid(posed / "posed.npz")
    h = export_unity(posed / "posed.npz", tmp_path / "x").header
    q = _queries(h)
    q32 = (q[0], *(np.float32(a).astype(float) for a in q[1:]))  # what the harness passes
    got = _run_cs(harness, tmp_path / "x", q, tmp_path)
    np.testing.assert_allclose(got, _reference(grid, h, *q32, POSE), rtol=1e-4, atol=1e-4)


_JS = """
const [[t, y, p, r]] = args;
const m = await import('./vimsim.js');
const rt = await m.loadExport('./');
const on = t.map((v, i) => rt.epof(v, y[i], p[i], r[i]));
const angles = rt.viewAngles(y[0], p[0], r[0]);
rt.applyOrientation = false;
const off = t.map((v, i) => rt.epof(v, y[i], p[i], r[i]));
return {on, off, angles, pose: rt.orientationDeg};
"""


@pytest.mark.browser
def test_js_runtime_turns_the_head_by_the_orientation(browser, posed, tmp_path):
    grid = load_grid(posed / "posed.npz")
    h = export_web(posed / "posed.npz", tmp_path / "w").header
    q = _queries(h)
    got = browser.run_served(tmp_path / "w", "example.html", _JS, [a.tolist() for a in q])
    assert got["pose"] == pytest.approx(list(POSE))
    np.testing.assert_allclose(got["on"], _reference(grid, h, *q, POSE), rtol=1e-4, atol=1e-4)
    np.testing.assert_allclose(got["off"], _reference(grid, h, *q, None), rtol=1e-4, atol=1e-4)
    want = [float(v[0]) for v in view_angles_deg(POSE, q[1][:1], q[2][:1], q[3][:1])]
    assert got["angles"] == pytest.approx(want, abs=1e-6)
