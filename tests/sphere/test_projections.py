"""sphere.projections: every input projection against ffmpeg v360 (tiny frames), sizes, coverage."""

from __future__ import annotations

import numpy as np
import pytest
from media_helpers import smooth_equirect

from simulator.core.errors import InputError
from simulator.sphere.projections import PROJECTIONS, EquirectConverter, converter
from simulator.testing.reference import v360_convert

CASES = [
    ("c3x2", (192, 128), ""),
    ("c6x1", (384, 64), ""),
    ("eac", (192, 128), ""),
    ("dfisheye", (256, 128), ":h_fov=190:v_fov=190"),
    ("hequirect", (128, 128), ""),
]


@pytest.mark.parametrize("name,size,opts", CASES)
def test_conversion_matches_v360(name, size, opts):
    E = smooth_equirect()
    src = v360_convert(E, name, size, opts)
    c = converter(name, size, 190.0 if name == "dfisheye" else None)
    back = c(src)
    assert back.shape[:2] == (c.equirect_size[1], c.equirect_size[0])
    ref = smooth_equirect(*c.equirect_size)
    m = c.covered.copy()
    m[: m.shape[0] // 8] = m[-m.shape[0] // 8 :] = False  # v360 reflects rows at the poles
    d = (back.astype(float) - ref.astype(float))[m]
    psnr = 10 * np.log10(255**2 / (d**2).mean())
    assert psnr > 36, (name, psnr)
    # and a wrong layout would not pass: the cube faces swapped
    if name == "c3x2":
        sw = src.copy()
        sw[:64, :64], sw[:64, 64:128] = src[:64, 64:128], src[:64, :64]  # right <-> left
        d2 = (c(sw).astype(float) - ref.astype(float))[m]
        assert 10 * np.log10(255**2 / (d2**2).mean()) < psnr - 10


def test_coverage_of_each_projection():
    assert not converter("hequirect", (64, 64)).covered.all()
    cov = converter("hequirect", (64, 64)).covered
    assert cov[:, :32].sum() == 0 and cov[:, 32:96].all() and cov[:, 96:].sum() == 0
    for name in ("c3x2", "eac", "dfisheye"):
        size = {"c3x2": (96, 64), "eac": (96, 64), "dfisheye": (128, 64)}[name]
        assert converter(name, size).covered.all()
    assert set(PROJECTIONS) == {"c3x2", "c6x1", "eac", "dfisheye", "hequirect"}


@pytest.mark.parametrize(
    "name,size,word",
    [("c3x2", (100, 64), "does not fit"), ("c6x1", (384, 96), "does not fit"),
     ("eac", (128, 128), "3:2"), ("dfisheye", (128, 128), "2:1"), ("hequirect", (128, 64), "1:1")],
)  # fmt: skip
def test_size_that_does_not_fit_the_layout_is_refused(name, size, word):
    with pytest.raises(InputError, match=f"--projection {name}: .*{word}"):
        EquirectConverter(name, size)
