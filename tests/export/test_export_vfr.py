"""A variable-rate video's export: the header carries the frames' times, and Python, the C#
runtime (Mono) and the JS runtime (Chromium) all show the frame whose time is the last at or
before the query, as ``vimsim epof`` rows are timed; ``floor(t * fps)`` would be off by the gaps."""

from __future__ import annotations

import struct
import subprocess

import numpy as np
import pytest

from simulator.cli import main
from simulator.epof.exact import shared_query
from simulator.export.unity import covers, export_unity, frame_at
from simulator.export.web import export_web
from simulator.media.gridfile import load_grid, require_field
from simulator.sphere.cells import Frustum
from simulator.testing.reference import ffmpeg_exe


@pytest.fixture(scope="module")
def vfr_grid(tmp_path_factory):
    """Frames 3.. of a 30 fps clip with every third frame dropped (times 0, 1/30, 3/30, ...)."""
    d = tmp_path_factory.mktemp("vfrexp")
    assert main(["synth", str(d / "r.mp4"), "--scene", "rotate", "--seconds", "1.2", "--fps", "30",
                 "--size", "128x64"]) == 0  # fmt: skip
    subprocess.run([ffmpeg_exe(), "-v", "error", "-y", "-i", str(d / "r.mp4"), "-vf",
                    "select='not(eq(mod(n\\,3)\\,2))'", "-fps_mode", "vfr", "-c:v", "libx264",
                    "-crf", "10", str(d / "vfr.mp4")], check=True)  # fmt: skip
    g = d / "g.npz"
    assert main(["preprocess", str(d / "vfr.mp4"), "-o", str(g), "--method", "sphere", "--cell",
                 "10", "--start", "0.1", "--no-progress"]) == 0  # fmt: skip
    return g


def _queries(grid):
    """Times: before the range, each frame's time, inside every interval (the gaps too), just
    before and at the range's end, far beyond; and the frame each shows."""
    t = np.asarray(grid.meta["frame_times_s"], float)
    fps = float(grid.fps)
    mid = (t[:-1] + t[1:]) / 2
    q = np.concatenate([[0.0, t[0] - 1e-3], t, mid, [t[-1] + 0.9 / fps, t[-1] + 1 / fps, 50.0]])
    start = int(grid.meta["start_frame"])
    want = np.concatenate([[start - 1, start - 1], start + np.arange(len(t)),
                           start + np.arange(len(mid)), [start + len(t) - 1, start + len(t)] * 1,
                           [start + len(t)]])  # fmt: skip
    return q, want


def _reference(grid, header, t):
    field, cells = require_field(grid)
    vp = header["viewport"]
    q = shared_query(cells.cell_deg, Frustum.symmetric(vp["hfov_deg"], vp["vfov_deg"]))
    rows = frame_at(header, t) - int(header["start_frame"])
    n = len(t)
    return q.many(np.asarray(field)[rows], np.full(n, 30.0), np.full(n, -10.0), np.full(n, 5.0))


def test_python_frame_rule_follows_the_frame_times(vfr_grid, tmp_path):
    grid = load_grid(vfr_grid)
    h = export_unity(vfr_grid, tmp_path / "x").header
    t = np.asarray(grid.meta["frame_times_s"], float)
    assert h["frame_times_s"] == pytest.approx(t.tolist()) and np.ptp(np.diff(t)) > 0.03  # gaps
    assert h["range"]["start_s"] == pytest.approx(t[0]) and h["range"]["end_s"] > t[-1]
    q, want = _queries(grid)
    s, e = h["range"]["start_frame"], h["range"]["end_frame"]
    np.testing.assert_array_equal(covers(h, q), (want >= s) & (want < e))
    np.testing.assert_array_equal(frame_at(h, q), np.clip(want, s, e - 1))
    cfr = np.floor(q * h["fps"] + 1e-6)  # what index / fps would show: off after the gaps
    assert (cfr != want).sum() > len(t) // 2


def test_csharp_runtime_follows_the_frame_times(vfr_grid, tmp_path, harness):
    grid = load_grid(vfr_grid)
    h = export_unity(vfr_grid, tmp_path / "x").header
    q, _ = _queries(grid)
    n = len(q)
    rec = np.zeros(n, dtype=[("t", "<f8"), ("y", "<f4"), ("p", "<f4"), ("r", "<f4")])
    rec["t"], rec["y"], rec["p"], rec["r"] = q, 30.0, -10.0, 5.0
    (tmp_path / "q").write_bytes(struct.pack("<i", n) + rec.tobytes())
    r = subprocess.run(["mono", str(harness), "covers", str(tmp_path / "x"), str(tmp_path / "q"),
                        str(tmp_path / "o")], capture_output=True, text=True, check=False)  # fmt: skip
    assert r.returncode == 0, r.stdout + r.stderr
    out = np.fromfile(tmp_path / "o", dtype=[("c", "<i4"), ("e", "<f4")])
    inside = covers(h, q)
    np.testing.assert_array_equal(out["c"].astype(bool), inside)
    ref = _reference(grid, h, q[inside])
    np.testing.assert_allclose(out["e"][inside], ref, rtol=1e-5)
    assert np.isnan(out["e"][~inside]).all()


_JS = """
const [times] = args;
const m = await import('./vimsim.js');
const rt = await m.loadExport('./');
return {covers: times.map((t) => rt.covers(t)), epof: times.map((t) => rt.epof(t, 30, -10, 5)),
        frames: times.map((t) => rt.frameAt(t)), range: rt.range,
        starts: [rt.frameTime(rt.range.startFrame), rt.frameTime(rt.range.endFrame - 1)]};
"""


@pytest.mark.browser
def test_js_runtime_follows_the_frame_times(browser, vfr_grid, tmp_path):
    grid = load_grid(vfr_grid)
    h = export_web(vfr_grid, tmp_path / "w").header
    q, _ = _queries(grid)
    got = browser.run_served(tmp_path / "w", "example.html", _JS, q.tolist())
    inside = covers(h, q)
    assert got["covers"] == inside.tolist()
    assert got["frames"] == frame_at(h, q).tolist()
    t = grid.meta["frame_times_s"]
    assert got["starts"] == pytest.approx([t[0], t[-1]])
    js = np.asarray([got["epof"][i] for i in np.flatnonzero(inside)])
    np.testing.assert_allclose(js, _reference(grid, h, q[inside]), rtol=1e-5)
    assert all(got["epof"][i] is None for i in np.flatnonzero(~inside))
