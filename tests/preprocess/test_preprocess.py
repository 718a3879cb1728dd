"""Preprocess: the POF reduction against exact geometry, a small rotating-panorama video
against analytic truth, checkpoint/resume (Ctrl-C and kill -9), real clips, bad input."""

from __future__ import annotations

import errno
import json
import subprocess
import sys

import av
import numpy as np
import pytest
from media_helpers import noise_frames, write_clip
from PIL import Image
from scipy.spatial.transform import Rotation

from simulator.cli import main
from simulator.core.errors import InputError
from simulator.media.gridfile import load_grid
from simulator.preprocess import (
    PreprocessInterrupted,
    WindowFlowReducer,
    checkpoint_path,
    preprocess_video,
)
from simulator.sphere import geometry
from simulator.sphere.geometry import head_rotation, perspective_rays
from simulator.sphere.windows import grid_preset

OBLIQUE = np.array([1.0, 2.0, 0.5]) / np.linalg.norm([1.0, 2.0, 0.5])
FPS = 30.0
SMALL = grid_preset("paper-198", size=(64, 64))  # 18 x 11 windows of 64x64 px, 107 deg
TINY = grid_preset("paper-198", size=(32, 32))
TINY = grid_preset("paper-198", size=(32, 32))


# ------------------------------------------------------------------------- helpers
def _rotation_video(path, img, axis, omega_dps, n):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    frames = (
        geometry.rotate_equirect(img, Rotation.from_rotvec(axis * np.radians(omega_dps * i / FPS)))
        for i in range(n)
    )
    return write_clip(path, frames, FPS, preset="veryfast")


def _truth_dps(grid, axis, omega_dps):
    """Solid-angle mean of omega |a x R_w d| over each window's pixel rays, (P, Y)."""
    dirs, sa = perspective_rays(grid.size, grid.hfov_deg, grid.vfov_deg)
    d = dirs.reshape(-1, 3).astype(np.float64)
    w = sa.ravel().astype(np.float64)
    pitch, yaw = grid.centres_deg()
    R = head_rotation(yaw.ravel(), pitch.ravel()).as_matrix()
    speed = np.linalg.norm(np.cross(axis, np.einsum("nij,pj->npi", R, d)), axis=-1)
    return (omega_dps * (speed @ w) / w.sum()).reshape(grid.shape)


@pytest.fixture(scope="module")
def pano(real_dir):
    img = Image.open(real_dir / "equirect" / "vrview" / "petra.jpg").convert("RGB")
    return np.asarray(img.resize((1024, 512), Image.LANCZOS))


@pytest.fixture(scope="module")
def videos(tmp_path_factory, pano):
    d = tmp_path_factory.mktemp("rot")
    return {
        "yaw60": _rotation_video(d / "yaw60.mp4", pano, (0, 1, 0), 60.0, 4),
        "obl30": _rotation_video(d / "obl30.mp4", pano, OBLIQUE, 30.0, 4),
        "still": _rotation_video(d / "still.mp4", pano, (0, 1, 0), 0.0, 3),
        # Checkpoint tests: a smaller video (512x256) and grid (TINY).
        "long": _rotation_video(d / "long.mp4", pano[::2, ::2].copy(), OBLIQUE, 45.0, 8),
    }


@pytest.fixture(scope="module")
def ref_long(tmp_path_factory, videos):
    """The uninterrupted grid of videos['long'] (TINY grid)."""
    out = tmp_path_factory.mktemp("ref") / "ref.npz"
    return load_grid(preprocess_video(videos["long"], out, grid=TINY, progress=False))


def _cli(*argv):
    return main(["preprocess", "--method", "paper", *map(str, argv), "--no-progress"])


# ---------------------------------------------------------------------- reduction
@pytest.mark.parametrize(
    "axis,delta_deg", [((0, 1, 0), 2.0), (tuple(OBLIQUE), 0.7), ((1, 0, 0), 5.0)]
)
def test_reducer_matches_exact_ray_angles(axis, delta_deg):
    """Flow = where each pixel's ray lands under a head-frame rotation (projected back on
    the window plane): the reducer must give the solid-angle mean of the exact angles."""
    w, h, hfov, vfov = 80, 60, 100.0, 80.0
    dirs, sa = perspective_rays((w, h), hfov, vfov)
    d = dirs.reshape(-1, 3).astype(np.float64)
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    q = Rotation.from_rotvec(a * np.radians(delta_deg)).apply(d)
    tx, ty = np.tan(np.radians(hfov) / 2), np.tan(np.radians(vfov) / 2)
    # Continuous pixel position of a ray (x right, y down; pixel centres at i + 0.5).
    x1 = (q[:, 0] / q[:, 2] / tx + 1) / 2 * w
    y1 = (1 - q[:, 1] / q[:, 2] / ty) / 2 * h
    jj, ii = np.mgrid[0:h, 0:w]
    flow = np.stack([x1.reshape(h, w) - (ii + 0.5), y1.reshape(h, w) - (jj + 0.5)], -1)
    ang = np.degrees(np.arccos(np.clip(np.sum(d * q, 1), -1, 1)))
    truth = float(np.sum(ang * sa.ravel()) / sa.sum()) * FPS
    dps, px = WindowFlowReducer((w, h), hfov, vfov)(flow[None].astype(np.float32), FPS)
    assert dps.shape == px.shape == (1,)
    assert abs(dps[0] - truth) / truth < 2e-3
    assert abs(px[0] - np.hypot(flow[..., 0], flow[..., 1]).mean()) < 1e-4 * px[0]


def test_reducer_zero_and_shape():
    r = WindowFlowReducer((32, 16), 90.0, 60.0)
    dps, px = r(np.zeros((3, 16, 32, 2), np.float32), FPS)
    assert np.all(dps == 0) and np.all(px == 0)
    with pytest.raises(ValueError, match="flow must be"):
        r(np.zeros((3, 32, 16, 2), np.float32), FPS)


# ------------------------------------------------------------ analytic truth, small
@pytest.mark.parametrize(
    "key,axis,omega", [("yaw60", (0, 1, 0), 60.0), ("obl30", tuple(OBLIQUE), 30.0)]
)
def test_rotating_panorama_matches_analytic_truth(tmp_path, videos, key, axis, omega):
    out = preprocess_video(videos[key], tmp_path / "g.npz", grid=SMALL, progress=False)
    g = load_grid(out)
    assert g.pof_dps.shape == (4, *SMALL.shape)
    assert np.array_equal(g.pof_dps[0], g.pof_dps[1])  # frame 0 repeats frame 1
    rel = np.abs(
        g.pof_dps[1:] - _truth_dps(SMALL, np.asarray(axis) / np.linalg.norm(axis), omega)
    ) / _truth_dps(SMALL, np.asarray(axis) / np.linalg.norm(axis), omega)
    # Small version of the bench (1024x512, 64 px windows): measured median 0.04-0.06.
    assert np.median(rel) < 0.10
    assert np.percentile(rel, 90) < 0.25


def test_still_video_is_still(tmp_path, videos):
    g = load_grid(preprocess_video(videos["still"], tmp_path / "g.npz", grid=SMALL, progress=False))
    assert g.pof_dps.max() < 0.5
    assert g.pof_px.max() < 0.05


def test_meta_complete(tmp_path, videos):
    g = load_grid(
        preprocess_video(
            videos["yaw60"], tmp_path / "g.npz", grid=SMALL, flow="dis:fast", progress=False
        )
    )
    m = g.meta
    assert m["fps"] == FPS and m["n_frames"] == 4 and m["layout"] == "mono" and m["eye"] == "left"
    assert m["flow"]["method"] == "dis" and m["flow"]["preset"] == "fast"
    assert m["grid"]["size"] == [64, 64] and m["grid"]["hfov_deg"] == 107.0
    assert (m["video"]["width"], m["video"]["height"], m["video"]["sar"]) == (1024, 512, 1.0)
    assert m["video"]["content_hash"].startswith("sha256:")
    assert (m["start_frame"], m["end_frame"]) == (0, 4)
    assert m["reduce_stride"] == 2  # DIS fast: flow read where it is computed
    assert list(g.yaw_deg) == list(SMALL.yaw_deg) and list(g.pitch_deg) == list(SMALL.pitch_deg)


# ------------------------------------------------------------- checkpoint / resume
def test_ctrl_c_then_resume_is_bit_identical(tmp_path, videos, ref_long):
    ref = ref_long
    out = tmp_path / "g.npz"

    def stop(row):
        if row == 3:
            raise KeyboardInterrupt

    with pytest.raises(PreprocessInterrupted, match="--resume"):
        preprocess_video(videos["long"], out, grid=TINY, progress=False, on_frame=stop)
    assert not out.exists() and checkpoint_path(out).exists()
    with pytest.raises(InputError, match="--resume"):  # refuses to silently restart
        preprocess_video(videos["long"], out, grid=TINY, progress=False)
    g = load_grid(preprocess_video(videos["long"], out, grid=TINY, progress=False, resume=True))
    assert np.array_equal(g.pof_dps, ref.pof_dps) and np.array_equal(g.pof_px, ref.pof_px)
    assert g.meta == {**ref.meta}
    assert not checkpoint_path(out).exists()


class _Killed(BaseException):
    """Stands in for kill -9: not a KeyboardInterrupt, so no checkpoint is written on exit."""


def test_kill9_keeps_periodic_checkpoint(tmp_path, videos, ref_long):
    ref = ref_long
    out = tmp_path / "g.npz"

    def die(row):
        if row == 5:
            raise _Killed

    with pytest.raises(_Killed):
        preprocess_video(
            videos["long"], out, grid=TINY, progress=False, checkpoint_every_s=0, on_frame=die
        )
    assert not out.exists()
    with np.load(checkpoint_path(out), allow_pickle=False) as z:
        # on_frame(5) runs before row 5's periodic save: rows 0..4 survive.
        assert json.loads(str(z["meta"]))["done"] == 5
    g = load_grid(preprocess_video(videos["long"], out, grid=TINY, progress=False, resume=True))
    assert np.array_equal(g.pof_dps, ref.pof_dps) and np.array_equal(g.pof_px, ref.pof_px)


def _full_disk_at(monkeypatch, name: str, fail_call: int, seen: dict):
    """``np.<name>`` fails as a full disk does from its ``fail_call``-th call on: it writes
    a few bytes of the temporary file, then ENOSPC. ``seen["ckpt"]`` records the
    checkpoint's bytes at the failing call (what must survive)."""
    real = getattr(np, name)
    calls = {"n": 0}

    def full(fh, *a, **k):
        calls["n"] += 1
        if calls["n"] < fail_call:
            return real(fh, *a, **k)
        ck = seen["path"]
        seen["ckpt"] = ck.read_bytes() if ck.exists() else None
        fh.write(b"PK\x03\x04partial")
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(np, name, full)
    return calls


@pytest.mark.parametrize("where", ["checkpoint", "grid"])
def test_full_disk_keeps_checkpoint_resumable(
    tmp_path, videos, ref_long, monkeypatch, capsys, where
):
    """ENOSPC while paper-mode preprocess writes its 4th checkpoint, or the final grid:
    exit 1 with one line naming the file and the OS error, no temporary file, the last
    checkpoint byte-for-byte intact, and --resume (space freed) gives the grid of an
    uninterrupted run."""
    out = tmp_path / "g.npz"
    ck = checkpoint_path(out)
    seen = {"path": ck}
    argv = [videos["long"], "-o", out, "--grid", "paper-198", "--window-size", 32,
            "--checkpoint-every", 1e-6]  # fmt: skip
    with monkeypatch.context() as m:
        if where == "checkpoint":
            calls = _full_disk_at(m, "savez", 4, seen)
        else:
            calls = _full_disk_at(m, "savez_compressed", 1, seen)
        assert _cli(*argv) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "No space left on device" in err and "Traceback" not in err
    assert (ck.name if where == "checkpoint" else out.name) in err
    assert calls["n"] == (4 if where == "checkpoint" else 1)  # it failed where we said
    assert seen["ckpt"] is not None and ck.read_bytes() == seen["ckpt"]  # intact
    assert sorted(p.name for p in tmp_path.iterdir()) == [ck.name]  # no temporary, no grid
    with np.load(ck, allow_pickle=False) as z:
        done = json.loads(str(z["meta"]))["done"]
    assert done == (4 if where == "checkpoint" else 8)
    assert _cli(*argv, "--resume") == 0
    g = load_grid(out)
    assert np.array_equal(g.pof_dps, ref_long.pof_dps) and np.array_equal(g.pof_px, ref_long.pof_px)
    assert not ck.exists()


def test_real_kill9_subprocess(tmp_path, videos):
    """A real SIGKILL of `vimsim preprocess` mid-run; --resume then finishes the grid."""
    out = tmp_path / "g.npz"
    code = (
        "import os, signal, sys\n"
        "from simulator.sphere.windows import grid_preset\n"
        "from simulator.preprocess import preprocess_video\n"
        "def hook(row):\n"
        "    if row == 4: os.kill(os.getpid(), signal.SIGKILL)\n"
        f"preprocess_video({str(videos['long'])!r}, {str(out)!r}, grid=grid_preset('paper-198', size=(32, 32)),"
        " progress=False, checkpoint_every_s=0, on_frame=hook)\n"
    )
    r = subprocess.run([sys.executable, "-c", code], check=False, capture_output=True, timeout=120)
    assert r.returncode == -9
    assert not out.exists() and checkpoint_path(out).exists()
    assert (
        _cli(videos["long"], "-o", out, "--grid", "paper-198", "--window-size", 32, "--resume") == 0
    )
    assert load_grid(out).pof_dps.shape == (8, *TINY.shape)


def test_resume_mismatch_names_the_difference(tmp_path, videos, capsys):
    out = tmp_path / "g.npz"
    with pytest.raises(PreprocessInterrupted):
        preprocess_video(
            videos["long"],
            out,
            grid=TINY,
            progress=False,
            on_frame=lambda r: (_ for _ in ()).throw(KeyboardInterrupt) if r == 2 else None,
        )
    with pytest.raises(InputError, match="flow.preset"):
        preprocess_video(
            videos["long"], out, grid=TINY, flow="dis:fast", progress=False, resume=True
        )
    rc = _cli(videos["yaw60"], "-o", out, "--grid", "paper-198", "--window-size", 32, "--resume")
    err = capsys.readouterr().err.strip()
    assert rc == 2 and len(err.splitlines()) == 1 and "video.content_hash" in err
    assert not out.exists()


def test_end_then_resume_longer_is_refused(tmp_path, videos):
    out = tmp_path / "g.npz"
    with pytest.raises(PreprocessInterrupted):
        preprocess_video(
            videos["long"],
            out,
            grid=TINY,
            progress=False,
            end_s=6 / FPS,
            on_frame=lambda r: (_ for _ in ()).throw(KeyboardInterrupt) if r == 2 else None,
        )
    with pytest.raises(InputError, match="end_frame"):
        preprocess_video(videos["long"], out, grid=TINY, progress=False, resume=True)


def test_start_end_range(tmp_path, videos, ref_long):
    full = ref_long
    part = load_grid(
        preprocess_video(
            videos["long"],
            tmp_path / "b.npz",
            grid=TINY,
            progress=False,
            start_s=2 / FPS,
            end_s=6 / FPS,
        )
    )
    assert part.pof_dps.shape[0] == 4 and part.meta["start_frame"] == 2
    assert np.array_equal(part.pof_dps[1:], full.pof_dps[3:6])


# ---------------------------------------------------------------------- real clips
@pytest.mark.parametrize(
    "name,extra",
    [
        ("pano.mp4", []),
        ("pano.webm", []),
        ("MaryOculus.mp4", ["--layout", "side-by-side", "--eye", "right"]),
    ],
)
def test_real_clips(tmp_path, real_dir, name, extra, capsys):
    out = tmp_path / "g.npz"
    src = real_dir / "equirect" / "threejs" / name
    rc = _cli(src, "-o", out, "--window-size", 48, "--grid", "paper-198", "--end", 0.2, *extra)
    assert rc == 0, capsys.readouterr().err
    g = load_grid(out)
    assert g.pof_dps.shape[1:] == (11, 18) and g.pof_dps.shape[0] == round(0.2 * g.fps)
    assert np.all(g.pof_dps >= 0) and np.all(np.isfinite(g.pof_dps))
    if name == "MaryOculus.mp4":
        assert g.meta["eye_size"] == [960, 1024] and g.meta["eye"] == "right"


# ----------------------------------------------------------------------- bad input
def _video(path, n, size=(128, 64)):
    return write_clip(path, noise_frames(n, size), FPS, preset="veryfast")


def _zero_frame_video(path):
    c = av.open(str(path), "w", format="avi")
    s = c.add_stream("mpeg4", rate=30)
    s.width, s.height, s.pix_fmt = 128, 64, "yuv420p"
    c.start_encoding()
    c.close()
    return path


def _corrupt_stream_video(path):
    """Valid header (moov first), garbage frame data."""
    c = av.open(str(path), "w", options={"movflags": "faststart"})
    s = c.add_stream("libx264", rate=30)
    s.width, s.height, s.pix_fmt = 128, 64, "yuv420p"
    rng = np.random.default_rng(0)
    for _ in range(6):
        for pk in s.encode(
            av.VideoFrame.from_ndarray(
                rng.integers(0, 255, (64, 128, 3), dtype=np.uint8), format="rgb24"
            )
        ):
            c.mux(pk)
    for pk in s.encode():
        c.mux(pk)
    c.close()
    data = bytearray(path.read_bytes())
    i = data.find(b"mdat") + 4
    data[i:] = rng.integers(0, 256, len(data) - i, dtype=np.uint8).tobytes()
    path.write_bytes(bytes(data))
    return path


def _not_flow_model(path):
    torch = pytest.importorskip("torch")

    class One(torch.nn.Module):
        def forward(self, a, b):
            return a[:, :1] - b[:, :1]

    torch.jit.script(One()).save(str(path))
    return f"torch:{path}"


@pytest.mark.parametrize(
    "case,match",
    [
        ("not_video", "not a readable video"),
        ("zero_frames", "no frames"),
        ("one_frame", "at least 2 frames"),
        ("unreadable", "unreadable video stream"),
        ("not_2to1", "2:1"),
        ("unknown_flow", "unknown flow backend"),
        ("not_flow_model", "not a flow model"),
        ("still_image", "still image"),
        ("start_past_end", "past the end"),
        ("no_out_dir", "does not exist"),
    ],
)
def test_bad_input_one_line_exit_2_no_output(tmp_path, capsys, case, match):
    flow, extra = "dis", []
    if case == "not_video":
        src = tmp_path / "x.mp4"
        src.write_text("not a video\n")
    elif case == "zero_frames":
        src = _zero_frame_video(tmp_path / "z.avi")
    elif case == "one_frame":
        src = _video(tmp_path / "one.mp4", 1)
    elif case == "unreadable":
        src = _corrupt_stream_video(tmp_path / "bad.mp4")
    elif case == "not_2to1":
        src = _video(tmp_path / "sq.mp4", 3, size=(64, 64))
    elif case == "still_image":
        src = tmp_path / "img.png"
        Image.fromarray(np.zeros((32, 64, 3), np.uint8)).save(src)
    else:
        src = _video(tmp_path / "ok.mp4", 3)
        if case == "unknown_flow":
            flow = "lucas-kanade"
        elif case == "not_flow_model":
            flow = _not_flow_model(tmp_path / "one.pt")
        elif case == "start_past_end":
            extra = ["--start", "5"]
    out = tmp_path / ("missing/g.npz" if case == "no_out_dir" else "g.npz")
    rc = _cli(src, "-o", out, "--window-size", 32, "--flow", flow, *extra)
    err = capsys.readouterr().err.strip()
    assert rc == 2
    assert len(err.splitlines()) == 1, err
    assert match in err
    assert not out.exists() and not checkpoint_path(out).exists()
    assert not [p for p in tmp_path.iterdir() if p.suffix == ".npz"]


def test_torch_backend_end_to_end(tmp_path, videos):
    """A TorchScript model returning constant flow (1.5, -0.5) px: pof_px is its length in
    every window, pof_dps the reduction of that field (same for every window)."""
    torch = pytest.importorskip("torch")

    class Const(torch.nn.Module):
        def forward(self, a, b):
            n, _, h, w = a.shape
            v = torch.tensor([1.5, -0.5], device=a.device).view(1, 2, 1, 1)
            return v.expand(n, 2, h, w) + 0.0 * (a[:, :2] - b[:, :2])

    model = tmp_path / "const.pt"
    torch.jit.script(Const()).save(str(model))
    out = tmp_path / "g.npz"
    assert (
        _cli(
            videos["long"],
            "-o",
            out,
            "--grid",
            "paper-198",
            "--window-size",
            32,
            "--flow",
            f"torch:{model}",
        )
        == 0
    )
    g = load_grid(out)
    assert g.meta["flow"]["method"] == "torch"
    assert np.allclose(g.pof_px, np.hypot(1.5, 0.5), rtol=1e-6)
    field = np.broadcast_to(np.float32([1.5, -0.5]), (1, 32, 32, 2))
    dps, _ = WindowFlowReducer((32, 32), 107.0, 107.0)(field, FPS)
    assert np.allclose(g.pof_dps, dps[0], rtol=1e-6)


def test_top_bottom_stereo_eyes(tmp_path, real_dir, capsys):
    """vrview's top-bottom stereo panorama, shifted per frame: each eye gets its own grid."""
    img = Image.open(real_dir / "equirect" / "vrview" / "dolphins_stereo_tb.jpg").convert("RGB")
    img = np.asarray(img.resize((256, 256), Image.LANCZOS))
    frames = (np.ascontiguousarray(np.roll(img, 2 * i, axis=1)) for i in range(3))
    src = write_clip(tmp_path / "tb.mp4", frames, FPS, preset="veryfast")
    grids = {}
    for eye in ("left", "right"):
        out = tmp_path / f"{eye}.npz"
        assert (
            _cli(src, "-o", out, "--layout", "top-bottom", "--eye", eye, "--window-size", 32) == 0
        )
        grids[eye] = load_grid(out)
        assert grids[eye].meta["eye_size"] == [256, 128]
    assert not np.array_equal(grids["left"].pof_px, grids["right"].pof_px)
    # Both eyes see the same yaw motion, 2 px of 256 per frame = 2.8125 deg/frame: the
    # equator row of windows must match the analytic truth (measured ratio 0.95).
    truth = _truth_dps(
        grid_preset("default", size=(32, 32)), np.array([0.0, 1.0, 0.0]), 2.8125 * FPS
    )
    for g in grids.values():
        assert abs(np.median(g.pof_dps[1:, 5]) / np.median(truth[5]) - 1) < 0.15
    # Mono is refused for a 1:1 frame with a hint.
    assert _cli(src, "-o", tmp_path / "m.npz", "--window-size", 32) == 2
    assert "top-bottom" in capsys.readouterr().err


def test_fov_options(tmp_path, videos, capsys):
    out = tmp_path / "g.npz"
    assert _cli(videos["long"], "-o", out, "--fov", 90, "--hfov", 80) == 2
    assert "give only one of --fov, --hfov/--vfov" in capsys.readouterr().err
    assert not out.exists()
    assert (
        _cli(
            videos["long"], "-o", out, "--hfov", 90, "--vfov", 60, "--window-size", 24, "--end", 0.1
        )
        == 0
    )
    m = load_grid(out).meta
    assert (m["grid"]["hfov_deg"], m["grid"]["vfov_deg"], m["grid"]["size"]) == (
        90.0,
        60.0,
        [24, 24],
    )


def _min_size_model(path):
    """Like RAFT: raises for images smaller than 128 px, else zero flow."""
    torch = pytest.importorskip("torch")

    class MinSize(torch.nn.Module):
        def forward(self, a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
            if a.shape[-1] < 128 or a.shape[-2] < 128:
                raise ValueError("input images should be at least 128 px")
            return 0.0 * (a[:, :2] - b[:, :2])

    torch.jit.script(MinSize()).save(str(path))
    return f"torch:{path}"


@pytest.mark.slow
def test_torch_model_checked_at_the_window_size(tmp_path, capsys, videos):
    """A model with a minimum input size (RAFT needs 128 px) is checked at the windows it
    will get: it works at 128 px windows, and at 32 px fails with its own reason, before
    any output."""
    flow = _min_size_model(tmp_path / "min.pt")
    out = tmp_path / "g.npz"
    assert _cli(videos["long"], "-o", out, "--window-size", 128, "--flow", flow, "--end", 0.2) == 0
    assert load_grid(out).meta["flow"]["method"] == "torch"
    bad = tmp_path / "small.npz"
    assert _cli(videos["long"], "-o", bad, "--window-size", 32, "--flow", flow) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    assert "32x32 px windows" in err and "at least 128 px" in err
    assert not bad.exists()


def test_reducer_stride_reads_upsampled_flow_unchanged():
    """DIS ultrafast/fast compute flow at 1/4 resolution and upsample it bilinearly: the
    stride-2 reduction of such a field agrees with the full one (analytic rotation flow,
    coarse field upsampled as DIS does)."""
    import cv2

    from simulator.flow.dis import DISFlow
    from simulator.flow.farneback import FarnebackFlow
    from simulator.preprocess import reduce_stride

    w = h = 64
    rng = np.random.default_rng(3)
    coarse = rng.normal(0, 2.0, (h // 4, w // 4, 2)).astype(np.float32) + np.float32([3, -1])
    flow = cv2.resize(coarse, (w, h), interpolation=cv2.INTER_LINEAR)[None]
    full = WindowFlowReducer((w, h), 107.0, 107.0)(flow, FPS)
    half = WindowFlowReducer((w, h), 107.0, 107.0, stride=2)(flow, FPS)
    assert np.allclose(half[0], full[0], rtol=5e-3) and np.allclose(half[1], full[1], rtol=5e-3)
    # ... and a field with pixel-scale detail is not: the stride is only for such backends.
    fine = np.zeros((1, h, w, 2), np.float32)
    fine[0, 1::2, 1::2, 0] = 5.0  # detail at the pixel scale, on the sampled pixels only
    a = WindowFlowReducer((w, h), 107.0, 107.0)(fine, FPS)[0]
    b = WindowFlowReducer((w, h), 107.0, 107.0, stride=2)(fine, FPS)[0]
    assert not np.allclose(a, b, rtol=5e-3)
    assert reduce_stride(DISFlow("ultrafast")) == reduce_stride(DISFlow("fast")) == 2
    assert reduce_stride(DISFlow("medium")) == reduce_stride(FarnebackFlow()) == 1


def test_fused_pipeline_equals_batch_path(tmp_path, videos, ref_long):
    """The fused path (flow + reduction per window in the workers, two frame pairs in
    flight, recycled window buffers; threads > 1) gives exactly the grid of the plain path
    (one thread: backend batch call, then the reducer), and both equal a brute
    recomputation from independently decoded and extracted frames."""
    plain = load_grid(
        preprocess_video(videos["long"], tmp_path / "one.npz", grid=TINY, threads=1, progress=False)
    )
    for name in ("pof_dps", "pof_px"):
        assert np.array_equal(getattr(plain, name), getattr(ref_long, name)), name
    from simulator.flow.base import make_backend
    from simulator.media.video import iter_frames
    from simulator.preprocess import WindowFlowReducer, reduce_stride
    from simulator.sphere.windows import WindowExtractor

    fr = [np.array(f) for f in iter_frames(videos["long"], fmt="gray")]
    ex = WindowExtractor(TINY, (fr[0].shape[1], fr[0].shape[0]), cache=False)
    be = make_backend("dis")
    red = WindowFlowReducer(TINY.size, TINY.hfov_deg, TINY.vfov_deg, stride=reduce_stride(be))
    n, (w, h) = TINY.n_windows, TINY.size
    fps = float(plain.meta["fps"])
    wins = [ex(f, interp="linear").reshape(n, h, w) for f in fr[:3]]
    for t in (1, 2):
        d, x = red(be(wins[t - 1], wins[t]), fps)
        assert np.array_equal(d.astype(np.float32).reshape(TINY.shape), ref_long.pof_dps[t])
        assert np.array_equal(x.astype(np.float32).reshape(TINY.shape), ref_long.pof_px[t])
