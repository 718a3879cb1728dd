"""render --start/--end: only the frames of the range, in video time."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from media_helpers import gray_frames, write_clip

from simulator.core.errors import InputError
from simulator.viewing.plan import frame_range


def _data_lines(path):
    """The lines of an EPOF CSV without its '#' settings lines (header first)."""
    return [ln for ln in path.read_text().splitlines() if not ln.startswith("#")]


def _ramp_video(path: Path, n: int = 10) -> None:
    """Frame i is a uniform gray of 20 + 20 i: its brightness names the frame."""
    write_clip(path, gray_frames(20 + 20 * i for i in range(n)), crf=0)


def _path_csv(path: Path, end_s: float) -> None:
    path.write_text(
        "time_s,yaw_deg,pitch_deg,roll_deg\n"
        + "".join(f"{t:.3f},{10 * t:.3f},0,0\n" for t in np.linspace(0, end_s, 11))
    )


def _partial_grid(path: Path, start: int, end: int, n_video: int, fps: float = 10.0) -> None:
    """A grid of frames start..end of a 128x64 video, random flow (no preprocessing run)."""
    from simulator.media.gridfile import save_grid
    from simulator.sphere.windows import WindowGrid

    g = WindowGrid()
    rng = np.random.default_rng(0)
    z = rng.uniform(0, 50, (end - start, len(g.pitch_deg), len(g.yaw_deg))).astype(np.float32)
    meta = {"fps": fps, "n_frames": end - start, "start_frame": start, "end_frame": end,
            "flow": {"method": "none"}, "layout": "mono", "eye": "left",
            "video": {"path": "r.mp4", "width": 128, "height": 64, "sar": 1.0,
                      "n_frames": n_video}}  # fmt: skip
    save_grid(path, z, z, g, meta)


def _means(path: Path) -> list[float]:
    from simulator.media.video import iter_frames

    return [float(f.mean()) for f in iter_frames(path)]


def test_frame_range_analytic():
    # frames i with start <= i / fps < end
    assert frame_range(100, 10.0) == (0, 100)
    assert frame_range(100, 10.0, 2.0, 5.0) == (20, 50)
    assert frame_range(100, 10.0, 2.05, 5.01) == (21, 51)
    assert frame_range(100, 25.0, None, 1.0) == (0, 25)
    for s, e in [(-1, 2), (10, None), (11, 12), (3, 3), (4, 2), (0, 10.5)]:
        with pytest.raises(InputError):
            frame_range(100, 10.0, s, e, video="v.mp4")


def test_render_range_has_exactly_the_frames(ctx, tmp_path):
    from simulator.cli import main

    vid = tmp_path / "r.mp4"
    _ramp_video(vid)
    _path_csv(tmp_path / "p.csv", 0.9)
    out = tmp_path / "o"
    argv = ["render", str(vid), str(tmp_path / "p.csv"), "-o", str(out), "--eye-size", "32x32",
            "--no-progress", "--grf", "off", "--start", "0.3", "--end", "0.7"]  # fmt: skip
    assert main(argv) == 0
    m = _means(out / "left.mp4")
    want = [20 + 20 * i for i in range(3, 7)]
    assert len(m) == 4 and np.allclose(m, want, atol=3), m
    rows = [r.split(",") for r in _data_lines(out / "epof.csv")[1:]]
    assert [int(r[0]) for r in rows] == [3, 4, 5, 6]
    assert np.allclose([float(r[1]) for r in rows], [0.3, 0.4, 0.5, 0.6])
    assert np.allclose([float(r[2]) for r in rows], [3.0, 4.0, 5.0, 6.0], atol=1e-6)  # yaw 10 t
    s = json.loads((out / "summary.json").read_text())
    assert s["frames_written"] == 4 and s["frames_range"] == [3, 7]


@pytest.mark.slow
def test_render_range_with_partial_grid(ctx, tmp_path):
    """A grid preprocessed for part of the video serves a range inside it; its EPOF rows
    equal the grid's own (epof CLI) rows for those frames."""
    from simulator.cli import main

    vid = tmp_path / "r.mp4"
    _ramp_video(vid, n=12)
    _path_csv(tmp_path / "p.csv", 1.1)
    g = tmp_path / "g.npz"
    _partial_grid(g, start=2, end=10, n_video=12)
    out = tmp_path / "o"
    base = ["render", str(vid), str(tmp_path / "p.csv"), "-o", str(out), "--eye-size", "32x32",
            "--no-progress", "--grid", str(g)]  # fmt: skip
    assert main(base) == 2  # the whole video is not covered
    assert not (out / "summary.json").exists()
    assert main([*base, "--start", "0.0", "--end", "0.5"]) == 2  # starts before the grid
    assert main([*base, "--start", "0.3", "--end", "0.8"]) == 0
    rows = [r.split(",") for r in _data_lines(out / "epof.csv")[1:]]
    assert [int(r[0]) for r in rows] == [3, 4, 5, 6, 7]
    ecsv = tmp_path / "e.csv"
    assert main(["epof", str(g), str(tmp_path / "p.csv"), "-o", str(ecsv),
                 "--fov", "107"]) == 0  # fmt: skip
    ref = {int(r.split(",")[0]): r.split(",")[5] for r in _data_lines(ecsv)[1:]}
    assert [r[5] for r in rows] == [ref[f] for f in range(3, 8)]


@pytest.mark.parametrize(
    "rng", [("-1", "0.5"), ("0.5", "0.5"), ("0.6", "0.2"), ("0", "99"), ("5", "6")]
)
def test_render_bad_range_one_line_exit_2(ctx, tmp_path, capsys, rng):
    from simulator.cli import main

    vid = tmp_path / "r.mp4"
    _ramp_video(vid)
    _path_csv(tmp_path / "p.csv", 0.9)
    out = tmp_path / "o"
    argv = ["render", str(vid), str(tmp_path / "p.csv"), "-o", str(out), "--eye-size", "32x32",
            "--no-progress", "--grf", "off", "--start", rng[0], "--end", rng[1]]  # fmt: skip
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and ("--start" in err or "--end" in err), err
    assert not out.exists() or not list(out.iterdir())


def test_render_layout_from_grid_meta(ctx, tmp_path, capsys):
    """No --layout: a stereo grid's layout (its meta) is used; both eye files by default."""
    from simulator.cli import main
    from simulator.media.gridfile import save_grid
    from simulator.sphere.windows import WindowGrid

    vid = write_clip(tmp_path / "tb.mp4", gray_frames([90] * 4, (128, 128)))
    g = WindowGrid()
    z = np.ones((4, len(g.pitch_deg), len(g.yaw_deg)), np.float32)
    meta = {"fps": 10.0, "n_frames": 4, "flow": {"method": "none"}, "layout": "top-bottom",
            "eye": "left", "video": {"path": "tb.mp4", "width": 128, "height": 128, "sar": 1.0}}  # fmt: skip
    save_grid(tmp_path / "g.npz", z, z, g, meta)
    _path_csv(tmp_path / "p.csv", 0.3)
    out = tmp_path / "o"
    argv = ["render", str(vid), str(tmp_path / "p.csv"), "-o", str(out), "--eye-size", "32x32",
            "--no-progress", "--grid", str(tmp_path / "g.npz")]  # fmt: skip
    assert main(argv) == 0
    assert "from the grid's meta" in capsys.readouterr().err
    s = json.loads((out / "summary.json").read_text())
    assert s["layout"] == "top-bottom" and s["eyes"] == "both"
    assert (out / "left.mp4").exists() and (out / "right.mp4").exists()
