"""The exported C# runtime's playback side (Mono): the opacity stepped once per video frame from a
player's frames equals ``vimsim epof``'s opacity column; times outside the exported range are
flagged; bad GRF settings and old exports are refused naming the field or the fix, in C# and
in Python (one line, exit 2)."""

from __future__ import annotations

import json
import struct
import subprocess
from pathlib import Path

import numpy as np
import pytest

from simulator.cli import main
from simulator.core.errors import InputError
from simulator.epof import read_epof_csv
from simulator.export import DATA_FILE, export_unity, read_export
from simulator.export.unity import covers, read_grain_layout
from simulator.export.unity.binary import pack
from simulator.media.gridfile import save_grid
from simulator.preprocess import SphereConfig, field_meta
from simulator.sphere.windows import grid_preset


def _sphere_grid(path: Path, T: int, start_frame: int, fps: float = 30.0) -> Path:
    g = grid_preset("default")
    rng = np.random.default_rng(5)
    i = np.arange(45)[None, :, None] / 45
    j = np.arange(90)[None, None, :] / 90
    t = np.arange(T)[:, None, None] / fps
    field = 36 + 18 * np.sin(2 * np.pi * (j + 0.3 * t)) * np.cos(np.pi * i) + 14 * np.cos(2 * t)
    field = (field + 4 * rng.random((T, 45, 90))).astype(np.float16)
    pof = np.full((T, *g.shape), 30.0, np.float32) + rng.random((T, *g.shape)).astype(np.float32)
    meta = {"fps": fps, "n_frames": T, "start_frame": start_frame, "flow": {"method": "test"},
            "layout": "mono", "eye": "left", "method": "sphere", "field": field_meta(SphereConfig()),
            "video": {"path": "v.mp4", "content_hash": "sha256:ab", "n_frames": start_frame + T + 30}}  # fmt: skip
    save_grid(path, pof, pof / 10, g, meta, field_dps=field)
    return path


def _queries(path: Path, t, yaw, pitch, roll) -> Path:
    rec = np.zeros(len(t), dtype=[("t", "<f8"), ("y", "<f4"), ("p", "<f4"), ("r", "<f4")])
    rec["t"], rec["y"], rec["p"], rec["r"] = t, yaw, pitch, roll
    path.write_bytes(struct.pack("<i", len(t)) + rec.tobytes())
    return path


def _mono(exe, *args, check=True):
    r = subprocess.run(["mono", str(exe), *map(str, args)], capture_output=True, text=True, check=False)
    if check:
        assert r.returncode == 0, r.stdout + r.stderr
    return r


def test_clock_steps_once_per_video_frame_as_vimsim_epof(tmp_path, harness):
    """A player at 30 fps rendered at 90 Hz: each video frame is seen three times (the later
    two with other head poses: held). The clock's eased opacity at each frame equals vimsim
    epof's default (absolute) opacity column within 1e-6; a seek back restarts the easing at
    the raw opacity; a paused player (the same frame for many calls) holds."""
    T, start = 150, 20
    grid = _sphere_grid(tmp_path / "g.npz", T, start)
    rng = np.random.default_rng(2)
    frames = start + np.arange(T)
    yaw = np.cumsum(rng.normal(0, 6, T)) % 360 - 180
    yaw = np.where(np.arange(T) % 50 < 25, yaw, yaw[0])  # fast turns, then still: easing both ways
    pitch, roll = rng.uniform(-30, 30, T), rng.uniform(-20, 20, T)
    path = tmp_path / "p.csv"
    rows = ["time_s,yaw_deg,pitch_deg,roll_deg"] + [
        ",".join(repr(float(v)) for v in r) for r in zip(frames / 30.0, yaw, pitch, roll)
    ]
    path.write_text("\n".join(rows) + "\n")
    # The default (absolute) rule, its deg/s inside this grid's flow (18-47 deg/s): eased both ways.
    dps = ["--low-dps", "18", "--high-dps", "47"]
    assert main(["epof", str(grid), str(path), "-o", str(tmp_path / "e.csv"), *dps]) == 0
    ref = read_epof_csv(tmp_path / "e.csv")
    assert ref.frame[0] == start and len(ref.frame) == T
    assert main(["export", str(grid), "-o", str(tmp_path / "x"), *dps]) == 0
    # Render frames: each video frame three times, poses after the first are noise (held).
    f3 = np.repeat(frames, 3).astype(np.float64)
    y3, p3, r3 = (np.repeat(a, 3).astype(np.float32) for a in (yaw, pitch, roll))
    y3[1::3] += 90.0
    p3[2::3] = -p3[2::3]
    # Then paused on the last frame for 10 calls, then a seek back to frame start + 30.
    f3 = np.concatenate([f3, np.full(10, frames[-1]), [start + 30]])
    y3, p3, r3 = (np.concatenate([a, np.full(10, 45.0), a[[90]]]).astype(np.float32) for a in (y3, p3, r3))
    _mono(harness, "clock", tmp_path / "x", _queries(tmp_path / "q", f3, y3, p3, r3), tmp_path / "o")
    out = np.fromfile(tmp_path / "o", dtype=[("e", "<f4"), ("raw", "<f4"), ("eased", "<f4"), ("flags", "<i4")])
    main_part = out[: 3 * T]
    eased = main_part["eased"][::3].astype(np.float64)
    err = np.abs(eased - ref.opacity)
    assert err.max() <= 1e-6, (err.max(), err.argmax())
    assert np.ptp(ref.opacity) > 0.3  # the easing is exercised
    np.testing.assert_array_equal(main_part["eased"][1::3], main_part["eased"][::3])  # held
    np.testing.assert_array_equal(main_part["eased"][2::3], main_part["eased"][::3])
    paused = out[3 * T : 3 * T + 10]
    assert (paused["eased"] == eased[-1]).all() and (paused["flags"] == 1).all()
    last = out[-1]
    assert last["flags"] == 3 and last["eased"] == last["raw"]  # seek: restarted, in range
    assert (main_part["flags"][1:] == 1).all()  # no restart during normal playback


def test_outside_the_exported_range_is_flagged(tmp_path, harness):
    """Covers(t) in C# = covers() in Python = the exported frames (start_frame .. end_frame);
    Epof is NaN outside (before the start, after the end, at 1e6 s, NaN), the clock flags."""
    grid = _sphere_grid(tmp_path / "g.npz", T=60, start_frame=40)
    res = export_unity(grid, tmp_path / "x")
    h = res.header
    assert h["range"] == {**h["range"], "start_frame": 40, "end_frame": 100}
    assert h["source"]["n_frames"] == 130 and h["source"]["duration_s"] == pytest.approx(130 / 30)
    t = np.array([0.0, 39.999 / 30, 40 / 30, 70.5 / 30, 99.999 / 30, 100 / 30, 3.9, 1e6, np.nan])
    n = len(t)
    _mono(harness, "covers", tmp_path / "x", _queries(tmp_path / "q", t, *(np.zeros(n, np.float32),) * 3),
          tmp_path / "o")  # fmt: skip
    out = np.fromfile(tmp_path / "o", dtype=[("c", "<i4"), ("e", "<f4")])
    want = covers(h, t)
    np.testing.assert_array_equal(out["c"].astype(bool), want)
    assert list(want) == [False, False, True, True, True, False, False, False, False]
    assert np.isnan(out["e"][~want]).all() and np.isfinite(out["e"][want]).all()
    f = np.array([39, 40, 99, 100, 5000], np.float64)
    _mono(harness, "clock", tmp_path / "x", _queries(tmp_path / "q2", f, *(np.zeros(5, np.float32),) * 3),
          tmp_path / "o2")  # fmt: skip
    clk = np.fromfile(tmp_path / "o2", dtype=[("e", "<f4"), ("raw", "<f4"), ("eased", "<f4"), ("flags", "<i4")])
    assert list(clk["flags"] & 1) == [0, 1, 1, 0, 0] and np.isnan(clk["eased"][[0, 3, 4]]).all()


def _rewrite(src: Path, dst: Path, edit, grains=None) -> Path:
    header, data = read_export(src)
    g = read_grain_layout(src) if grains is None else grains
    header = json.loads(json.dumps(header))
    edit(header)
    dst.write_bytes(pack(header, data, g))
    return dst


def test_bad_grf_settings_are_refused_naming_the_field(tmp_path, harness, capsys):
    """A layout of the wrong size, a negative density, cutout radii in the wrong order:
    VimsimLoadException naming the field (C#), InputError naming it (Python's reader), and
    as CLI options one line and exit 2 with nothing written. An export of format version 2
    is refused saying to export again."""
    grid = _sphere_grid(tmp_path / "g.npz", T=10, start_frame=0)
    export_unity(grid, tmp_path / "x")
    good = tmp_path / "x" / DATA_FILE
    lay = read_grain_layout(good)
    bad_density = _rewrite(good, tmp_path / "density.bin", lambda h: h["grf"].update(density=-0.5))
    bad_cutout = _rewrite(good, tmp_path / "cutout.bin", lambda h: h["grf"].update(inner_deg=40.0, outer_deg=18.0))
    cases = {
        "layout.bin": (_rewrite(good, tmp_path / "layout.bin", lambda h: None, grains=lay[:-5]), "grains"),
        "density.bin": (bad_density, "grf.density"),
        "cutout.bin": (bad_cutout, "grf.inner_deg"),
    }
    for name, (path, field) in cases.items():
        r = _mono(harness, "load", path, check=False)
        assert r.returncode == 3, r.stdout + r.stderr
        kind, fpath, _msg, got_field = r.stdout.strip().split("|")
        assert kind == "VimsimLoadException" and fpath.endswith(name) and got_field == field, r.stdout
        with pytest.raises(InputError) as e:
            read_export(path)
        assert name in str(e.value) and field.split(".")[0] in str(e.value) and "\n" not in str(e.value)
    v2 = tmp_path / "v2.bin"
    v2.write_bytes(good.read_bytes()[:8] + struct.pack("<I", 2) + good.read_bytes()[12:])
    r = _mono(harness, "load", v2, check=False)
    assert r.returncode == 3 and "v2.bin" in r.stdout and "export again" in r.stdout, r.stdout
    with pytest.raises(InputError, match="export again"):
        read_export(v2)
    for opts, what in ((["--density", "-0.5"], "--density"), (["--cutout", "40", "18"], "--cutout"),
                       (["--mitigation", "local-grf"], "--mitigation")):  # fmt: skip
        rc = main(["export", str(grid), "-o", str(tmp_path / "o"), *opts])
        err = capsys.readouterr().err
        assert rc == 2 and err.count("\n") == 1 and what in err, err
        assert not (tmp_path / "o").exists() or not any((tmp_path / "o").iterdir())


@pytest.fixture(scope="module")
def behaviour_harness(tmp_path_factory, harness) -> Path:
    """VimsimEpofBehaviour compiled with the UnityEngine stub and a driver calling its Awake /
    Update as Unity does (``tests/export/cs/BehaviourHarness.cs``)."""
    cs = Path(__file__).parent / "cs"
    u = Path(__file__).resolve().parents[2] / "simulator" / "export" / "unity"
    out = tmp_path_factory.mktemp("bh") / "bh.exe"
    r = subprocess.run(["mcs", "-warnaserror+", f"-out:{out}", str(u / "VimsimEpof.cs"), str(u / "VimsimEpofBehaviour.cs"),
                        str(u / "VimsimEpofAsset.cs"), str(cs / "UnityEngineStub.cs"), str(cs / "BehaviourHarness.cs")],
                       capture_output=True, text=True, check=False)  # fmt: skip
    assert r.returncode == 0, r.stdout + r.stderr
    return out


def test_behaviour_follows_the_video_player(tmp_path, behaviour_harness):
    """The MonoBehaviour driven as Unity would (stub VideoPlayer, head looking at the frame's
    centre): nothing before the player is prepared; 30 fps video at 90 Hz updates = vimsim
    epof's opacity column (1e-6); paused: held; seek event: the easing restarts; a player at
    60 fps is mapped through time (frame 32 -> 16, one warning); outside the export: NaN,
    nothing drawn, one warning however often."""
    T = 90
    grid = _sphere_grid(tmp_path / "g.npz", T, 0)
    path = tmp_path / "p.csv"
    path.write_text("time_s,yaw_deg,pitch_deg,roll_deg\n0,0,0,0\n10,0,0,0\n")
    assert main(["epof", str(grid), str(path), "-o", str(tmp_path / "e.csv")]) == 0
    ref = read_epof_csv(tmp_path / "e.csv")
    assert main(["export", str(grid), "-o", str(tmp_path / "x")]) == 0
    rows = [(-1, 30.0, 0)] * 3  # not prepared
    rows += [(f, 30.0, 3) for f in range(60) for _ in range(3)]  # playing, 90 Hz
    rows += [(59, 30.0, 2)] * 5  # paused
    rows += [(10, 30.0, 3 | 4)] + [(f, 30.0, 3) for f in range(11, 16)]  # a seek back
    rows += [(32, 60.0, 3), (34, 60.0, 3)]  # a 60 fps player: frames 16, 17
    rows += [(500, 30.0, 3), (501, 30.0, 3)]  # past the export
    rec = np.array(rows, dtype=[("f", "<i8"), ("r", "<f4"), ("k", "<i4")])
    (tmp_path / "s").write_bytes(struct.pack("<i", len(rec)) + rec.tobytes())
    r = _mono(behaviour_harness, tmp_path / "x", tmp_path / "s", tmp_path / "o")
    out = np.fromfile(tmp_path / "o", dtype=[("e", "<f4"), ("raw", "<f4"), ("eased", "<f4"), ("drawn", "<f4")])
    assert np.isnan(out["eased"][:3]).all() and (out["drawn"][:3] == 0).all()
    play = out[3 : 3 + 180]
    assert np.abs(play["eased"][::3] - ref.opacity[:60]).max() <= 1e-6
    assert (play["eased"][1::3] == play["eased"][::3]).all() and (play["drawn"] == play["eased"]).all()
    paused = out[183:188]
    assert (paused["eased"] == play["eased"][-1]).all()
    seek = out[188]
    assert seek["eased"] == seek["raw"] and abs(seek["e"] - ref.epof_dps[10]) <= 1e-5 * ref.epof_dps[10]
    np.testing.assert_allclose(out["e"][194:196], ref.epof_dps[[16, 17]], rtol=1e-5)
    assert np.isnan(out["eased"][196:]).all() and (out["drawn"][196:] == 0).all()
    assert r.stdout.strip() == "warnings 2 errors 0", r.stdout + r.stderr
    assert np.ptp(ref.opacity[:60]) > 0.2  # the easing is exercised
