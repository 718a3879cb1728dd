"""media.source: the Source value (checked once, one decode funnel), URL refusal."""

from __future__ import annotations

import numpy as np
import pytest
from media_helpers import gray_frames, write_clip

from simulator.core.errors import InputError
from simulator.media.source import Source, as_source


def _tb(gray_top, gray_bottom, w=64):
    f = np.full((w, w, 3), gray_top, np.uint8)
    f[w // 2 :] = gray_bottom
    return f


@pytest.mark.parametrize(
    "url",
    ["https://example.org/a.mp4", "rtmp://host/live", "s3://bucket/key.mp4", "data:video/mp4;x"],
)
def test_url_refused_in_one_line(url):
    with pytest.raises(
        InputError, match="URL; vimsim reads local video files only: download it first"
    ):
        Source.open(url)


def test_stereo_funnel_gives_each_eye(tmp_path):
    p = tmp_path / "tb.mp4"
    write_clip(p, [_tb(40, 200)] * 3, crf=0)
    s = Source.open(p, layout="top-bottom", eye="right")
    assert s.stereo and s.eye_size == (64, 32) and s.files == [str(p)]
    assert abs(float(s.read(1).mean()) - 200) < 4  # its eye: right = bottom
    assert abs(float(s.read(1, eye="left").mean()) - 40) < 4
    pairs = list(s.eye_frames(start=1))
    assert len(pairs) == 2 and all(len(e) == 2 and e[0].flags.c_contiguous for e in pairs)
    assert abs(float(pairs[0][1].mean()) - 200) < 4
    gray = next(s.frames(fmt="gray"))
    assert gray.shape == (32, 64)


def test_right_eye_file_and_as_source(tmp_path):
    left, right = tmp_path / "l.mp4", tmp_path / "r.mp4"
    write_clip(left, gray_frames([60] * 2, (64, 32)), crf=0)
    write_clip(right, gray_frames([180] * 2, (64, 32)), crf=0)
    s = Source.open(left, right=right)
    assert s.stereo and s.files == [str(left), str(right)]
    (fl, fr), _ = list(s.eye_frames())
    assert abs(float(fl.mean()) - 60) < 4 and abs(float(fr.mean()) - 180) < 4
    assert as_source(s) is s and not as_source(left).stereo
    with pytest.raises(InputError, match="--right takes the right eye's own"):
        Source.open(left, layout="top-bottom", right=right)


def test_bad_layout_projection_and_aspect(tmp_path):
    p = tmp_path / "m.mp4"
    write_clip(p, gray_frames([0] * 2, (64, 32)), crf=0)
    with pytest.raises(InputError, match="unknown stereo layout"):
        Source.open(p, layout="left-right")
    with pytest.raises(InputError, match="--projection 'mercator': unknown"):
        Source.open(p, projection="mercator")
    q = tmp_path / "sq.mp4"
    write_clip(q, gray_frames([0] * 2, (64, 64)), crf=0)
    with pytest.raises(InputError, match="top-bottom"):
        Source.open(q)  # 1:1 mono: the hint names the stereo layout
