"""``ViewSpec.from_options``: the one builder of what the eye sees, from a command line or
a study manifest alike; a study render and a CLI render of the same viewing agree."""

from __future__ import annotations

import argparse
import glob
import json
from pathlib import Path

import numpy as np
import pytest

from simulator.core.errors import InputError
from simulator.viewing.spec import ViewSpec


def _cli_args(*argv: str) -> argparse.Namespace:
    """The namespace ``vimsim render`` parses (its real parser)."""
    from simulator.cli import build_parser

    return build_parser().parse_args(["render", "v.mp4", "p.csv", "-o", "o", *argv])


def test_cli_and_table_give_the_same_view():
    """The same options from argparse and from a manifest's tables: equal values, the
    headset's asymmetric per-eye frustum and the eased rule in both."""
    from simulator.sphere.cells import Frustum

    args = _cli_args("--grid", "g.npz", "--headset", "quest-2", "--eye-size", "64x64",
                     "--mitigation", "grf+vignette", "--feather", "5", "--ease-in", "0.2",
                     "--cutout", "10", "30")  # fmt: skip
    table = {"grid": True, "headset": "quest-2", "eye_size": "64x64",
             "mitigation": "grf+vignette", "feather": 5, "ease_in": 0.2, "cutout": [10, 30]}  # fmt: skip
    a, b = ViewSpec.from_options(args), ViewSpec.from_options(table)
    assert a == b
    fr = Frustum.from_headset("quest-2", "left")
    assert a.frustum == fr and fr.left_deg != fr.right_deg
    assert a.rule.ease_in_s == 0.2 and a.rule.ease_out_s > 0  # comfort rule, eased
    assert a.grains is not None and a.grains.inner_deg == 10.0 and a.mitigation.vignette
    # no grid, no numeric opacity: nothing but the vignette... and no grains at all
    assert ViewSpec.from_options({"opacity": 0.5}).grains is not None
    assert ViewSpec.from_options({}).grains is None


@pytest.mark.parametrize(
    ("argv", "table", "cli_name", "key"),
    [
        (["--grain-size", "95"], {"grain_size": 95}, "--grain-size", "grain_size"),
        (["--eye-size", "63x64"], {"eye_size": "63x64"}, "--eye-size", "eye_size"),
        (["--headset", "rift-9"], {"headset": "rift-9"}, "--headset", "headset"),
        (["--opacity-rule", "paper", "--smooth", "1"], {"opacity_rule": "paper", "smooth": 1},
         "--smooth", "smooth"),
        (["--mitigation", "vignette", "--aperture-min", "120"],
         {"mitigation": "vignette", "aperture_min": 120}, "--aperture-min", "aperture_min"),
        (["--vignette-color", "red"], {"vignette_color": "red"}, "--vignette-color",
         "vignette_color"),
    ],
)  # fmt: skip
def test_messages_name_the_option(argv, table, cli_name, key):
    with pytest.raises(InputError) as cli:
        ViewSpec.from_options(_cli_args(*argv))
    assert cli_name in str(cli.value)
    with pytest.raises(InputError) as toml:
        ViewSpec.from_options(table, label=lambda k: f"[render] {k}")
    assert f"[render] {key}" in str(toml.value)


def test_conflicting_fov_options_name_both():
    with pytest.raises(InputError, match="--headset, --fov"):
        ViewSpec.from_options(_cli_args("--headset", "quest-2", "--fov", "90"))


def test_manifest_messages_name_the_table_and_key(tmp_path):
    """The study checks its render view when it reads the manifest, naming table and key."""
    from simulator.study.manifest import _view

    m = tmp_path / "s.toml"
    with pytest.raises(InputError, match=r"s\.toml: \[grf\] grain_size: .*95"):
        _view(m, {"grf": {"grain_size": 95}})
    with pytest.raises(InputError, match=r"\[epof\] smooth"):
        _view(m, {"epof": {"opacity_rule": "paper", "smooth": 1.0}})
    assert _view(m, {"render": {"headset": "quest-2"}})["headset"] == "quest-2"


def test_given_replaces_fields():
    v = ViewSpec.given(opacity=0.8)
    assert v.opacity == 0.8 and ViewSpec.given(v, hold=True).hold and not v.hold
    with pytest.raises(TypeError):
        ViewSpec.given(colour=1)


def _psnr(a: np.ndarray, b: np.ndarray) -> float:
    mse = float(np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2))
    return float("inf") if mse == 0 else 10 * np.log10(255.0**2 / mse)


def _epof_columns(path: Path) -> tuple[dict, np.ndarray]:
    """(settings of the '#' lines, the rows' epof_dps and opacity columns)."""
    lines = path.read_text().splitlines()
    settings = {}
    for ln in lines:
        if ln.startswith("# "):
            k, _, v = ln[2:].partition(": ")
            settings[k] = json.loads(v)
    data = [ln for ln in lines if ln and not ln.startswith("#")]
    head = data[0].split(",")
    num = [i for i, c in enumerate(head) if c != "artefact"]  # the kind is text (studies detect artefacts)
    rows = np.loadtxt(data[1:], delimiter=",", ndmin=2, usecols=num)
    head = [head[i] for i in num]
    return settings, rows[:, [head.index("epof_dps"), head.index("opacity")]]


@pytest.mark.gl
@pytest.mark.slow
def test_study_render_equals_cli_render_with_a_headset(tmp_path, capsys):
    """A study render and ``vimsim render`` of the same viewing with the quest-2 headset:
    the same (asymmetric) frustum, EPOF and opacity in epof.csv, and frames that differ by
    encoding alone (before ViewSpec the study drew a symmetric view with the paper's
    unsmoothed opacity: 18.1 dB apart on this clip)."""
    from simulator.cli import main
    from simulator.media.video import iter_frames
    from simulator.synth import SynthConfig, synthesize
    from simulator.traces.path import save_headpath_csv, synth

    synthesize(SynthConfig("rotate", seconds=1.5, fps=10, size=(128, 64)), tmp_path / "clip.mp4")
    save_headpath_csv(tmp_path / "P01.csv", synth("look-around", 2.0, rate_hz=30, seed=1))
    (tmp_path / "s.toml").write_text(
        '[[videos]]\nid = "clip"\npath = "clip.mp4"\nmethod = "sphere"\nwindow_size = 64\n\n'
        '[[viewings]]\nvideo = "clip"\ntrace = "P01.csv"\nid = "v"\nrender = true\n\n'
        '[render]\neye_size = "64x64"\nheadset = "quest-2"\n\n[epof]\nheadset = "quest-2"\n'
    )
    study = tmp_path / "study"
    rc = main(["study", str(tmp_path / "s.toml"), "-o", str(study), "--cache-dir",
               str(tmp_path / "cache"), "--workers", "1", "--no-progress"])  # fmt: skip
    assert rc == 0, capsys.readouterr().err
    (grid,) = glob.glob(str(tmp_path / "cache" / "grids" / "*.npz"))
    cli = tmp_path / "cli"
    assert main(["render", str(tmp_path / "clip.mp4"), str(tmp_path / "P01.csv"), "-o", str(cli),
                 "--grid", grid, "--eye-size", "64x64", "--headset", "quest-2",
                 "--no-progress"]) == 0  # fmt: skip
    a = json.loads((study / "render" / "v" / "summary.json").read_text())
    b = json.loads((cli / "summary.json").read_text())
    assert a["frustum_deg"] == b["frustum_deg"]
    assert a["frustum_deg"]["left"] != a["frustum_deg"]["right"]  # the headset's, asymmetric
    sa, ea = _epof_columns(study / "render" / "v" / "epof.csv")
    sb, eb = _epof_columns(cli / "epof.csv")
    assert sa["frustum_deg"] == sb["frustum_deg"] and sa["opacity_rule"] == sb["opacity_rule"]
    assert np.array_equal(ea, eb) and np.ptp(eb[:, 1]) > 0  # same EPOF and (varying) opacity
    # the study's EPOF of the viewing is vimsim epof's with the same headset, byte for byte
    ref = tmp_path / "epof.csv"
    assert main(["epof", grid, str(tmp_path / "P01.csv"), "-o", str(ref), "--headset",
                 "quest-2", "--artefacts"]) == 0  # fmt: skip  (a study detects them by default)
    assert (study / "epof" / "v.csv").read_bytes() == ref.read_bytes()
    fa = np.stack(list(iter_frames(study / "render" / "v" / "left.mp4")))
    fb = np.stack(list(iter_frames(cli / "left.mp4")))
    assert fa.shape == fb.shape
    psnr = _psnr(fa, fb)
    print(f"study vs CLI render PSNR: {psnr:.1f} dB")
    assert psnr > 45.0, psnr
