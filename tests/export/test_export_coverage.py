"""A source that does not cover the sphere (VR180, ``hequirect``) exported: the runtimes
give ``vimsim epof``'s EPOF, the covered part of the viewport's mean faded below a quarter
covered (Python's reference, Mono's C# runtime and Chromium's JS runtime agree), not the
plain viewport mean that counts the black half as still; a paper-mode export of it is
refused in one line."""

from __future__ import annotations

import struct
import subprocess

import numpy as np
import pytest

from simulator.cli import main
from simulator.epof.viewing import compute_epof
from simulator.export.unity import export_unity
from simulator.export.web import export_web
from simulator.media.gridfile import load_grid
from simulator.testing.reference import ffmpeg_exe
from simulator.traces.path import HeadPath


@pytest.fixture(scope="module")
def vr180(tmp_path_factory):
    d = tmp_path_factory.mktemp("covexp")
    assert main(["synth", str(d / "r.mp4"), "--scene", "forward", "--seconds", "1", "--fps", "10",
                 "--size", "128x64"]) == 0  # fmt: skip
    subprocess.run([ffmpeg_exe(), "-v", "error", "-y", "-i", str(d / "r.mp4"), "-vf",
                    "v360=e:hequirect:w=64:h=64", "-c:v", "libx264", "-crf", "10", str(d / "h.mp4")],
                   check=True)  # fmt: skip
    for method in ("sphere", "paper"):
        assert main(["preprocess", str(d / "h.mp4"), "-o", str(d / f"{method}.npz"), "--method",
                     method, "--projection", "hequirect", "--window-size", "32", "--cell", "10",
                     "--no-progress"]) == 0  # fmt: skip
    return d


def _viewing(grid):
    """vimsim epof along a head path that looks ahead, to the sides, behind and up."""
    t = np.asarray(grid.meta.get("frame_times_s") or
                   (np.arange(grid.n_frames) + grid.meta["start_frame"]) / grid.fps, float)  # fmt: skip
    n = len(t)
    yaw = np.resize([0.0, 70.0, -85.0, 180.0, 110.0, 30.0, -60.0], n)
    pitch = np.resize([0.0, 10.0, -20.0, 0.0, 45.0, 80.0, -5.0], n)
    roll = np.resize([0.0, 5.0, 0.0, -10.0, 0.0, 0.0, 20.0], n)
    r = compute_epof(grid, HeadPath.from_angles_deg(t, yaw, pitch, roll), hold=True)
    return r


def test_reference_is_the_covered_mean(vr180):
    r = _viewing(load_grid(vr180 / "sphere.npz"))
    cov = np.asarray(r.coverage)
    assert cov.min() < 0.05 and cov.max() > 0.95 and ((cov > 0.3) & (cov < 0.8)).any()


def test_csharp_runtime_gives_vimsims_covered_epof(vr180, tmp_path, harness):
    grid = load_grid(vr180 / "sphere.npz")
    h = export_unity(vr180 / "sphere.npz", tmp_path / "x").header
    assert len(h["coverage"]["cells"]) == h["field"]["n_lat"] * h["field"]["n_lon"]
    r = _viewing(grid)
    n = len(r.time_s)
    rec = np.zeros(n, dtype=[("t", "<f8"), ("y", "<f4"), ("p", "<f4"), ("r", "<f4")])
    rec["t"], rec["y"], rec["p"], rec["r"] = r.time_s, r.yaw_deg, r.pitch_deg, r.roll_deg
    (tmp_path / "q").write_bytes(struct.pack("<i", n) + rec.tobytes())
    res = subprocess.run(["mono", str(harness), "covers", str(tmp_path / "x"), str(tmp_path / "q"),
                          str(tmp_path / "o")], capture_output=True, text=True, check=False)  # fmt: skip
    assert res.returncode == 0, res.stdout + res.stderr
    got = np.fromfile(tmp_path / "o", dtype=[("c", "<i4"), ("e", "<f4")])["e"]
    want = _viewing_at(grid, rec)
    np.testing.assert_allclose(got, want, rtol=1e-4, atol=1e-3)


def _viewing_at(grid, rec):
    """vimsim's EPOF at the harness's float32 angles (what the C# runtime was given)."""
    hp = HeadPath.from_angles_deg(rec["t"], rec["y"].astype(float), rec["p"].astype(float),
                                  rec["r"].astype(float))  # fmt: skip
    return np.asarray(compute_epof(grid, hp, hold=True).epof_dps)


_JS = """
const [[t, y, p, r]] = args;
const m = await import('./vimsim.js');
const rt = await m.loadExport('./');
return {epof: t.map((v, i) => rt.epof(v, y[i], p[i], r[i])),
        coverage: t.map((v, i) => rt.coverage(y[i], p[i], r[i]))};
"""


@pytest.mark.browser
def test_js_runtime_gives_vimsims_covered_epof(browser, vr180, tmp_path):
    grid = load_grid(vr180 / "sphere.npz")
    export_web(vr180 / "sphere.npz", tmp_path / "w")
    r = _viewing(grid)
    q = [np.asarray(a, float).tolist() for a in (r.time_s, r.yaw_deg, r.pitch_deg, r.roll_deg)]
    got = browser.run_served(tmp_path / "w", "example.html", _JS, q)
    np.testing.assert_allclose(got["epof"], r.epof_dps, rtol=1e-4, atol=1e-3)
    np.testing.assert_allclose(got["coverage"], r.coverage, rtol=1e-4, atol=1e-4)
    plain = np.asarray(got["epof"]) * np.asarray(got["coverage"])  # about what counting black gives
    assert np.abs(plain - r.epof_dps).max() > 0.2 * np.max(r.epof_dps)


def test_paper_mode_export_of_a_partial_source_is_refused(vr180, tmp_path, capsys):
    assert main(["export", str(vr180 / "paper.npz"), "-o", str(tmp_path / "p")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "does not cover the sphere" in err[0] and "sphere-mode" in err[0]
    assert not (tmp_path / "p").exists()
