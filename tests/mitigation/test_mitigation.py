"""Mitigations beyond the paper (simulator/mitigation/kinds.py): vignette geometry and local-grf
coverage measured from rendered white frames, visible flow against a brute-force per-pixel
computation on rendered frames, goldens per mode, the ``--mitigation`` CLI and its bad input.

Goldens: ``VIMSIM_UPDATE_GOLDEN=1 pytest tests/mitigation/test_mitigation.py -k golden`` rewrites
tests/golden/mitigation_*.png (look at them first).
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

import cv2
import numpy as np
import pytest
from media_helpers import write_clip

from simulator.core.choices import MITIGATIONS
from simulator.core.errors import InputError
from simulator.mitigation.grf import GrfConfig
from simulator.mitigation.kinds import Mitigation, cell_opacity, parse_color, visible_flow
from simulator.render import RenderConfig, render_view
from simulator.sphere.cells import CellGrid, Frustum
from simulator.sphere.geometry import head_rotation, perspective_rays

REPO = Path(__file__).resolve().parents[2]
GOLDEN = REPO / "tests" / "golden"
WHITE = np.full((256, 512, 3), 255, np.uint8)
FOV = 107.0


def _render(ctx, img, yaw, pitch, roll, mit, *, size=400, grf=None, opacity=1.0, co=None):
    cfg = RenderConfig(eye_size=(size, size), hfov_deg=FOV, vfov_deg=FOV, grf=grf, mitigation=mit)
    return render_view(ctx, img, yaw, pitch, roll, config=cfg, opacity=opacity, cell_opacity=co)


def _ecc_deg(size):
    dirs, sa = perspective_rays((size, size), FOV, FOV)
    return np.degrees(np.arccos(np.clip(dirs[..., 2], -1, 1))), dirs, sa


# ------------------------------------------------------------------------- config
@pytest.mark.parametrize(
    "kw,match",
    [
        ({"kind": "tunnel"}, "unknown mitigation"),
        ({"kind": "vignette", "aperture_min_deg": 0.0}, "aperture-min"),
        ({"kind": "vignette", "aperture_min_deg": -5.0}, "aperture-min"),
        ({"kind": "vignette", "feather_deg": -1.0}, "feather"),
        ({"kind": "vignette", "color": (2.0, 0, 0)}, "colour"),
    ],
)
def test_mitigation_bad_input(kw, match):
    with pytest.raises(InputError, match=match):
        Mitigation(**kw)


def test_aperture_must_lie_inside_the_view():
    with pytest.raises(InputError, match=r"\(0, FOV\) = \(0, 107\)"):
        RenderConfig(hfov_deg=107, vfov_deg=107, mitigation=Mitigation("vignette", 107.0))
    RenderConfig(hfov_deg=107, vfov_deg=107, mitigation=Mitigation("vignette", 106.0))
    # grains only: the aperture is not used, so not checked
    RenderConfig(hfov_deg=60, vfov_deg=60, mitigation=Mitigation("grf", 90.0))


def test_kinds_table_is_the_one_definition(monkeypatch):
    """Every kind is one entry of KINDS, in the CLI's order; its flags, shader defines and
    visible-flow rule come from the entry alone: a new kind added to the table is drawn
    and measured with no other change."""
    from simulator.core.choices import MITIGATION_HELP
    from simulator.mitigation import kinds as K

    assert tuple(K.KINDS) == MITIGATIONS == tuple(MITIGATION_HELP)
    assert K.SHADER_DEFINES == ("LOCAL_GRF", "VIGNETTE")
    assert Mitigation("local-grf").shader_defines(grains=True) == {"LOCAL_GRF": 1, "VIGNETTE": 0}
    assert Mitigation("local-grf").shader_defines(grains=False) == {"LOCAL_GRF": 0, "VIGNETTE": 0}
    assert Mitigation("grf+vignette").shader_defines(grains=True)["VIGNETTE"] == 1
    new = K.Kind("local-grf+vignette", "both", lambda r: r.grains(r.cell_grain_alpha()) * r.vignette(),
                 grains=True, vignette=True, local=True, defines=("VIGNETTE",),
                 grain_defines=("LOCAL_GRF",))  # fmt: skip
    monkeypatch.setitem(K.KINDS, new.name, new)
    m = Mitigation(new.name)
    assert m.grains and m.vignette and m.local
    assert m.shader_defines(grains=True) == {"LOCAL_GRF": 1, "VIGNETTE": 1}
    field = _smooth_field()
    co = cell_opacity(field, (20.0, 60.0))
    fr, views = Frustum.symmetric(FOV, FOV), np.zeros((1, 3))
    kw = {"grf": GrfConfig(), "field_dps": field, "cell_deg": 4.0, "cell_op": co}
    both = visible_flow(m, fr, views, [0.7], [50.0], **kw)
    local = visible_flow(Mitigation("local-grf"), fr, views, [0.7], [50.0], **kw)
    vig = visible_flow(Mitigation("vignette"), fr, views, [0.7], [50.0], **kw)
    assert both.blocked[0] > max(local.blocked[0], vig.blocked[0]) > 0


def test_parse_color():
    assert parse_color("#ff8000") == (1.0, 128 / 255, 0.0)
    assert parse_color("0,0,255") == (0.0, 0.0, 1.0)
    for bad in ("red", "1,2", "0,0,256", "#12345"):
        with pytest.raises(InputError, match="R,G,B"):
            parse_color(bad)


# ------------------------------------------------------------------------ vignette
def _requested_radius_deg(op, aperture, feather):
    """The issue's rule, written independently: the diameter shrinks linearly from the
    full view (corner eccentricity, plus half the feather so nothing is blocked) at
    opacity 0 to the requested aperture at opacity 1."""
    corner = math.degrees(math.atan(math.sqrt(2) * math.tan(math.radians(FOV / 2))))
    d0, d1 = 2 * (corner + feather / 2), aperture
    return (d0 + (d1 - d0) * op) / 2


@pytest.mark.parametrize("yaw,pitch,roll", [(0, 0, 0), (120, 35, 0), (-60, -20, 40)])
@pytest.mark.parametrize("op", [0.3, 0.7, 1.0])
def test_vignette_aperture_feather_and_centre(ctx, yaw, pitch, roll, op):
    size, aperture, feather = 400, 60.0, 12.0
    ecc, dirs, _ = _ecc_deg(size)
    a = 1.0 - _render(ctx, WHITE, yaw, pitch, roll, Mitigation("vignette", aperture, feather),
                      size=size, opacity=op)[..., 0] / 255.0  # fmt: skip
    want_r = _requested_radius_deg(op, aperture, feather)
    ramp = (a > 0.05) & (a < 0.95)
    slope, icpt = np.polyfit(ecc[ramp], a[ramp], 1)
    r = (0.5 - icpt) / slope  # where alpha is 1/2
    print(f"op {op} view {yaw},{pitch},{roll}: radius {r:.3f} want {want_r:.3f}, "
          f"feather {1 / slope:.3f}")  # fmt: skip
    assert r == pytest.approx(want_r, abs=0.5)
    assert 1.0 / slope == pytest.approx(feather, rel=0.02)  # linear in angle
    assert np.abs(a[ramp] - (slope * ecc[ramp] + icpt)).max() < 0.02
    assert a[ecc < want_r - feather / 2 - 0.5].max() == 0.0
    outside = ecc > want_r + feather / 2 + 0.5
    assert not outside.any() or a[outside].min() == 1.0
    # centred: the same radius in each quadrant of the image (roll included)
    az = np.arctan2(dirs[..., 1], dirs[..., 0])
    for q in range(4):
        m = ramp & (az >= -math.pi + q * math.pi / 2) & (az < -math.pi + (q + 1) * math.pi / 2)
        if m.sum() < 50:
            continue  # the ring leaves the image there (low opacity)
        s, c = np.polyfit(ecc[m], a[m], 1)
        assert (0.5 - c) / s == pytest.approx(want_r, abs=0.5)


def test_vignette_at_opacity_0_blocks_nothing_and_hard_edge(ctx):
    a0 = _render(ctx, WHITE, 10, 5, 0, Mitigation("vignette"), opacity=0.0)
    assert a0.min() == 255
    size = 400
    ecc, _, _ = _ecc_deg(size)
    img = _render(ctx, WHITE, 0, 0, 0, Mitigation("vignette", 50.0, 0.0), size=size)
    blocked = img[..., 0] < 128
    edge = blocked & ~(np.roll(blocked, 1, 0) & np.roll(blocked, -1, 0)
                       & np.roll(blocked, 1, 1) & np.roll(blocked, -1, 1))  # fmt: skip
    assert float(ecc[edge].mean()) == pytest.approx(25.0, abs=0.5)


def test_vignette_colour_and_grf_plus_vignette_composition(ctx):
    red = _render(ctx, WHITE, 0, 0, 0, Mitigation("vignette", color=(1.0, 0.0, 0.0)), size=200)
    assert tuple(red[0, 0]) == (255, 0, 0) and tuple(red[100, 100]) == (255, 255, 255)
    g = GrfConfig()
    both = _render(ctx, WHITE, 30, 10, 5, Mitigation("grf+vignette"), grf=g, opacity=0.6)
    grains = _render(ctx, WHITE, 30, 10, 5, Mitigation("grf"), grf=g, opacity=0.6)
    vig = _render(ctx, WHITE, 30, 10, 5, Mitigation("vignette"), opacity=0.6)
    want = grains.astype(float) * vig.astype(float) / 255.0
    assert np.abs(both.astype(float) - want).max() <= 2.0  # each from the same opacity
    assert (grains < 255).any() and (vig < 255).any()


def test_none_draws_nothing_and_default_is_grf(ctx, petra_small):
    g = GrfConfig()
    video = _render(ctx, petra_small, 20, 0, 0, Mitigation("none"), grf=g, size=160)
    plain = _render(ctx, petra_small, 20, 0, 0, Mitigation("grf"), grf=None, size=160)
    assert np.array_equal(video, plain)
    dflt = render_view(ctx, petra_small, 20, 0, 0, config=RenderConfig((160, 160), grf=g))
    grf = _render(ctx, petra_small, 20, 0, 0, Mitigation("grf"), grf=g, size=160)
    assert np.array_equal(dflt, grf)


# ----------------------------------------------------------------------- local-grf
def _half_moving_clip(path: Path, n: int = 6, fps: float = 30.0) -> None:
    """A 512x256 noise panorama whose eastern half (lon 0..180) slides east 4 px a frame
    (wrapping inside that half); the western half stands still."""

    rng = np.random.default_rng(3)
    base = cv2.GaussianBlur(rng.integers(0, 256, (256, 512)).astype(np.uint8), (0, 0), 1.5)
    base = cv2.normalize(base, None, 0, 255, cv2.NORM_MINMAX)

    def frame(k):
        f = base.copy()
        f[:, 256:] = np.roll(base[:, 256:], 4 * k, axis=1)
        return np.repeat(f[..., None], 3, axis=2)

    write_clip(path, (frame(k) for k in range(n)), fps, crf=10)


@pytest.fixture(scope="module")
def half_grid(tmp_path_factory):
    from simulator.media.gridfile import load_grid
    from simulator.preprocess.sphere import SphereConfig, preprocess_sphere
    from simulator.sphere.windows import grid_preset

    d = tmp_path_factory.mktemp("half")
    _half_moving_clip(d / "half.mp4")
    preprocess_sphere(
        d / "half.mp4",
        d / "half.npz",
        grid=grid_preset("default"),
        config=SphereConfig(tile_size=128),
        progress=False,
    )
    return d / "half.mp4", load_grid(d / "half.npz")


def test_local_grf_coverage_follows_the_field(ctx, half_grid):
    from simulator.media.gridfile import require_field
    from simulator.mitigation.grf import OpacityRule

    _, grid = half_grid
    field, _cells = require_field(grid)
    lo, hi = OpacityRule().fit(grid, None)
    co = cell_opacity(field, (lo, hi))[3]
    size = 400
    _, dirs, sa = _ecc_deg(size)
    for yaw in (0.0, 180.0):  # the view straddles each boundary between the halves
        a = 1.0 - _render(ctx, WHITE, yaw, 0, 0, Mitigation("local-grf"), grf=GrfConfig(),
                          size=size, co=co)[..., 0] / 255.0  # fmt: skip
        world = dirs.reshape(-1, 3) @ head_rotation(yaw, 0, 0).as_matrix().T
        lon = np.degrees(np.arctan2(world[:, 0], world[:, 2])).reshape(size, size)
        ecc = np.degrees(np.arccos(np.clip(dirs[..., 2], -1, 1)))
        away = ecc > 40  # grains fully on there (cutout 1)
        moving = away & (np.abs(lon - 90) < 80)
        still = away & (np.abs(lon + 90) < 80)
        cov_m = float((a[moving] * sa[moving]).sum() / sa[moving].sum())
        cov_s = float((a[still] * sa[still]).sum() / sa[still].sum())
        print(f"yaw {yaw}: coverage moving {cov_m:.4f}, still {cov_s:.4f}")
        assert cov_s <= 0.01
        assert cov_m > 0.3  # grains there (the paper's density 0.5 at full opacity)


def test_local_grf_cells_move_with_the_world(ctx):
    """The cell texture is world-fixed and laid out as the field (row 0 north, column 0
    at lon -180): one cell set to 1 shows grains only inside that cell's lon/lat box."""
    cells = CellGrid(10.0)
    co = np.zeros(cells.shape, np.float32)
    co[6, 21] = 1.0  # lat 30..20 deg north, lon 30..40 deg
    size = 400
    _, dirs, _ = _ecc_deg(size)
    a = 1.0 - _render(ctx, WHITE, 35, 25, 10, Mitigation("local-grf"),
                      grf=GrfConfig(inner_deg=0.0, outer_deg=1e-3), size=size,
                      co=co)[..., 0] / 255.0  # fmt: skip
    world = dirs.reshape(-1, 3) @ head_rotation(35, 25, 10).as_matrix().T
    lon = np.degrees(np.arctan2(world[:, 0], world[:, 2])).reshape(size, size)
    lat = np.degrees(np.arcsin(np.clip(world[:, 1], -1, 1))).reshape(size, size)
    inside = (lon > 30.3) & (lon < 39.7) & (lat > 20.3) & (lat < 29.7)
    outside = (lon < 29.5) | (lon > 40.5) | (lat < 19.5) | (lat > 30.5)
    assert a[outside].max() == 0.0
    assert 0.3 < a[inside].mean() < 0.7


def test_local_grf_needs_cell_opacity(ctx):
    with pytest.raises(ValueError, match="cell_opacity"):
        _render(ctx, WHITE, 0, 0, 0, Mitigation("local-grf"), grf=GrfConfig(), size=64)


# -------------------------------------------------------------------- visible flow
def _smooth_field(cell: float = 4.0) -> np.ndarray:
    cells = CellGrid(cell)
    lon, lat = cells.centres_lonlat()
    LON, LAT = np.meshgrid(lon, lat)
    return (40 + 30 * np.sin(LON) * np.cos(LAT) + 10 * np.sin(LAT)).astype(np.float32)[None]


@pytest.mark.gl
@pytest.mark.parametrize("kind", MITIGATIONS)  # every kind of the table
def test_visible_flow_matches_brute_force_on_rendered_frames(ctx, kind):
    """Library figures (ray samples + grain discs on the CPU) against every pixel of
    rendered white frames: visibility = pixel / 255, each pixel's flow from its field cell."""
    size, op = 480, 0.7
    field = _smooth_field()
    cells = CellGrid(4.0)
    co = cell_opacity(field, (20.0, 60.0))
    mit, grf = Mitigation(kind), GrfConfig()
    views = np.array([[0.0, 0.0, 0.0], [100.0, 30.0, -20.0], [-45.0, -10.0, 15.0]])
    fr = Frustum.symmetric(FOV, FOV)
    got = visible_flow(mit, fr, views, np.full(3, op), np.full(3, 50.0), grf=grf,
                       field_dps=np.repeat(field, 3, 0), cell_deg=4.0,
                       cell_op=np.repeat(co, 3, 0))  # fmt: skip
    _, dirs, sa = _ecc_deg(size)
    for t, (yaw, pitch, roll) in enumerate(views):
        img = _render(ctx, WHITE, yaw, pitch, roll, mit, grf=grf, size=size, opacity=op, co=co[0])
        v = img[..., 0].astype(np.float64) / 255.0
        world = dirs.reshape(-1, 3) @ head_rotation(yaw, pitch, roll).as_matrix().T
        idx = cells.index(np.arctan2(world[:, 0], world[:, 2]), np.arcsin(world[:, 1]))
        f = field[0].ravel()[idx].reshape(size, size)
        ratio = (f * v * sa).sum() / (f * sa).sum()
        blocked = 1.0 - (v * sa).sum() / sa.sum()
        print(f"{kind} view {t}: ratio {got.ratio[t]:.4f} vs {ratio:.4f}, "
              f"blocked {got.blocked[t]:.4f} vs {blocked:.4f}")  # fmt: skip
        assert got.ratio[t] == pytest.approx(ratio, rel=0.02)
        assert got.blocked[t] == pytest.approx(blocked, abs=0.02)
        assert got.visible_dps[t] == pytest.approx(50.0 * got.ratio[t])
    if kind == "none":
        assert np.all(got.ratio == 1.0) and np.all(got.blocked == 0.0)
    else:
        assert np.all(got.ratio < 0.95)


# ------------------------------------------------------------------------- goldens
GOLDEN_MAD = 1.5  # as tests/render/test_render.py: same Mesa gives 0


@pytest.mark.parametrize("kind", ["vignette", "grf+vignette", "local-grf"])
def test_golden(ctx, petra_small, out_dir, kind):
    lon = CellGrid(4.0).centres_lonlat()[0]
    co = np.broadcast_to(np.clip(np.sin(lon) + 0.3, 0, 1), CellGrid(4.0).shape).astype(np.float32)
    got = _render(ctx, petra_small, 90, 20, 10, Mitigation(kind), grf=GrfConfig(), size=160,
                  opacity=0.6, co=co)  # fmt: skip
    name = f"mitigation_{kind.replace('+', '_')}.png"
    path = GOLDEN / name
    if os.environ.get("VIMSIM_UPDATE_GOLDEN"):
        cv2.imwrite(str(path), cv2.cvtColor(got, cv2.COLOR_RGB2BGR))
    want = cv2.cvtColor(cv2.imread(str(path)), cv2.COLOR_BGR2RGB)
    mad = float(np.abs(got.astype(float) - want.astype(float)).mean())
    if mad > GOLDEN_MAD:
        cv2.imwrite(str(out_dir / f"FAILED_{name}"), cv2.cvtColor(got, cv2.COLOR_RGB2BGR))
    assert mad <= GOLDEN_MAD, f"{name}: mean |diff| {mad:.2f} > {GOLDEN_MAD}"


@pytest.fixture(scope="module")
def petra_small(real_dir):
    from simulator.media.video import read_frame

    img = read_frame(real_dir / "equirect" / "vrview" / "petra.jpg")
    return cv2.resize(img, (1024, 512), interpolation=cv2.INTER_AREA)


# ----------------------------------------------------------------------------- CLI
def _path_csv(path: Path, end_s: float = 1.0) -> Path:
    path.write_text(f"time_s,yaw_deg,pitch_deg,roll_deg\n0,0,0,0\n{end_s},60,5,0\n")
    return path


def test_cli_render_mitigations_write_visible_flow(ctx, tmp_path, half_grid):
    from simulator.cli import main

    vid, grid = half_grid
    hp = _path_csv(tmp_path / "p.csv", 0.5)
    ratios = {}
    for kind in ("grf", "vignette", "grf+vignette", "local-grf", "none"):
        out = tmp_path / kind
        rc = main(["render", str(vid), str(hp), "-o", str(out), "--grid", str(grid.path),
                   "--eye-size", "64x64", "--mitigation", kind, "--no-progress"])  # fmt: skip
        assert rc == 0
        rows = [r for r in (out / "epof.csv").read_text().splitlines() if not r.startswith("#")]
        head = rows[0].split(",")
        assert head[-3:] == ["visible_flow_dps", "visible_ratio", "blocked_share"]
        data = np.array([[float(x) for x in r.split(",")] for r in rows[1:]])
        epof, vis, ratio = data[:, 5], data[:, 7], data[:, 8]
        assert np.allclose(vis, epof * ratio, rtol=1e-6, atol=1e-6)
        s = json.loads((out / "summary.json").read_text())
        assert s["mitigation"]["kind"] == kind
        assert s["visible_flow"]["flow_per_direction"] == "sphere-mode field"
        ratios[kind] = s["visible_flow"]["visible_ratio_flow_weighted"]
    assert ratios["none"] == pytest.approx(1.0)
    assert ratios["grf+vignette"] < min(ratios["grf"], ratios["vignette"])
    assert all(ratios[k] < 1.0 for k in ("grf", "vignette", "local-grf"))


@pytest.mark.parametrize(
    "extra,match",
    [
        (["--mitigation", "tunnel"], "invalid choice"),
        (["--mitigation", "vignette", "--aperture-min", "120"], "aperture-min"),
        (["--mitigation", "vignette", "--aperture-min", "0"], "aperture-min"),
        (["--mitigation", "vignette", "--feather", "-2"], "feather"),
        (["--mitigation", "vignette", "--vignette-color", "blue"], "R,G,B"),
        (["--mitigation", "local-grf", "--opacity", "0.5"], "--method sphere"),
    ],
)
def test_cli_render_mitigation_bad_input(ctx, tmp_path, capsys, half_grid, extra, match):
    from simulator.cli import main

    vid, _ = half_grid
    out = tmp_path / "out"
    try:  # usage errors leave through argparse (SystemExit), the others as a status
        rc = main(["render", str(vid), str(_path_csv(tmp_path / "p.csv", 0.5)), "-o", str(out),
                   "--eye-size", "64x64", "--no-progress", *extra])  # fmt: skip
    except SystemExit as e:
        rc = e.code
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and match in err[0], err
    assert not out.exists()


@pytest.mark.slow
def test_cli_local_grf_on_a_paper_grid_says_how_to_make_a_field(ctx, tmp_path, capsys):
    from simulator.cli import main
    from simulator.preprocess import preprocess_video
    from simulator.sphere.windows import grid_preset

    vid = tmp_path / "half.mp4"
    _half_moving_clip(vid, n=3)
    grid = tmp_path / "paper.npz"
    preprocess_video(vid, grid, grid=grid_preset("paper-198", size=(32, 32)), progress=False)
    out = tmp_path / "out"
    rc = main(["render", str(vid), str(_path_csv(tmp_path / "p.csv", 0.2)), "-o", str(out),
               "--grid", str(grid), "--eye-size", "64x64", "--mitigation", "local-grf",
               "--no-progress"])  # fmt: skip
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "--method sphere" in err[0], err
    assert not out.exists()
    # other mitigations run on it, the flow taken as uniform over the view (the EPOF)
    rc = main(["render", str(vid), str(_path_csv(tmp_path / "p.csv", 0.2)), "-o", str(out),
               "--grid", str(grid), "--eye-size", "64x64", "--mitigation", "vignette",
               "--no-progress"])  # fmt: skip
    s = json.loads((out / "summary.json").read_text())
    assert rc == 0 and s["visible_flow"]["flow_per_direction"] == "uniform (EPOF)"
    blocked = s["visible_flow"]["blocked_share_mean"]
    assert s["visible_flow"]["visible_ratio_mean"] == pytest.approx(1.0 - blocked)
