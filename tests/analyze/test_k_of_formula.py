"""K_OF: the group-size-invariant default, the paper's formula one option away."""

from __future__ import annotations

import csv

import numpy as np
import pytest

from simulator.analyze import analyze_study, k_of, read_study, write_report
from simulator.analyze.report import p_text
from simulator.cli import main


def _draw(n: int, seed: int):
    rng = np.random.default_rng(seed)
    return rng.uniform(0, 200, n), rng.uniform(1, 40, n), rng.uniform(100, 3000, n)


def test_duplicating_a_group_changes_no_ratio_of_the_default():
    s, ms, f = _draw(7, 1)
    g = ["A"] * 4 + ["B"] * 3
    base = {form: k_of(s, ms, f, g, form) for form in ("invariant", "paper")}
    # every participant of A twice
    dup = np.r_[s, s[:4]], np.r_[ms, ms[:4]], np.r_[f, f[:4]], g + ["A"] * 4
    twice = {form: k_of(*dup, form)[:7] for form in ("invariant", "paper")}
    ratio = base["invariant"][:, None] / base["invariant"][None, :]
    np.testing.assert_allclose(twice["invariant"][:, None] / twice["invariant"][None, :], ratio,
                               rtol=1e-12)  # fmt: skip
    # the paper's formula halves A's scores against B's
    before = base["paper"][0] / base["paper"][4]
    after = twice["paper"][0] / twice["paper"][4]
    assert after == pytest.approx(before / 2, rel=1e-12)


def test_equal_groups_give_the_papers_numbers_exactly():
    s, ms, f = _draw(10, 2)
    g = ["GR", "NR"] * 5
    assert np.array_equal(k_of(s, ms, f, g), k_of(s, ms, f, g, "paper"))


def _data(path, n_gr: int, n_nr: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["id", "condition", "ssq_n", "ssq_o", "ssq_d", "ssq_total", "mssq", "flow"])
        for i in range(n_gr + n_nr):
            w.writerow([f"p{i}", "GR" if i < n_gr else "NR", 9.54, 7.58, 13.92,
                        float(rng.integers(0, 40) * 3.74), float(rng.uniform(1, 30)),
                        float(rng.uniform(500, 3000))])  # fmt: skip
    return path


def test_unequal_groups_warn_and_the_report_states_the_formula(tmp_path, capsys):
    data = _data(tmp_path / "d.csv", 48, 4)
    an = analyze_study(read_study(data))
    assert any("unequal groups, 48 GR vs. 4 NR" in n for n in an.notes)
    write_report(an, tmp_path / "r")
    report = (tmp_path / "r" / "report.md").read_text()
    assert "K_OF formula (invariant)" in report and "n_g / n_mean" in report
    assert main(["analyze", str(data), "-o", str(tmp_path / "p"), "--k-of", "paper"]) == 0
    out = capsys.readouterr()
    assert "K_OF formula: paper" in out.out and "unequal groups" in out.err
    assert "K_OF formula (paper)" in (tmp_path / "p" / "report.md").read_text()
    same = analyze_study(read_study(_data(tmp_path / "e.csv", 5, 5)))
    assert not any("unequal" in n for n in same.notes)


def test_small_p_is_printed_as_below_0_001():
    assert p_text(0.0000004) == "< 0.001"
    assert p_text(0.0123) == "0.012"
    assert p_text(float("nan")) == "n/a"
