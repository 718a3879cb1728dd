"""Variable frame rate: frame times from the stream's timestamps, everywhere."""

from __future__ import annotations

import json
import subprocess
from fractions import Fraction
from types import SimpleNamespace

import numpy as np
import pytest

from simulator.cli import main
from simulator.core.errors import InputError
from simulator.epof.viewing import read_epof_csv
from simulator.media.gridfile import load_grid
from simulator.media.video import _count_frames, probe
from simulator.testing.reference import ffmpeg_exe
from simulator.traces.path import save_headpath_csv, synth


@pytest.fixture(scope="module")
def clips(tmp_path_factory):
    d = tmp_path_factory.mktemp("vfr")
    assert main(["synth", str(d / "r.mp4"), "--scene", "rotate", "--seconds", "1.2", "--fps", "30",
                 "--size", "128x64"]) == 0  # fmt: skip
    ff = [ffmpeg_exe(), "-v", "error", "-y"]
    subprocess.run([*ff, "-i", str(d / "r.mp4"), "-vf", "select='not(eq(mod(n\\,3)\\,2))'",
                    "-fps_mode", "vfr", "-c:v", "libx264", "-crf", "10", str(d / "vfr.mp4")],
                   check=True)  # fmt: skip
    subprocess.run([*ff, "-itsoffset", "1.0", "-i", str(d / "r.mp4"), "-f", "lavfi", "-i",
                    "sine=duration=2.5", "-map", "0:v", "-map", "1:a", "-c:v", "copy", "-c:a", "aac",
                    str(d / "late.mp4")], check=True)  # fmt: skip
    save_headpath_csv(d / "p.csv", synth("static", 3.0, rate_hz=60.0))
    return d


def test_frame_times_come_from_the_timestamps(clips):
    info = probe(clips / "vfr.mp4")
    assert info.variable_rate and info.n_frames == 24
    assert np.allclose(info.times_s()[:5], [0, 1 / 30, 3 / 30, 4 / 30, 6 / 30], atol=1e-3)
    assert int(info.frame_at(0.09)) == 1 and int(info.frame_at(0.1)) == 2
    late = probe(clips / "late.mp4")  # video 1 s after the container's (audio's) start
    assert late.variable_rate and abs(late.times_s()[0] - 1.0) < 1e-3
    assert probe(clips / "r.mp4").frame_times is None  # constant rate from 0: i / fps


def test_flow_uses_the_true_interval_and_rows_carry_the_true_times(clips, tmp_path):
    g = tmp_path / "g.npz"
    assert main(["preprocess", str(clips / "vfr.mp4"), "-o", str(g), "--method", "sphere",
                 "--cell", "10", "--no-progress"]) == 0  # fmt: skip
    grid = load_grid(g)
    assert np.allclose(grid.meta["frame_times_s"][:3], [0, 1 / 30, 0.1], atol=1e-3)
    assert main(["epof", str(g), str(clips / "p.csv"), "-o", str(tmp_path / "e.csv")]) == 0
    r = read_epof_csv(tmp_path / "e.csv")
    assert np.allclose(r.time_s[:3], [0, 1 / 30, 0.1], atol=1e-3)
    gap = np.diff(r.time_s) > 0.05  # rows after a 2/30 s gap
    e = r.epof_dps[1:]
    # same rotation speed after a gap (index / fps would read twice the speed)
    assert abs(np.median(e[gap]) / np.median(e[~gap]) - 1) < 0.15


def test_a_late_video_stream_is_placed_on_the_players_clock(ctx, clips, tmp_path):
    out = tmp_path / "r"
    assert main(["render", str(clips / "late.mp4"), str(clips / "p.csv"), "-o", str(out),
                 "--opacity", "0.5", "--eye-size", "32x32", "--no-progress", "--no-audio"]) == 0  # fmt: skip
    lines = [ln for ln in (out / "epof.csv").read_text().splitlines() if not ln.startswith("#")]
    t = [float(ln.split(",")[1]) for ln in lines[1:]]
    assert abs(t[0] - 1.0) < 1e-3 and abs(t[1] - 1.0 - 1 / 30) < 1e-3
    s = json.loads((out / "summary.json").read_text())
    assert abs(s["range_s"][0] - 1.0) < 1e-3


def _fake(dts, pts):
    pk = [SimpleNamespace(size=1, is_discard=False, dts=a, pts=b) for a, b in zip(dts, pts)]
    c = SimpleNamespace(demux=lambda s: iter(pk), start_time=0)
    return c, SimpleNamespace(time_base=Fraction(1, 30))


@pytest.mark.parametrize(
    "dts,pts,word",
    [([0, 1, 2, 1, 4], [0, 1, 2, 3, 4], "go backwards or repeat at frame 3"),
     ([0, 1, 2, 3, 4], [0, 1, 1, 3, 4], "repeat at frame 2")],
)  # fmt: skip
def test_backwards_or_repeated_timestamps_refused_naming_the_frame(dts, pts, word):
    c, s = _fake(dts, pts)
    with pytest.raises(InputError, match=word):
        _count_frames(c, s, "x.mp4")


def test_render_keeps_the_sources_timing(ctx, clips, tmp_path):
    out = tmp_path / "r"
    assert main(["render", str(clips / "vfr.mp4"), str(clips / "p.csv"), "-o", str(out),
                 "--opacity", "0.5", "--eye-size", "32x32", "--no-progress"]) == 0  # fmt: skip
    t = probe(out / "left.mp4").times_s()
    assert np.allclose(t[:5], [0, 1 / 30, 3 / 30, 4 / 30, 6 / 30], atol=2e-3)


def _pts_s(path) -> tuple[np.ndarray, float]:
    """Each frame's presentation time (seconds, in presentation order) and the stream's
    tick (seconds)."""
    import av

    with av.open(str(path)) as c:
        s = c.streams.video[0]
        pts = sorted(int(p.pts) for p in c.demux(s) if p.pts is not None and p.size)
        return np.asarray(pts, float) * float(s.time_base), float(s.time_base)


def test_review_video_keeps_the_sources_timing(ctx, clips, tmp_path):
    out = tmp_path / "r"
    assert main(["render", str(clips / "vfr.mp4"), str(clips / "p.csv"), "-o", str(out),
                 "--opacity", "0.5", "--eye-size", "32x32", "--no-progress", "--review",
                 "--no-audio"]) == 0  # fmt: skip
    src, tick = _pts_s(clips / "vfr.mp4")
    for name in ("review.mp4", "left.mp4"):
        t, out_tick = _pts_s(out / name)
        assert len(t) == len(src) == 24
        # every frame at the source's time (from its first frame) within one tick
        assert np.abs((t - t[0]) - (src - src[0])).max() <= max(tick, out_tick) + 1e-9, name
