"""``--preset paper|cao2021-code`` in ``render``, ``frames`` and the view builder: the same
rules as ``vimsim epof --preset`` (nearest window, row k-2, the fixed px/frame scale), the
authors' grains, the refusals, and ``--x264-preset``."""

from __future__ import annotations

import json

import numpy as np
import pytest
from media_helpers import write_clip

from simulator.cli import main
from simulator.core.errors import InputError
from simulator.epof import read_epof_csv
from simulator.export.caocsv import window_file_name
from simulator.media.gridfile import load_grid
from simulator.mitigation.cao2021 import FixedPxRule, nearest_flow
from simulator.viewing.spec import ViewSpec

T, FPS = 12, 10


def test_view_presets():
    v = ViewSpec.from_options({"grid": True, "preset": "cao2021-code", "seed": 3})
    g = v.grains
    assert (g.layout, g.grain_deg, g.inner_deg, g.seed) == ("fibonacci", 0.5, 0.0, 3)
    assert v.preset == "cao2021-code"
    p = ViewSpec.from_options({"grid": True, "preset": "paper"})
    assert p.method == "paper" and p.rule.is_paper and p.grains.layout == "random"
    assert ViewSpec.from_options({"grid": True}).preset == "vimsim"


@pytest.mark.parametrize(
    "opts,named",
    [
        ({"grain_size": 1.0}, "grain_size"),
        ({"cutout": [10, 30]}, "cutout"),
        ({"method": "paper"}, "method"),
        ({"opacity_rule": "paper"}, "opacity_rule"),
        ({"mitigation": "vignette"}, "mitigation"),
        ({"ease_in": 0.2}, "ease_in"),
    ],
)
def test_cao_preset_refuses_what_it_fixes(opts, named):
    with pytest.raises(InputError, match=f"^preset: cao2021-code fixes {named}; drop {named}$"):
        ViewSpec.from_options({"grid": True, "preset": "cao2021-code", **opts})
    with pytest.raises(InputError, match="paper fixes method"):
        ViewSpec.from_options({"grid": True, "preset": "paper", "method": "sphere"})
    with pytest.raises(InputError, match="preset: expected one of vimsim, paper, cao2021-code"):
        ViewSpec.from_options({"preset": "veryfast"})


@pytest.fixture
def clip(tmp_path):
    """A tiny video and an imported grid of the authors' layout for it (T frames)."""
    x = np.linspace(0, 255, 256, dtype=np.uint8)
    frame = np.repeat(np.repeat(x[None, :, None], 128, axis=0), 3, axis=2)
    vid = tmp_path / "v.mp4"
    write_clip(vid, [frame] * T, FPS)
    d = tmp_path / "csv"
    d.mkdir()
    rng = np.random.default_rng(2)
    for p in range(-90, 91, 15):
        for y in range(-180, 180, 15):
            v = rng.uniform(0, 60, T).astype(np.float32)
            v[0] = 900.0  # their frame-0 row: the flash at frame 2
            rows = "".join(f"{t},{float(a)!r}\n" for t, a in enumerate(v))
            (d / window_file_name(y, p)).write_text(",0\n" + rows)
    grid = tmp_path / "g.npz"
    assert main(["grid", "import", str(d), "-o", str(grid), "--fps", str(FPS)]) == 0
    path = tmp_path / "p.csv"
    path.write_text("time_s,yaw_deg,pitch_deg,roll_deg\n0,150,-20,0\n1.2,200,40,0\n")
    return vid, grid, path


def test_x264_name_given_to_preset_is_refused(clip, tmp_path, capsys):
    vid, grid, path = clip
    out = tmp_path / "o"
    with pytest.raises(SystemExit) as e:  # argparse: one line, status 2
        main(["render", str(vid), str(path), "-o", str(out), "--preset", "ultrafast"])
    assert e.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--x264-preset ultrafast" in err[0]
    assert main(["render", str(vid), str(path), "-o", str(out), "--grid", str(grid),
                 "--preset", "cao2021-code", "--grain-size", "1"]) == 2  # fmt: skip
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--preset: cao2021-code fixes --grain-size" in err[0]
    assert not out.exists()


def test_render_cao2021_code_is_the_authors_runtime(ctx, clip, tmp_path):
    vid, grid, path = clip
    out = tmp_path / "r"
    assert main(["render", str(vid), str(path), "-o", str(out), "--grid", str(grid),
                 "--preset", "cao2021-code", "--eye-size", "64x64", "--x264-preset",
                 "ultrafast", "--no-progress", "--no-audio"]) == 0  # fmt: skip
    res = read_epof_csv(out / "epof.csv")
    g = load_grid(grid)
    px = nearest_flow(g.pof_px, res.frame, res.yaw_deg, res.pitch_deg, g.yaw_deg, g.pitch_deg)
    np.testing.assert_allclose(res.opacity, FixedPxRule()(px), atol=1e-9)
    assert res.opacity[1] == 0 and res.opacity[2] == 1.0  # the header at 1, the flash at 2
    # the same as vimsim epof --preset cao2021-code
    ep = tmp_path / "e.csv"
    assert main(["epof", str(grid), str(path), "-o", str(ep), "--preset", "cao2021-code"]) == 0
    np.testing.assert_allclose(read_epof_csv(ep).opacity, res.opacity, atol=1e-12)
    text = (out / "epof.csv").read_text()
    assert ",flow_px\n" in text and '# preset: "cao2021-code"' in text
    s = json.loads((out / "summary.json").read_text())
    assert s["preset"] == "cao2021-code" and s["x264"]["preset"] == "ultrafast"
    assert s["grf"]["layout"] == "fibonacci" and s["grf"]["n_grains"] == 129_600
    assert s["opacity_rule"]["low_px"] == 0.18 and s["opacity_rule"]["high_px"] == 53.73


def test_frames_cao2021_code(ctx, clip, tmp_path):
    vid, grid, path = clip
    out = tmp_path / "f"
    assert main(["frames", str(vid), str(path), "-o", str(out), "--grid", str(grid),
                 "--preset", "cao2021-code", "--eye-size", "64x64", "--at", "0.2"]) == 0  # fmt: skip
    idx = json.loads((out / "frames.json").read_text())
    r = idx["renderer"]
    assert r["preset"] == "cao2021-code" and r["grf"]["layout"] == "fibonacci"
    assert r["opacity_rule"]["rule"] == "cao2021-code"
    assert idx["frames"][0]["opacity"] == 1.0  # frame 2: their frame-0 row
