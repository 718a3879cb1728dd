"""vimsim export --format unity: the binary, the CLI, and the C# runtime compiled with Mono's
``mcs`` and run with ``mono`` against ``vimsim epof`` (the reference: its CSV rows)."""

from __future__ import annotations

import json
import struct
import subprocess
from pathlib import Path

import numpy as np
import pytest

from simulator.cli import main
from simulator.epof import read_epof_csv, viewport_overlaps
from simulator.export import DATA_FILE, VERSION, export_unity, frame_at, read_export
from simulator.export.unity import ASSET_FILES, CS_FILES
from simulator.export.unity.assets import meta_files
from simulator.media.gridfile import load_grid, save_grid
from simulator.preprocess import SphereConfig, field_meta
from simulator.sphere.geometry import head_rotation
from simulator.sphere.windows import grid_preset

REPO = Path(__file__).resolve().parents[2]
CS_DIR = REPO / "simulator" / "export" / "unity"
HARNESS = REPO / "tests" / "export" / "cs" / "EpofHarness.cs"
N_POSES = 1000  # random poses and times per mode (the issue: at least 1000)


# ----------------------------------------------------------------------- fixtures
def _meta(T: int, fps: float, **extra) -> dict:
    return {
        "fps": fps,
        "n_frames": T,
        "flow": {"method": "test"},
        "layout": "mono",
        "eye": "left",
        "video": {
            "path": "v.mp4",
            "width": 2048,
            "height": 1024,
            "sar": 1,
            "content_hash": "sha256:ab",
            "n_frames": T + int(extra.get("start_frame", 0)) + 10,
        },
        **extra,
    }


def _smooth(rng, T: int, shape: tuple[int, int]) -> np.ndarray:
    """Positive flow that varies smoothly over the grid and over time, plus noise (deg/s)."""
    a, b = shape
    i = np.arange(a)[None, :, None] / a
    j = np.arange(b)[None, None, :] / b
    t = np.arange(T)[:, None, None] / 30.0
    base = 30 + 18 * np.sin(2 * np.pi * (j + 0.1 * t)) * np.cos(np.pi * i) + 8 * np.cos(3 * t)
    return (base + 6 * rng.random((T, a, b))).astype(np.float32)


def _paper_grid(path: Path, preset="default", T=N_POSES, fps=30.0, seed=0, **grid_kw) -> Path:
    g = grid_preset(preset, **grid_kw)
    pof = _smooth(np.random.default_rng(seed), T, g.shape)
    save_grid(path, pof, pof / 10, g, _meta(T, fps))
    return path


def _sphere_grid(path: Path, T=N_POSES, fps=25.0, start_frame=40, seed=1) -> Path:
    g = grid_preset("default")
    rng = np.random.default_rng(seed)
    cfg = SphereConfig()
    field = _smooth(rng, T, (45, 90)).astype(np.float16)  # 4 deg cells: 45 x 90
    pof = _smooth(rng, T, g.shape)
    meta = _meta(T, fps, start_frame=start_frame, method="sphere", field=field_meta(cfg))
    save_grid(path, pof, pof / 10, g, meta, field_dps=field)
    return path


def _poses(n: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """float32 yaw, pitch, roll (degrees): uniform on the sphere with any roll, plus a tenth
    at the +-180 seam, a tenth within 1 deg of the poles (and 4 exactly there), a tenth with
    roll 0."""
    rng = np.random.default_rng(seed)
    yaw = rng.uniform(-180, 180, n)
    pitch = np.degrees(np.arcsin(rng.uniform(-1, 1, n)))
    roll = rng.uniform(-180, 180, n)
    k = n // 10
    yaw[:k] = rng.choice([-1, 1], k) * rng.uniform(179.0, 180.0, k)
    pitch[k : 2 * k] = rng.choice([-1, 1], k) * rng.uniform(89.0, 90.0, k)
    pitch[2 * k : 2 * k + 4] = [90.0, -90.0, 89.999, -89.999]
    roll[3 * k : 4 * k] = 0.0
    return tuple(np.asarray(a, np.float32) for a in (yaw, pitch, roll))


def _headpath_csv(path: Path, times, yaw, pitch, roll) -> Path:
    """Canonical head path with full precision (repr), one sample per frame time."""
    lines = ["time_s,yaw_deg,pitch_deg,roll_deg"]
    for row in zip(times, yaw, pitch, roll):
        lines.append(",".join(repr(float(v)) for v in row))
    path.write_text("\n".join(lines) + "\n")
    return path


def _mono(exe: Path, *args, check=True) -> subprocess.CompletedProcess:
    r = subprocess.run(
        ["mono", str(exe), *map(str, args)], capture_output=True, text=True, check=False
    )
    if check:
        assert r.returncode == 0, r.stdout + r.stderr
    return r


def _write_queries(path: Path, t, yaw, pitch, roll) -> Path:
    rec = np.zeros(len(t), dtype=[("t", "<f8"), ("y", "<f4"), ("p", "<f4"), ("r", "<f4")])
    rec["t"], rec["y"], rec["p"], rec["r"] = t, yaw, pitch, roll
    path.write_bytes(struct.pack("<i", len(t)) + rec.tobytes())
    return path


def _read_results(path: Path):
    rec = np.fromfile(path, dtype=[("e", "<f4"), ("o", "<f4"), ("f", "<i4")])
    return rec["e"].astype(np.float64), rec["o"].astype(np.float64), rec["f"]


def _reference(tmp_path: Path, grid: Path, seed: int, *extra) -> tuple:
    """``vimsim epof`` on a head path with one random pose per frame; returns its rows and
    the C# queries for them: the rows' poses, at the frame time or between it and the next."""
    g = load_grid(grid)
    start = int(g.meta.get("start_frame", 0))
    times = (start + np.arange(g.n_frames)) / g.fps  # the frame times vimsim epof samples
    yaw, pitch, roll = _poses(g.n_frames, seed)
    hp = _headpath_csv(tmp_path / f"path{seed}.csv", times, yaw, pitch, roll)
    out = tmp_path / f"epof{seed}.csv"
    # Opacity() is the per-call percentile rule: compare with vimsim epof's paper rule unless
    # the caller asks for a rule (the eased ones are checked through OpacityEasing).
    rule = (
        []
        if any(a in extra for a in ("--smooth", "--ease-in", "--ease-out", "--opacity-rule"))
        else ["--opacity-rule", "paper"]
    )
    assert main(["epof", str(grid), str(hp), "-o", str(out), *extra, *rule]) == 0
    ref = read_epof_csv(out)
    u = np.random.default_rng(seed + 7).uniform(0.0, 0.999, g.n_frames)
    u[::3] = 0.0  # exactly at the frame time
    qt = ref.time_s + u / g.fps
    q = [np.float32(a) for a in (ref.yaw_deg, ref.pitch_deg, ref.roll_deg)]
    return ref, qt, q


#: The rule the un-eased runtime opacity is compared in (vimsim epof's paper rule, _reference).
PAPER = ("--opacity-rule", "paper")


def _check_agreement(ref, e, op, frames, *, rel=1e-4):
    np.testing.assert_array_equal(frames, ref.frame)  # same frame for every time
    err = np.abs(e - ref.epof_dps) / np.abs(ref.epof_dps)
    assert err.max() <= rel, f"max relative error {err.max():.3g} at row {err.argmax()}"
    assert np.abs(op - ref.opacity).max() <= 1e-4
    return err.max()


# -------------------------------------------------------------------- agreement
@pytest.mark.slow
def test_paper_mode_agrees_with_vimsim_epof(tmp_path, harness, capsys):
    """1000 random poses (roll, seam, |pitch| -> 90) at random times between frames, paper
    mode: float32 within 1e-4 relative; float16 within float16's rounding (2^-11, a weighted
    mean of values each rounded by at most that); the C# overlap table equals Python's."""
    grid = _paper_grid(tmp_path / "g.npz")
    pct = ["--opacity-rule", "paper", "--low-pct", "35", "--high-pct", "65"]
    ref, qt, (y, p, r) = _reference(tmp_path, grid, 3, *pct)
    assert (np.abs(ref.pitch_deg) > 89.0).sum() >= 100 and (np.abs(ref.yaw_deg) > 179.0).sum() >= 90
    assert np.ptp(ref.opacity) == 1.0  # the opacity rule is exercised over its whole range
    assert main(["export", str(grid), "-o", str(tmp_path / "x32"), *pct]) == 0
    assert main(["export", str(grid), "-o", str(tmp_path / "x16"), "--dtype", "float16", *pct]) == 0
    assert "paper mode, float32 1000x11x24" in capsys.readouterr().out
    qf = _write_queries(tmp_path / "q.bin", qt, y, p, r)
    _mono(harness, "query", tmp_path / "x32", qf, tmp_path / "r32.bin",
          tmp_path / "x16", qf, tmp_path / "r16.bin", ";", "table", tmp_path / "x32", tmp_path / "t")  # fmt: skip
    table = viewport_overlaps(grid_preset("default"), 107.0, 107.0).table
    np.testing.assert_array_equal(np.fromfile(tmp_path / "t", "<f4").reshape(table.shape), table)
    worst = _check_agreement(ref, *_read_results(tmp_path / "r32.bin"))
    e16, _, f16 = _read_results(tmp_path / "r16.bin")
    np.testing.assert_array_equal(f16, ref.frame)
    err16 = np.abs(e16 - ref.epof_dps) / ref.epof_dps
    assert err16.max() <= 2.0**-11 + 1e-6
    assert worst < err16.max()  # float32 is the exact one


@pytest.mark.slow
def test_paper_198_and_another_viewport_fov(tmp_path, harness):
    """Another grid (paper-198, 90 x 80 deg windows) and viewport (--fov 100): the runtime
    builds its table from the header and still matches."""
    grid = _paper_grid(
        tmp_path / "g.npz", "paper-198", T=300, fps=24.0, hfov_deg=90.0, vfov_deg=80.0
    )
    ref, qt, (y, p, r) = _reference(tmp_path, grid, 5, "--fov", "100")
    assert main(["export", str(grid), "-o", str(tmp_path / "x"), "--fov", "100", *PAPER]) == 0
    assert read_export(tmp_path / "x")[0]["viewport"] == {"hfov_deg": 100.0, "vfov_deg": 100.0}
    _mono(
        harness,
        "query",
        tmp_path / "x",
        _write_queries(tmp_path / "q", qt, y, p, r),
        tmp_path / "r",
    )
    _check_agreement(ref, *_read_results(tmp_path / "r"))


def test_sphere_mode_agrees_with_vimsim_epof(tmp_path, harness):
    """The field (float16 as stored: exact), exact integration; a grid starting at frame 40."""
    grid = _sphere_grid(tmp_path / "s.npz")
    ref, qt, (y, p, r) = _reference(tmp_path, grid, seed=11)
    assert ref.frame[0] == 40
    assert main(["export", str(grid), "-o", str(tmp_path / "x"), *PAPER]) == 0
    h, data = read_export(tmp_path / "x")
    assert h["mode"] == "sphere" and data.dtype == np.float16 and data.shape == (N_POSES, 45, 90)
    np.testing.assert_array_equal(data, load_grid(grid).field_dps)  # stored exactly
    # Times before the first and after the last frame clamp to them.
    qt2 = np.concatenate([qt, [0.0, 1e6]])
    y2, p2, r2 = (np.concatenate([a, a[[0, -1]]]) for a in (y, p, r))
    _mono(
        harness,
        "query",
        tmp_path / "x",
        _write_queries(tmp_path / "q", qt2, y2, p2, r2),
        tmp_path / "r",
    )
    e, op, fr = _read_results(tmp_path / "r")
    _check_agreement(ref, e[:-2], op[:-2], fr[:-2])
    assert list(fr[-2:]) == [40, 40 + N_POSES - 1]  # FrameAt clamps
    assert np.isnan(e[-2:]).all() and np.isnan(op[-2:]).all()  # Epof flags: NaN outside the range


def test_easing_matches_vimsim_epof_smooth(tmp_path, harness):
    """OpacityEasing.Step per video frame = vimsim epof --smooth S's opacity column."""
    grid = _sphere_grid(tmp_path / "s.npz", T=200, start_frame=0)
    no_ease = ["--opacity-rule", "comfort", "--ease-in", "0", "--ease-out", "0"]
    ref, _, _ = _reference(tmp_path, grid, 2, "--smooth", "0.4", *no_ease)
    raw, _, _ = _reference(tmp_path, grid, 2)
    assert main(["export", str(grid), "-o", str(tmp_path / "x"), "--smooth", "0.4", *no_ease]) == 0
    assert read_export(tmp_path / "x")[0]["opacity"]["smoothing_s"] == 0.4
    inp = tmp_path / "in.bin"
    inp.write_bytes(struct.pack("<i", len(raw.opacity)) + raw.opacity.astype("<f4").tobytes())
    _mono(harness, "ease", tmp_path / "x", inp, tmp_path / "out.bin")
    eased = np.fromfile(tmp_path / "out.bin", "<f4")
    assert np.abs(eased - ref.opacity).max() <= 1e-5
    assert np.abs(eased - raw.opacity).max() > 0.05  # the easing does something


@pytest.mark.parametrize("mode", ["sphere", "paper"])
def test_default_comfort_opacity_matches_vimsim_epof(tmp_path, harness, mode):
    """Both with their defaults, vimsim export and vimsim epof use the comfort rule (ease-in
    0.4 s, ease-out 1.5 s). OpacityEasing.Step fed vimsim epof's unlimited (paper-rule)
    opacity per video frame reproduces its default opacity column within 1e-5; the runtime
    alone (Step, and Update with dt = 1 / fps, of Opacity(Epof)) within 1e-4 (its EPOF
    agrees within 1e-4 relative). A custom rule (smoothing and both easings) travels in the
    header the same way."""
    T = 240
    grid = (
        _sphere_grid(tmp_path / "g.npz", T=T, start_frame=0)
        if mode == "sphere"
        else _paper_grid(tmp_path / "g.npz", T=T)
    )
    g = load_grid(grid)
    times = np.arange(T) / g.fps
    yaw, pitch, roll = _poses(T, 21)
    # Head turns of different speeds: stretches where the opacity changes faster than the
    # ease limits allow, in both directions.
    yaw = np.where(np.arange(T) % 60 < 30, yaw, yaw * 0.05)
    hp = _headpath_csv(tmp_path / "p.csv", times, yaw, pitch, roll)
    q = _write_queries(tmp_path / "q", times, *(np.float32(a) for a in (yaw, pitch, roll)))
    raw_csv = tmp_path / "raw.csv"
    assert main(["epof", str(grid), str(hp), "-o", str(raw_csv), "--opacity-rule", "paper"]) == 0
    raw = read_epof_csv(raw_csv).opacity
    inp = tmp_path / "in.bin"
    inp.write_bytes(struct.pack("<i", T) + raw.astype("<f4").tobytes())
    # The comfort rule: the paper's thresholds (raw) with the default easing; the default
    # rule (absolute) eases the same way (test_unity_runtime.py).
    comfort = ["--opacity-rule", "comfort"]
    custom = [*comfort, "--smooth", "0.1", "--ease-in", "0.2", "--ease-out", "0.7"]
    for name, opts in (("default", comfort), ("custom", custom)):
        assert main(["epof", str(grid), str(hp), "-o", str(tmp_path / f"{name}.csv"), *opts]) == 0
        assert main(["export", str(grid), "-o", str(tmp_path / name), *opts]) == 0
        ref = read_epof_csv(tmp_path / f"{name}.csv")
        want = (0.4, 1.5, 0.0) if name == "default" else (0.2, 0.7, 0.1)
        r = ref.meta["settings"]["opacity_rule"]
        assert (r["ease_in_s"], r["ease_out_s"], r["smoothing_s"]) == want
        op = read_export(tmp_path / name)[0]["opacity"]
        assert (op["ease_in_s"], op["ease_out_s"], op["smoothing_s"]) == want
        assert op["name"] == "comfort" and op["eased"] and op["scale"] == "relative"
        _mono(harness, "ease", tmp_path / name, inp, tmp_path / f"{name}.ease", ";",
              "play", tmp_path / name, q, tmp_path / f"{name}.play")  # fmt: skip
        eased = np.fromfile(tmp_path / f"{name}.ease", "<f4")
        assert np.abs(eased - ref.opacity).max() <= 1e-5
        play = np.fromfile(tmp_path / f"{name}.play", "<f4").reshape(T, 2)
        assert np.abs(play[:, 0] - ref.opacity).max() <= 1e-4
        assert np.abs(play[:, 1] - ref.opacity).max() <= 1e-4
        assert np.abs(eased - raw).max() > 0.1  # the rule does something
    # The easing is exercised: the default column rises by at most 1 / (fps 0.4) and falls
    # by at most 1 / (fps 1.5) per frame while the unlimited one jumps.
    eased = read_epof_csv(tmp_path / "default.csv").opacity
    assert np.diff(eased).max() <= 1 / (g.fps * 0.4) + 1e-9 < np.diff(raw).max()
    assert np.diff(eased).min() >= -1 / (g.fps * 1.5) - 1e-9 > np.diff(raw).min()
    assert np.ptp(eased) > 0.3


def test_unity_euler_conversion(tmp_path, harness):
    """FromUnityEuler: Unity's Quaternion.Euler(x, y, z) (rotations about fixed axes z, then
    x, then y; Euler(0, 90, 0) * forward = right, Euler(90, 0, 0) * forward = down,
    Euler(0, 0, 90) * up = left, from Unity's documentation) gives the same head rotation
    as vimsim's yaw/pitch/roll; plus the worked example of the docs."""
    rng = np.random.default_rng(4)
    n = 500
    e = rng.uniform(0, 360, (n, 3)).astype(np.float32)
    off = rng.choice([0.0, -90.0, 30.0], n).astype(np.float32)
    e[0], off[0] = (350, 30, 5), 0.0
    inp = tmp_path / "u.bin"
    inp.write_bytes(struct.pack("<i", n) + np.column_stack([e, off]).astype("<f4").tobytes())
    _mono(harness, "unity", inp, tmp_path / "o.bin")
    ypr = np.fromfile(tmp_path / "o.bin", "<f4").reshape(n, 3).astype(np.float64)
    np.testing.assert_allclose(ypr[0], [30, 10, -5], atol=1e-5)

    def axis(v, a):  # right-hand-formula rotation matrix about x, y or z (degrees)
        c, s = np.cos(np.radians(a)), np.sin(np.radians(a))
        m = {"x": [[1, 0, 0], [0, c, -s], [0, s, c]], "y": [[c, 0, s], [0, 1, 0], [-s, 0, c]],
             "z": [[c, -s, 0], [s, c, 0], [0, 0, 1]]}[v]  # fmt: skip
        return np.array(m)

    assert np.allclose(axis("y", 90) @ [0, 0, 1], [1, 0, 0])  # the documented Unity facts
    assert np.allclose(axis("x", 90) @ [0, 0, 1], [0, -1, 0])
    assert np.allclose(axis("z", 90) @ [0, 1, 0], [-1, 0, 0])
    for (x, y, z), o, (yaw, pitch, roll) in zip(e.astype(float), off, ypr):
        unity = axis("y", y) @ axis("x", x) @ axis("z", z)  # z first, then x, then y (fixed axes)
        want = axis("y", o) @ unity  # the video's yaw offset about the vertical
        got = head_rotation(yaw, pitch, roll).as_matrix()
        np.testing.assert_allclose(got, want, atol=2e-6)


def test_behaviour_compiles_against_unity_api_stub(tmp_path, harness):
    """The MonoBehaviour compiles with the core against a stub of the UnityEngine types it
    uses (the real UnityEngine is not installable here)."""
    stub = REPO / "tests" / "export" / "cs" / "UnityEngineStub.cs"
    r = subprocess.run(
        ["mcs", "-target:library", "-warnaserror+", f"-out:{tmp_path / 'b.dll'}",
         "-d:UNITY_2020_2_OR_NEWER", str(CS_DIR / "VimsimEpof.cs"), str(CS_DIR / "VimsimEpofBehaviour.cs"),
         str(CS_DIR / "VimsimEpofAsset.cs"), str(CS_DIR / "Editor" / "VimsimEpofImporter.cs"), str(stub)],
        capture_output=True, text=True, check=False,
    )  # fmt: skip
    assert r.returncode == 0, r.stdout + r.stderr
    # The core file itself must not need UnityEngine.
    assert "UnityEngine" not in (CS_DIR / "VimsimEpof.cs").read_text().split("namespace Vimsim")[1]


# ------------------------------------------------------------------ the binary
def test_binary_layout_round_trip_and_frame_rule(tmp_path):
    grid = _paper_grid(tmp_path / "g.npz", T=40)
    res = export_unity(grid, tmp_path / "x", dtype="float16")
    b = (tmp_path / "x" / DATA_FILE).read_bytes()
    assert b[:8] == b"VIMSIMEP" and struct.unpack("<II", b[8:16])[0] == VERSION
    hlen = struct.unpack("<I", b[12:16])[0]
    header = json.loads(b[16 : 16 + hlen])
    assert (16 + hlen) % 16 == 0 and header["data"]["offset"] == 16 + hlen
    g_off = header["grains"]["offset"]
    assert g_off % 16 == 0 and 0 <= g_off - (16 + hlen + 40 * 11 * 24 * 2) < 16
    assert len(b) == g_off + 12 * res.n_grains == res.file_bytes
    assert header["grains"]["shape"] == [res.n_grains, 3] == [header["grf"]["n_grains"], 3]
    h, data = read_export(tmp_path / "x")
    pof = load_grid(grid).pof_dps
    np.testing.assert_array_equal(data, pof.astype(np.float16))
    assert res.max_rel_error == pytest.approx(
        float(np.max(np.abs(data.astype(np.float64) - pof) / pof))
    )
    assert 0 < res.max_rel_error <= 2.0**-11
    for k in ("fps", "n_frames", "start_frame", "viewport", "grid", "opacity", "video"):
        assert k in h
    assert h["video"]["content_hash"] == "sha256:ab" and h["overlap_table"]["rays"] == 48
    assert [p.name for p in res.files][: 1 + len(CS_FILES)] == [DATA_FILE, *CS_FILES]
    fps = h["fps"]
    np.testing.assert_array_equal(
        frame_at(h, [-1.0, 0.0, 5 / fps, 5.999 / fps, 6 / fps, 1e9]), [0, 0, 5, 5, 6, 39]
    )


def test_float16_export_is_at_most_the_grid_file(tmp_path):
    """File size: float16 export <= the grid's npz, paper mode and sphere mode (a field grid
    holds the field and the window matrix; its export holds the field only)."""
    for grid in (_paper_grid(tmp_path / "g.npz", T=200), _sphere_grid(tmp_path / "s.npz", T=200)):
        res = export_unity(grid, tmp_path / grid.stem, dtype="float16")
        flow = res.file_bytes - 12 * res.n_grains  # the grain layout: 12 bytes a grain, any video
        assert flow <= grid.stat().st_size, (flow, grid.stat().st_size)


# ------------------------------------------------------------------- bad input
def _run(argv, capsys):
    rc = main(argv)
    err = capsys.readouterr().err
    return rc, err


def test_cli_bad_input_one_line_exit_2(tmp_path, capsys):
    notgrid = tmp_path / "v.mp4"
    notgrid.write_bytes(b"\x00\x00\x00 ftypisom not really a grid")
    rc, err = _run(["export", str(notgrid), "-o", str(tmp_path / "x")], capsys)
    assert rc == 2 and err.count("\n") == 1 and "not a vimsim grid file" in err
    assert not (tmp_path / "x").exists() or not any((tmp_path / "x").iterdir())
    # A grid file of a future format version.
    grid = _paper_grid(tmp_path / "g.npz", T=10)
    with np.load(grid) as z:
        arrs = {k: z[k] for k in z.files}
    meta = json.loads(str(arrs["meta"]))
    meta["version"] = 99
    arrs["meta"] = np.array(json.dumps(meta))
    np.savez(tmp_path / "future.npz", **arrs)
    rc, err = _run(["export", str(tmp_path / "future.npz"), "-o", str(tmp_path / "y")], capsys)
    assert rc == 2 and err.count("\n") == 1 and "version 99" in err and "future.npz" in err
    # Sphere mode of a grid without a field; output = input; a foreign file in DIR.
    rc, err = _run(["export", str(grid), "-o", str(tmp_path / "z"), "--method", "sphere"], capsys)
    assert rc == 2 and "no sphere-mode field" in err
    rc, err = _run(["export", str(grid), "-o", str(grid)], capsys)
    assert rc == 2 and err.count("\n") == 1 and "input" in err and grid.is_file()
    (tmp_path / "w").mkdir()
    (tmp_path / "w" / "VimsimEpof.cs").write_text("// my own code\n")
    rc, err = _run(["export", str(grid), "-o", str(tmp_path / "w")], capsys)
    assert rc == 2 and "not written by vimsim export" in err
    assert (tmp_path / "w" / "VimsimEpof.cs").read_text() == "// my own code\n"
    assert not (tmp_path / "w" / DATA_FILE).exists()  # nothing half written
    # Opacity options as vimsim epof's: a viewing's percentiles cannot be exported (the
    # option value is not even offered); the paper rule with easing is a contradiction.
    # One line, exit 2, nothing written.
    with pytest.raises(SystemExit) as e:
        main(["export", str(grid), "-o", str(tmp_path / "o"), "--opacity-source", "viewing"])
    err = capsys.readouterr().err
    assert e.value.code == 2 and err.count("\n") == 1 and "invalid choice: 'viewing'" in err
    for opts, what in ((["--opacity-rule", "paper", "--ease-in", "1"], "--ease-in"),):
        rc, err = _run(["export", str(grid), "-o", str(tmp_path / "o"), *opts], capsys)
        assert rc == 2 and err.count("\n") == 1 and what in err, err
        assert not (tmp_path / "o").exists() or not any((tmp_path / "o").iterdir())
    assert main(["export", str(grid), "-o", str(tmp_path / "o"), "--opacity-rule", "paper"]) == 0
    assert read_export(tmp_path / "o")[0]["opacity"]["name"] == "paper"
    # A second export into the same folder replaces its own files.
    assert main(["export", str(grid), "-o", str(tmp_path / "v")]) == 0
    assert main(["export", str(grid), "-o", str(tmp_path / "v"), "--dtype", "float16"]) == 0
    assert read_export(tmp_path / "v")[0]["data"]["dtype"] == "float16"
    written = sorted(str(p.relative_to(tmp_path / "v")) for p in (tmp_path / "v").rglob("*") if p.is_file())
    assert written == sorted([DATA_FILE, *ASSET_FILES, *meta_files()])


def test_csharp_loader_errors_name_file_and_problem(tmp_path, harness):
    """VimsimLoadException (file, problem) for a truncated file, another version, a file
    that is not an export, a missing file. (A sphere-mode export: no table to build.)"""
    grid = _sphere_grid(tmp_path / "g.npz", T=10, start_frame=0)
    export_unity(grid, tmp_path / "x")
    good = (tmp_path / "x" / DATA_FILE).read_bytes()
    cases = {
        "truncated.bin": (good[:-7], "truncated"),
        "short.bin": (good[:11], "truncated"),
        "header.bin": (good[: 16 + 40], "truncated"),
        "future.bin": (
            good[:8] + struct.pack("<I", VERSION + 1) + good[12:],
            f"version {VERSION + 1}",
        ),
        # Version 1 (before the header had ease-in / ease-out): refused, not read without them.
        "v1.bin": (good[:8] + struct.pack("<I", 1) + good[12:], "version 1"),
        "notours.bin": (b"PK\x03\x04" + good[4:], "not a vimsim export"),
    }
    for name, (blob, problem) in cases.items():
        (tmp_path / name).write_bytes(blob)
    cases["missing.bin"] = (None, "file not found")
    for name, (_, problem) in cases.items():
        r = _mono(harness, "load", tmp_path / name, check=False)
        assert r.returncode == 3, r.stdout + r.stderr
        kind, path, msg, _field = r.stdout.strip().split("|")
        assert kind == "VimsimLoadException" and path.endswith(name) and problem in msg, msg
    # The rule as exported: export_unity's default is the paper's (the library's OpacityRule()).
    assert _mono(harness, "load", tmp_path / "x").stdout.strip() == "ok sphere paper relative"
    # vimsim export's default is the absolute rule (issue 37): header and C# runtime say so.
    assert main(["export", str(grid), "-o", str(tmp_path / "d")]) == 0
    op = read_export(tmp_path / "d")[0]["opacity"]
    assert (op["name"], op["scale"], op["low_dps"], op["high_dps"]) == ("absolute", "absolute", 5.0, 30.0)
    assert _mono(harness, "load", tmp_path / "d").stdout.strip() == "ok sphere absolute absolute"


def test_absolute_rule_carried_into_the_header(tmp_path):
    """--opacity-rule absolute: the header holds the fixed deg/s, the same for any video."""
    from simulator.mitigation.grf import OpacityRule

    grid = _paper_grid(tmp_path / "g.npz", T=20)
    export_unity(grid, tmp_path / "x", rule=OpacityRule(low_dps=5.0, high_dps=30.0))
    h, _ = read_export(tmp_path / "x")
    assert (h["opacity"]["low_dps"], h["opacity"]["high_dps"]) == (5.0, 30.0)
    assert h["opacity"]["scale"] == "absolute"
