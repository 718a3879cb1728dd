"""vimsim frames / compare / simulator.testing.goldens: an unchanged setup passes, real changes fail with the frame named."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from media_helpers import write_clip

FPS = 10
N = 20


def _texture(shift: int = 0) -> np.ndarray:
    """A smooth random colour texture 256x128 (seeded), plus ``shift`` levels of red."""
    import cv2

    rng = np.random.default_rng(7)
    small = rng.integers(0, 256, (16, 32, 3)).astype(np.uint8)
    img = cv2.resize(small, (256, 128), interpolation=cv2.INTER_CUBIC).astype(np.int16)
    img[..., 0] += shift
    return np.clip(img, 0, 255).astype(np.uint8)


def _video(path: Path, shift: int = 0) -> Path:

    base = _texture(shift)  # the scene scrolls 4 px per frame
    frames = (np.ascontiguousarray(np.roll(base, 4 * i, axis=1)) for i in range(N))
    return write_clip(path, frames, FPS, crf=0)


@pytest.fixture(scope="module")
def clip(tmp_path_factory):
    d = tmp_path_factory.mktemp("frames")
    p = d / "path.csv"
    p.write_text("time_s,yaw_deg,pitch_deg,roll_deg\n0,0,0,0\n2,40,10,0\n")
    return {
        "video": _video(d / "clip.mp4"),
        "shifted": _video(d / "shifted.mp4", shift=6),
        "path": p,
        "dir": d,
    }


def _frames(ctx, clip, out, *, video=None, path=None, grain=1.5, at="0.25,1.05,1.9"):
    from simulator.mitigation.grf import GrfConfig
    from simulator.render import RenderConfig
    from simulator.viewing.frames import render_frames

    cfg = RenderConfig(eye_size=(96, 96), grf=GrfConfig(grain_deg=grain))
    return render_frames(
        video or clip["video"], path or clip["path"], out, at=at, config=cfg, opacity=0.8, ctx=ctx
    )


@pytest.fixture(scope="module")
def golden(ctx, clip):
    g = clip["dir"] / "golden"
    _frames(ctx, clip, g)
    return g


def test_decode_frames_matches_sequential_decoding(real_dir):
    """Seek-based decoding against decoding every frame (three.js MaryOculus.mp4, real H.264)."""
    from simulator.media.video import iter_frames
    from simulator.viewing.frames import decode_frames

    p = real_dir / "equirect" / "threejs" / "MaryOculus.mp4"
    want = [0, 7, 64, 119]
    got = decode_frames(p, want)
    ref = {i: np.array(f) for i, f in enumerate(iter_frames(p)) if i in want}
    assert sorted(got) == want
    for i in want:
        assert np.array_equal(got[i], ref[i]), i


def test_frames_index_and_determinism(ctx, clip, golden, tmp_path):
    index = json.loads((golden / "frames.json").read_text())
    assert [f["frame"] for f in index["frames"]] == [2, 10, 19]  # floor(t * fps)
    assert [f["file"] for f in index["frames"]] == [
        "t0000.250_both.png",
        "t0001.050_both.png",
        "t0001.900_both.png",
    ]
    from simulator.traces.readers import load_headpath

    yaw, pitch, _ = load_headpath(clip["path"]).sample_angles_deg(np.array([1.0]))
    assert index["frames"][1]["yaw_deg"] == pytest.approx(yaw[0])  # the pose of frame 10 (t=1 s)
    assert index["frames"][1]["pitch_deg"] == pytest.approx(pitch[0])
    assert index["frames"][0]["opacity"] == 0.8
    again = tmp_path / "again"
    _frames(ctx, clip, again)
    for f in index["frames"]:
        assert (again / f["file"]).read_bytes() == (golden / f["file"]).read_bytes()


def test_frames_equal_the_render_pass(ctx, clip, golden):
    """The PNG is what EyeRenderer draws for that frame and pose (brute force: one view)."""
    from PIL import Image

    from simulator.media.video import read_frame
    from simulator.mitigation.grf import GrfConfig
    from simulator.render import RenderConfig, render_view

    frame = read_frame(clip["video"], 10)
    cfg = RenderConfig(eye_size=(96, 96), grf=GrfConfig())
    from simulator.traces.readers import load_headpath

    yaw, pitch, roll = load_headpath(clip["path"]).sample_angles_deg(np.array([1.0]))
    ref = render_view(ctx, frame, yaw[0], pitch[0], roll[0], config=cfg, opacity=0.8)
    got = np.asarray(Image.open(golden / "t0001.050_both.png"))
    assert np.array_equal(got, ref)


def test_unchanged_setup_passes(ctx, clip, golden, tmp_path):
    from simulator.testing.goldens import assert_frames_match

    _frames(ctx, clip, tmp_path / "new")
    rep = assert_frames_match(tmp_path / "new", golden)
    assert all(s.psnr_db == float("inf") and s.ssim == 1.0 for s in rep.scores)


@pytest.mark.parametrize("change", ["yaw", "grain", "colour"])
def test_changes_fail_naming_the_frame(ctx, clip, golden, tmp_path, change):
    from simulator.testing.goldens import assert_frames_match

    kw = {}
    if change == "yaw":  # 1 deg more yaw everywhere
        p = tmp_path / "path.csv"
        p.write_text("time_s,yaw_deg,pitch_deg,roll_deg\n0,1,0,0\n2,41,10,0\n")
        kw["path"] = p
    elif change == "grain":
        kw["grain"] = 2.0
    else:
        kw["video"] = clip["shifted"]
    _frames(ctx, clip, tmp_path / "new", **kw)
    with pytest.raises(AssertionError) as e:
        assert_frames_match(tmp_path / "new", golden)
    msg = str(e.value)
    assert "frame t0001.050_both.png" in msg
    assert "PSNR" in msg or "mean abs diff" in msg
    assert str(tmp_path / "new" / "compare" / "t0001.050_both.diff.png") in msg
    assert (tmp_path / "new" / "compare" / "t0001.050_both.side.png").is_file()


def test_cli_frames_compare_exit_codes(ctx, clip, golden, tmp_path, capsys):
    from simulator.cli import main

    out = tmp_path / "cli"
    args = [str(clip["video"]), str(clip["path"]), "-o", str(out), "--eye-size", "96x96"]
    args += ["--opacity", "0.8", "--no-progress", "--at", "0.25,1.05,1.9"]
    assert main(["frames", *args]) == 0
    assert main(["compare", str(out), str(golden)]) == 0
    shifted = tmp_path / "shifted"
    args[0] = str(clip["shifted"])
    args[3] = str(shifted)
    assert main(["frames", *args]) == 0
    capsys.readouterr()
    assert main(["compare", str(shifted), str(golden)]) == 1
    cap = capsys.readouterr()
    assert "FAIL frame t0000.250_both.png" in cap.err
    assert cap.out.startswith("vimsim compare: the input files differ: video")  # before figures
    g2 = tmp_path / "g2"
    assert main(["compare", str(out), str(g2), "--update"]) == 0  # creates the goldens
    before = {q.name: q.read_bytes() for q in g2.iterdir()}
    capsys.readouterr()
    assert main(["compare", str(shifted), str(g2), "--update"]) == 1  # refused: frames fail
    assert "NOT updated" in capsys.readouterr().err
    assert {q.name: q.read_bytes() for q in g2.iterdir()} == before
    assert main(["compare", str(shifted), str(g2), "--update", "--force"]) == 0
    assert main(["compare", str(shifted), str(g2)]) == 0
    (backup,) = tmp_path.glob("g2.backup-*")  # the replaced goldens, dated, beside them
    assert {q.name: q.read_bytes() for q in backup.iterdir()} == before
    assert main(["compare", str(out), str(backup)]) == 0  # the backup is a golden folder


@pytest.mark.parametrize(
    ("at", "match"),
    [("0.5,2.0", "outside the video"), ("-1", "outside the video"), ("", "--at"), ("1,,2", "--at")],
)
def test_cli_frames_bad_times(ctx, clip, tmp_path, capsys, at, match):
    from simulator.cli import main

    out = tmp_path / "o"
    rc = main(["frames", str(clip["video"]), str(clip["path"]), "-o", str(out), f"--at={at}"])
    err = capsys.readouterr().err
    assert rc == 2
    assert match in err
    assert len(err.strip().splitlines()) == 1
    assert not out.exists()


def test_cli_compare_bad_goldens(ctx, clip, golden, tmp_path, capsys):
    import shutil

    from PIL import Image

    from simulator.cli import main

    new = tmp_path / "new"
    shutil.copytree(golden, new)
    other = tmp_path / "other"  # frames of another size
    shutil.copytree(golden, other)
    Image.new("RGB", (64, 64)).save(other / "t0000.250_both.png")
    junk = tmp_path / "junk"  # a non-PNG in the golden folder
    shutil.copytree(golden, junk)
    (junk / "notes.txt").write_text("x")
    missing = tmp_path / "missing"
    shutil.copytree(golden, missing)
    (missing / "t0001.900_both.png").unlink()
    for g, match in ((other, "64x64"), (junk, "not a PNG"), (missing, "no golden")):
        capsys.readouterr()
        assert main(["compare", str(new), str(g)]) == 2
        err = capsys.readouterr().err
        assert match in err
        assert len(err.strip().splitlines()) == 1
    assert not (new / "compare").exists()  # nothing written


def test_failed_frames_run_leaves_no_pngs(ctx, clip, tmp_path, monkeypatch):
    import simulator.viewing.frames as fr

    calls = []

    def flaky(path, img):
        calls.append(path)
        if len(calls) == 2:
            raise OSError(28, "No space left on device")
        return real(path, img)

    real = fr._write_png
    monkeypatch.setattr(fr, "_write_png", flaky)
    with pytest.raises(OSError):
        _frames(ctx, clip, tmp_path / "o")
    assert len(calls) >= 2
    # no PNG, no frames.json: only the folder manifest, saying the run is incomplete
    assert sorted(p.name for p in (tmp_path / "o").iterdir()) == [".vimsim-manifest.json"]
    m = json.loads((tmp_path / "o" / ".vimsim-manifest.json").read_text())
    assert m["state"] == "incomplete" and m["command"] == "frames"
