"""Video I/O: probe (frame count = frames decoded), streaming decode, stereo eyes,
the gray fast path, the atomic H.264 writer, bad input."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest
from media_helpers import noise_frames, write_clip

from simulator.core.errors import InputError
from simulator.media.video import VideoWriter, iter_frames, prefetch, probe, read_frame


def _write(path, n: int, fps: float = 30.0):
    """``n`` noise frames at the writer's own defaults (veryfast, CRF 18)."""
    return write_clip(path, noise_frames(n), fps, preset="veryfast")


def test_writer_round_trip(tmp_path):
    p = _write(tmp_path / "v.mp4", 7, fps=29.97)
    info = probe(p)
    assert (info.width, info.height, info.n_frames, info.is_video) == (128, 64, 7, True)
    assert abs(info.fps - 29.97) < 1e-3
    assert sum(1 for _ in iter_frames(p, fmt="gray")) == 7
    assert not list(tmp_path.glob(".*tmp*"))


def test_writer_atomic_on_error(tmp_path):
    p = tmp_path / "v.mp4"
    with pytest.raises(RuntimeError), VideoWriter(p, 30, (64, 32)) as vw:
        vw.write(np.zeros((32, 64, 3), np.uint8))
        raise RuntimeError("boom")
    assert not p.exists() and not list(tmp_path.iterdir())


def test_gray_fast_path_matches_luma(tmp_path):
    p = _write(tmp_path / "v.mp4", 2)
    g = read_frame(p, 1, fmt="gray")
    rgb = read_frame(p, 1, fmt="rgb24").astype(np.float64)
    assert g.shape == (64, 128) and g.dtype == np.uint8
    # Y plane (limited range, BT.601) vs luma of the decoded RGB: same picture.
    y = 16 + (65.481 * rgb[..., 0] + 128.553 * rgb[..., 1] + 24.966 * rgb[..., 2]) / 255
    assert np.abs(g - y).mean() < 3.0


def test_start_end(tmp_path):
    p = _write(tmp_path / "v.mp4", 6)
    allf = [np.array(f) for f in iter_frames(p, fmt="gray")]
    part = [np.array(f) for f in iter_frames(p, fmt="gray", start=2, end=4)]
    assert len(part) == 2 and np.array_equal(part[0], allf[2]) and np.array_equal(part[1], allf[3])


@pytest.mark.parametrize(
    "name,n,fps,sar",
    [
        ("pano.mp4", 188, 25.0, 9 / 8),
        ("pano.webm", 189, 25.0, 9 / 8),
        ("MaryOculus.mp4", 120, 24.0, 16 / 15),
    ],
)
def test_real_clip_frame_count_is_decoded_count(real_dir, name, n, fps, sar):
    """pano.mp4's header says 189 frames but its edit list discards the last packet:
    FFmpeg delivers 188, and so must probe."""
    p = real_dir / "equirect" / "threejs" / name
    info = probe(p)
    assert (info.n_frames, info.fps) == (n, fps)
    assert abs(info.sar - sar) < 1e-9
    if name == "pano.mp4":
        assert sum(1 for _ in iter_frames(p, fmt="gray")) == n


def test_side_by_side_eyes(real_dir):
    p = real_dir / "equirect" / "threejs" / "MaryOculus.mp4"
    info = probe(p)
    assert info.eye_size("side-by-side") == (960, 1024)
    left = read_frame(p, 10, fmt="gray", layout="side-by-side", eye="left")
    right = read_frame(p, 10, fmt="gray", layout="side-by-side", eye="right")
    assert left.shape == right.shape == (1024, 960)
    assert not np.array_equal(left, right)
    # Half side-by-side: the whole frame displays 2:1 (1920 x 16/15 = 2048 by 1024), so
    # it also passes as mono; only the user knows it is stereo.
    assert info.eye_size("mono") == (1920, 1024)


def test_bad_inputs(tmp_path):
    txt = tmp_path / "notvideo.mp4"
    txt.write_text("hello\n")
    with pytest.raises(InputError, match="not a readable video"):
        probe(txt)
    with pytest.raises(InputError, match="not found"):
        probe(tmp_path / "missing.mp4")
    with pytest.raises(InputError, match="has no frame 9"):
        read_frame(_write(tmp_path / "v.mp4", 2), 9)


# ---------------------------------------------------------------------------- prefetch
def _source(n: int, log: list, fail_at: int | None = None):
    """A generator that records what it produced and whether it was closed."""
    try:
        for i in range(n):
            if i == fail_at:
                raise InputError(f"bad item {i}")
            log.append(i)
            yield i
    finally:
        log.append("closed")


def test_prefetch_in_order_and_closes_source():
    log: list = []
    assert list(prefetch(_source(50, log), depth=3)) == list(range(50))
    assert log[-1] == "closed"


def test_prefetch_reraises_producer_error_at_its_item():
    log: list = []
    got = prefetch(_source(10, log, fail_at=4))
    assert [next(got) for _ in range(4)] == [0, 1, 2, 3]
    with pytest.raises(InputError, match="bad item 4"):
        next(got)
    assert log[-1] == "closed"


def test_prefetch_early_exit_stops_thread_and_closes_source():
    log: list = []
    before = threading.active_count()
    gen = prefetch(_source(10_000, log), depth=2)
    assert next(gen) == 0
    time.sleep(0.05)  # let the producer fill the queue
    # Bounded read-ahead: the one consumed, `depth` queued, one blocked in put().
    assert len([x for x in log if x != "closed"]) <= 4
    gen.close()
    assert log[-1] == "closed"
    assert threading.active_count() == before


def test_prefetch_bad_depth():
    with pytest.raises(ValueError, match="depth"):
        next(prefetch([1], depth=0))


def test_x264_params_leave_out_only_avx512():
    """The writer's x264-params: x264's own CPU detection less the AVX-512 bit (whose
    kernels read memory they never wrote: the bits depended on the heap), or nothing on
    a CPU without AVX-512. tests/render: the render test across heap fills."""
    import av  # noqa: F401 - loads libavcodec and its x264

    from simulator.media.x264 import _flag, _loaded_x264, x264_params

    lib = _loaded_x264()
    assert lib is not None
    bit = _flag(lib, "AVX512") & ~_flag(lib, "AVX2")
    assert bit == 1 << 16  # x264.h X264_CPU_AVX512
    detected = int(lib.x264_cpu_detect())
    assert x264_params() == (f"asm={detected & ~bit}" if detected & bit else None)
