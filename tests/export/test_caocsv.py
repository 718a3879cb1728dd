"""``vimsim grid import`` and ``vimsim export --format cao-csv``: the authors' per-window CSV
layout, exact round trip on synthetic folders, and the bad-input refusals."""

from __future__ import annotations

import numpy as np
import pytest

from simulator.cli import main
from simulator.export.caocsv import read_cao_folder, window_file_name
from simulator.media.gridfile import load_grid


def _write_folder(d, yaws, pitches, T, *, seed=0, pct=("0.18", "53.73")):
    """Synthetic CSVs in their layout; values are float32 shortest decimals."""
    d.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    for p in pitches:
        for y in yaws:
            v = rng.uniform(0, 80, T).astype(np.float32)
            v[0] *= 50  # the 88 deg frame 0 of their data
            rows = "".join(
                f"{t},{np.format_float_positional(x, unique=True, trim='0')}\n"
                for t, x in enumerate(v)
            )
            (d / window_file_name(y, p)).write_text(",0\n" + rows)
    if pct:
        (d / "percentileData.csv").write_text("\n".join(pct) + "\n")
    return d


def _texts(d):
    return {f.name: f.read_text() for f in sorted(d.iterdir()) if f.suffix == ".csv"}


@pytest.mark.parametrize(
    "yaws,pitches",
    [
        (list(range(-180, 180, 15)), list(range(-90, 91, 15))),  # theirs: 24 x 13
        ([-180, -90, 0, 90], [-22.5, 0, 22.5]),  # any grid the names declare
    ],
)
def test_import_export_round_trip_exact(tmp_path, yaws, pitches, capsys):
    src = _write_folder(tmp_path / "src", yaws, pitches, 6)
    grid = tmp_path / "g.npz"
    assert main(["grid", "import", str(src), "-o", str(grid), "--fps", "30"]) == 0
    g = load_grid(grid)
    assert g.pof_px.shape == (6, len(pitches), len(yaws))
    np.testing.assert_array_equal(g.yaw_deg, yaws)
    np.testing.assert_array_equal(g.pitch_deg, pitches)
    assert (g.hfov_deg, g.grid.size) == (107.0, (1600, 1440))
    assert g.vfov_deg == pytest.approx(96.3)
    np.testing.assert_allclose(g.pof_dps, g.pof_px * 107.0 / 1600 * 30, rtol=1e-6)
    out = tmp_path / "out"
    assert main(["export", str(grid), "--format", "cao-csv", "--preset", "cao2021-code",
                 "-o", str(out)]) == 0  # fmt: skip
    assert _texts(out) == _texts(src)  # byte for byte, the percentile file included
    assert (out / ".vimsim-manifest.json").exists()
    again = read_cao_folder(out)
    np.testing.assert_array_equal(again.pof_px, g.pof_px)
    assert "wrote" in capsys.readouterr().out


def test_export_percentiles_from_rule(tmp_path):
    src = _write_folder(tmp_path / "src", [-180, -90, 0, 90], [0], 5, pct=None)
    grid = tmp_path / "g.npz"
    assert main(["grid", "import", str(src), "-o", str(grid), "--fps", "25"]) == 0
    out = tmp_path / "out"
    assert main(["export", str(grid), "--format", "cao-csv", "-o", str(out)]) == 0
    lo, hi = (float(x) for x in (out / "percentileData.csv").read_text().split())
    want = np.percentile(load_grid(grid).pof_px.astype(np.float64), [10, 90])
    np.testing.assert_allclose([lo, hi], want, rtol=1e-6)
    out2 = tmp_path / "out2"
    assert main(["export", str(grid), "--format", "cao-csv", "--opacity-rule", "absolute",
                 "-o", str(out2)]) == 2  # fmt: skip
    assert not out2.exists()


def _bad(tmp_path, capsys, mutate, needle):
    src = _write_folder(tmp_path / "src", [-180, -90, 0, 90], [-15, 0, 15], 4)
    mutate(src)
    grid = tmp_path / "g.npz"
    assert main(["grid", "import", str(src), "-o", str(grid), "--fps", "30"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and needle in err, err
    assert not grid.exists() and not list(tmp_path.glob("g.npz*"))


def test_import_refuses_missing_window(tmp_path, capsys):
    _bad(tmp_path, capsys, lambda d: (d / "horizontal_90_vertical_15.csv").unlink(),
         "horizontal_90_vertical_15.csv: missing")  # fmt: skip


def test_import_refuses_bad_row(tmp_path, capsys):
    def f(d):
        p = d / "horizontal_0_vertical_0.csv"
        p.write_text(p.read_text().replace("2,", "2;", 1))

    _bad(tmp_path, capsys, f, "horizontal_0_vertical_0.csv, line 4: expected 'frame,number'")


def test_import_refuses_non_number(tmp_path, capsys):
    def f(d):
        p = d / "horizontal_0_vertical_0.csv"
        lines = p.read_text().splitlines()
        lines[2] = "1,abc"
        p.write_text("\n".join(lines) + "\n")

    _bad(tmp_path, capsys, f, "is not a number")


def test_import_refuses_frames_out_of_order(tmp_path, capsys):
    def f(d):
        p = d / "horizontal_-90_vertical_15.csv"
        lines = p.read_text().splitlines()
        lines[2], lines[3] = lines[3], lines[2]
        p.write_text("\n".join(lines) + "\n")

    _bad(tmp_path, capsys, f, "frames must be 0..N-1 in order")


def test_import_refuses_unequal_lengths(tmp_path, capsys):
    def f(d):
        p = d / "horizontal_90_vertical_0.csv"
        p.write_text(p.read_text() + "4,1.5\n")

    _bad(tmp_path, capsys, f, "windows of unequal length")


def test_import_refuses_bad_header_and_percentiles(tmp_path, capsys):
    def f(d):
        p = d / "horizontal_0_vertical_0.csv"
        p.write_text(p.read_text().replace(",0\n", "frame,value\n", 1))

    _bad(tmp_path, capsys, f, "first line must be the header ',0'")
    _bad(tmp_path / "b", capsys, lambda d: (d / "percentileData.csv").write_text("1\n"),
         "percentileData.csv: expected two lines")  # fmt: skip


def test_import_refuses_uneven_yaws_and_empty_folder(tmp_path, capsys):
    _bad(tmp_path, capsys, lambda d: [(d / window_file_name(45, p)).write_text(",0\n0,1\n1,1\n2,1\n3,1\n")
                                      for p in (-15, 0, 15)], "not evenly spaced")  # fmt: skip
    empty = tmp_path / "empty"
    empty.mkdir()
    assert main(["grid", "import", str(empty), "-o", str(tmp_path / "x.npz"), "--fps", "30"]) == 2
    assert "no window files" in capsys.readouterr().err


def test_export_refuses_sphere_grid(tmp_path):
    import dataclasses

    from simulator.core.errors import InputError
    from simulator.export.caocsv import export_cao_csv

    src = _write_folder(tmp_path / "src", [-180, -90, 0, 90], [0], 3)
    main(["grid", "import", str(src), "-o", str(tmp_path / "g.npz"), "--fps", "30"])
    g = load_grid(tmp_path / "g.npz")
    sphere = dataclasses.replace(g, field_dps=np.zeros((3, 45, 90), np.float32))
    with pytest.raises(InputError, match="sphere-mode grid; --format cao-csv needs a paper-mode"):
        export_cao_csv(sphere, tmp_path / "out", percentiles_px=(0.18, 53.73))
    assert not (tmp_path / "out").exists()


def test_export_never_replaces_a_users_file(tmp_path, capsys):
    src = _write_folder(tmp_path / "src", [-180, -90, 0, 90], [0], 3)
    grid = tmp_path / "g.npz"
    assert main(["grid", "import", str(src), "-o", str(grid), "--fps", "30"]) == 0
    capsys.readouterr()
    # Exporting into the source folder: its CSVs were not written by vimsim: refused.
    assert main(["export", str(grid), "--format", "cao-csv", "-o", str(src)]) == 2
    assert "refusing to replace it" in capsys.readouterr().err
    assert _texts(src) == _texts(_write_folder(tmp_path / "again", [-180, -90, 0, 90], [0], 3))
