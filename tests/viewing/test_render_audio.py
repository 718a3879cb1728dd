"""render: the source's audio in the outputs (the range's part), --no-audio, and --right FILE."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

RATE = 48000
FPS = 10
N = 10  # frames: 1.0 s


def _tone(t: np.ndarray) -> np.ndarray:
    """300 Hz before 0.5 s, 900 Hz from 0.5 s: the frequency tells the time."""
    return np.where(t < 0.5, np.sin(2 * np.pi * 300 * t), np.sin(2 * np.pi * 900 * t))


def _clip(path: Path, *, gray=None, size=(128, 64), n=N, fps=FPS, audio="aac", fmt=None):
    """A video of ``n`` frames (frame i uniform gray ``gray`` or 20 + 20 i) with a mono
    tone (:func:`_tone`) over the same second, in codec ``audio`` (None: no audio)."""
    import av

    w, h = size
    with av.open(str(path), "w", format=fmt) as c:
        vs = c.add_stream("libx264", rate=fps)
        vs.width, vs.height, vs.pix_fmt = w, h, "yuv420p"
        vs.options = {"crf": "0", "preset": "ultrafast"}
        a_s = None
        if audio:
            a_s = c.add_stream(audio, rate=RATE)
            a_s.layout = "mono"
            a_s.format = "fltp" if audio == "aac" else "s16"
        for i in range(n):
            g = (20 + 20 * i) % 256 if gray is None else gray
            f = av.VideoFrame.from_ndarray(np.full((h, w, 3), g, np.uint8), format="rgb24")
            for p in vs.encode(f):
                c.mux(p)
        if a_s is not None:
            t = np.arange(int(RATE * n / fps)) / RATE
            x = (0.5 * _tone(t)).astype(np.float32)
            step = 1024
            for k in range(0, len(x), step):
                seg = x[k : k + step]
                if a_s.format.name == "s16":
                    af = av.AudioFrame.from_ndarray(
                        (seg * 32767).astype(np.int16)[None, :], format="s16", layout="mono"
                    )
                else:
                    af = av.AudioFrame.from_ndarray(seg[None, :], format="fltp", layout="mono")
                af.sample_rate = RATE
                af.pts = k
                for p in a_s.encode(af):
                    c.mux(p)
            for p in a_s.encode(None):
                c.mux(p)
        for p in vs.encode(None):
            c.mux(p)


def _audio(path: Path):
    """(codec, decoded mono samples) of the file's audio, or (None, None)."""
    import av

    with av.open(str(path)) as c:
        if not c.streams.audio:
            return None, None
        s = c.streams.audio[0]
        x = np.concatenate([f.to_ndarray().reshape(-1) for f in c.decode(s)])
        return s.codec_context.name, x.astype(float)


def _peak_hz(x: np.ndarray) -> float:
    spec = np.abs(np.fft.rfft(x * np.hanning(len(x))))
    return float(np.fft.rfftfreq(len(x), 1 / RATE)[np.argmax(spec)])


def _path_csv(path: Path) -> Path:
    path.write_text(
        "time_s,yaw_deg,pitch_deg,roll_deg\n"
        + "".join(f"{t:.3f},{20 * t:.3f},0,0\n" for t in np.linspace(0, 1.0, 11))
    )
    return path


def _render(tmp_path, vid, out, *extra):
    from simulator.cli import main

    argv = ["render", str(vid), str(_path_csv(tmp_path / "p.csv")), "-o", str(out),
            "--eye-size", "32x32", "--x264-preset", "ultrafast", "--no-progress", *extra]  # fmt: skip
    return main(argv)


def test_audio_copied_and_range_trimmed(ctx, tmp_path):
    vid = tmp_path / "a.mp4"
    _clip(vid)
    codec_in, x_in = _audio(vid)
    assert codec_in == "aac" and _peak_hz(x_in[: RATE // 2]) == pytest.approx(300, abs=3)

    out = tmp_path / "full"
    assert _render(tmp_path, vid, out, "--review") == 0
    s = json.loads((out / "summary.json").read_text())
    assert s["audio"]["copied"] and s["audio"]["mode"] == "packets copied"
    for name in ("left.mp4", "review.mp4"):
        codec, x = _audio(out / name)
        assert codec == "aac"
        # packets copied: the decoder gives back the source's very samples
        assert len(x) == len(x_in) and np.array_equal(x, x_in)

    # A range: only its audio, in the range's time (its start is t = 0 of the output).
    out = tmp_path / "late"
    assert _render(tmp_path, vid, out, "--start", "0.6", "--end", "1.0") == 0
    _, x = _audio(out / "left.mp4")
    assert abs(len(x) / RATE - 0.4) <= 2 * 1024 / RATE  # packet precision
    assert _peak_hz(x) == pytest.approx(900, abs=5)
    out = tmp_path / "early"
    assert _render(tmp_path, vid, out, "--start", "0", "--end", "0.4") == 0
    _, x = _audio(out / "left.mp4")
    assert abs(len(x) / RATE - 0.4) <= 2 * 1024 / RATE
    assert _peak_hz(x) == pytest.approx(300, abs=5)


def test_no_audio_and_silent_source(ctx, tmp_path):
    vid = tmp_path / "a.mp4"
    _clip(vid)
    out = tmp_path / "o"
    assert _render(tmp_path, vid, out, "--no-audio") == 0
    assert _audio(out / "left.mp4") == (None, None)
    assert json.loads((out / "summary.json").read_text())["audio"] == {
        "copied": False, "why": "off (--no-audio)"}  # fmt: skip
    silent = tmp_path / "s.mp4"
    _clip(silent, audio=None)
    assert _render(tmp_path, silent, tmp_path / "o2") == 0
    assert _audio(tmp_path / "o2" / "left.mp4") == (None, None)
    assert not json.loads((tmp_path / "o2" / "summary.json").read_text())["audio"]["copied"]


def test_audio_mp4_cannot_hold_is_reencoded(ctx, tmp_path):
    vid = tmp_path / "a.mkv"  # PCM audio: MP4 cannot hold it, so it becomes AAC
    _clip(vid, audio="pcm_s16le", fmt="matroska")
    out = tmp_path / "o"
    assert _render(tmp_path, vid, out, "--start", "0.5") == 0
    s = json.loads((out / "summary.json").read_text())
    assert s["audio"]["codec"] == "pcm_s16le" and s["audio"]["mode"] == "re-encoded to AAC"
    codec, x = _audio(out / "left.mp4")
    assert codec == "aac"
    assert abs(len(x) / RATE - 0.5) <= 2 * 1024 / RATE
    assert _peak_hz(x) == pytest.approx(900, abs=5)


def test_right_eye_file(ctx, tmp_path):
    left, right = tmp_path / "l.mp4", tmp_path / "r.mp4"
    _clip(left, gray=60)
    _clip(right, gray=180, audio=None)
    out = tmp_path / "o"
    assert _render(tmp_path, left, out, "--right", str(right)) == 0
    from simulator.media.video import iter_frames

    ml = [float(f.mean()) for f in iter_frames(out / "left.mp4")]
    mr = [float(f.mean()) for f in iter_frames(out / "right.mp4")]
    assert len(ml) == len(mr) == N
    assert np.allclose(ml, 60, atol=3) and np.allclose(mr, 180, atol=3)
    s = json.loads((out / "summary.json").read_text())
    assert s["right"] == str(right) and s["eyes"] == "both" and s["audio"]["copied"]


@pytest.mark.parametrize(
    "kw, word",
    [({"size": (256, 128)}, "size"), ({"fps": 20, "n": 20}, "fps"), ({"n": 9}, "frames")],
)
def test_right_eye_file_mismatch_refused(ctx, tmp_path, capsys, kw, word):
    left, right = tmp_path / "l.mp4", tmp_path / "r.mp4"
    _clip(left, audio=None)
    _clip(right, audio=None, **kw)
    out = tmp_path / "o"
    assert _render(tmp_path, left, out, "--right", str(right)) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(right) in err[0] and word in err[0]
    assert not out.exists()


def test_right_eye_with_stereo_layout_refused(ctx, tmp_path, capsys):
    left, right = tmp_path / "l.mp4", tmp_path / "r.mp4"
    _clip(left, audio=None, size=(128, 128))
    _clip(right, audio=None, size=(128, 128))
    assert _render(tmp_path, left, tmp_path / "o", "--right", str(right),
                   "--layout", "top-bottom") == 2  # fmt: skip
    assert "--layout top-bottom" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_review_shows_the_grid_eye_of_two_eye_files(ctx, tmp_path):
    """With two per-eye files the review panel gets the eye asked for (the grid's eye)."""
    from simulator.media.source import Source
    from simulator.render import RenderConfig
    from simulator.render.video import render_video

    left, right = tmp_path / "l.mp4", tmp_path / "r.mp4"
    _clip(left, gray=60, audio=None)
    _clip(right, gray=180, audio=None)
    for eye, want in (("left", 60), ("right", 180)):
        seen = []
        render_video(ctx, Source.open(left, right=right), (str(tmp_path / f"{eye}L.mp4"), str(tmp_path / f"{eye}R.mp4")),
                     np.zeros((N, 3)), config=RenderConfig(eye_size=(32, 32), grf=None),
                     preset="ultrafast", review_eye=eye,
                     on_frame=lambda eq, img, seen=seen: seen.append((float(eq.mean()), float(img[:32].mean()))))  # fmt: skip
        assert len(seen) == N
        assert np.allclose([s[0] for s in seen], want, atol=3)  # the equirect of that eye
        # its view: the Y plane, limited range (BT.601/709 luma of a gray: 16 + 219 g / 255)
        assert np.allclose([s[1] for s in seen], 16 + 219 * want / 255, atol=3)
