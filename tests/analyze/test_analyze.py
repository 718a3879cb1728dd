"""Tests of simulator.analyze and ``vimsim analyze``: hand-computed scores, scipy's tests."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from simulator.analyze import (
    MSSQ_TYPES,
    SSQ_ITEMS,
    analyze_study,
    k_of,
    mssq_section_score,
    mssq_short_score,
    read_study,
    session_flow,
    ssq_scores,
)
from simulator.cli import main
from simulator.core.errors import InputError

REPO = Path(__file__).resolve().parents[2]
EXAMPLE = REPO / "examples" / "study_example.csv"

# --------------------------------------------------------------------------- SSQ


def test_ssq_hand_computed() -> None:
    r = dict.fromkeys(SSQ_ITEMS, 0)
    r.update(
        ssq_general_discomfort=1,  # N O
        ssq_fatigue=2,  # O
        ssq_eyestrain=1,  # O
        ssq_difficulty_focusing=1,  # O D
        ssq_sweating=1,  # N
        ssq_nausea=2,  # N D
        ssq_fullness_of_head=1,  # D
        ssq_dizzy_eyes_open=1,  # D
        ssq_vertigo=1,  # D
        ssq_stomach_awareness=3,  # N
    )
    s = ssq_scores(r)
    # N_raw = discomfort 1 + sweating 1 + nausea 2 + stomach 3 = 7  -> 7 x 9.54 = 66.78
    # O_raw = discomfort 1 + fatigue 2 + eyestrain 1 + focusing 1 = 5 -> 5 x 7.58 = 37.90
    # D_raw = focusing 1 + nausea 2 + fullness 1 + dizzy open 1 + vertigo 1 = 6
    #       -> 6 x 13.92 = 83.52
    # Total = (7 + 5 + 6) x 3.74 = 67.32
    assert s.nausea == pytest.approx(66.78)
    assert s.oculomotor == pytest.approx(37.90)
    assert s.disorientation == pytest.approx(83.52)
    assert s.total == pytest.approx(67.32)
    # Same ratings as a sequence in SSQ_ITEMS order.
    assert ssq_scores([r[k] for k in SSQ_ITEMS]) == s


def test_ssq_extremes_and_bad_ratings() -> None:
    top = ssq_scores([3] * 16)
    # each subscale has 7 items: raw 21; total raw 63
    assert top.nausea == pytest.approx(21 * 9.54)  # 200.34
    assert top.oculomotor == pytest.approx(21 * 7.58)  # 159.18
    assert top.disorientation == pytest.approx(21 * 13.92)  # 292.32
    assert top.total == pytest.approx(63 * 3.74)  # 235.62
    assert ssq_scores([0] * 16).total == 0.0
    with pytest.raises(InputError, match="0..3"):
        ssq_scores([0] * 15 + [4])
    with pytest.raises(InputError, match="0..3"):
        ssq_scores([0] * 15 + [1.5])
    with pytest.raises(InputError, match="16"):
        ssq_scores([0] * 15)


# --------------------------------------------------------------------------- MSSQ


def test_mssq_hand_computed() -> None:
    child = [2, 1, None, 0, 3, None, 1, 2, 0]  # sum 9, two 't'
    adult = [1, 0, 0, None, 2, 1, 0, 0, 1]  # sum 5, one 't'
    # child = 9 x 9 / (9 - 2) = 81 / 7 = 11.571428...
    # adult = 5 x 9 / (9 - 1) = 45 / 8 = 5.625
    assert mssq_section_score(child) == pytest.approx(81 / 7)
    assert mssq_section_score(adult) == pytest.approx(5.625)
    m = mssq_short_score(child, adult)
    assert m.child == pytest.approx(11.5714285714)
    assert m.adult == pytest.approx(5.625)
    assert m.total == pytest.approx(17.1964285714)  # 81/7 + 45/8
    # No 't': plain sum. All 3: 27 per section, 54 in all.
    assert mssq_section_score([1] * 9) == 9.0
    assert mssq_short_score([3] * 9, [3] * 9).total == 54.0


def test_mssq_bad_sections() -> None:
    with pytest.raises(InputError, match="every answer is 't'"):
        mssq_section_score([None] * 9)
    with pytest.raises(InputError, match="0..3"):
        mssq_section_score([4] + [0] * 8)
    with pytest.raises(InputError, match="9 answers"):
        mssq_section_score([0] * 8)


# --------------------------------------------------------------------------- K_OF


def test_k_of_hand_table() -> None:
    #   id  group  K   MS  flow
    #   a   G1     10  2   100
    #   b   G1     20  6   200     sum MS in G1 = 2 + 6 = 8
    #   c   G2     30  5   50      sum MS in G2 = 5
    # a: 10 x 2 / (100 x 8) x 1000 = 20 / 800 x 1000 = 25
    # b: 20 x 6 / (200 x 8) x 1000 = 120 / 1600 x 1000 = 75
    # c: 30 x 5 / (50 x 5) x 1000 = 150 / 250 x 1000 = 600
    out = k_of(
        np.array([10.0, 20.0, 30.0]),
        np.array([2.0, 6.0, 5.0]),
        np.array([100.0, 200.0, 50.0]),
        ["G1", "G1", "G2"],
        "paper",
    )
    np.testing.assert_allclose(out, [25.0, 75.0, 600.0])


def test_k_of_zero_group_sum_and_bad_flow() -> None:
    out = k_of(np.array([10.0, 5.0]), np.array([0.0, 3.0]), np.array([1.0, 1.0]), ["A", "B"])
    assert math.isnan(out[0])  # group A: 10 x 0 / (1 x 0) = 0/0
    assert out[1] == pytest.approx(5.0 * 3 / (1 * 3) * 1000)  # 5000
    with pytest.raises(InputError, match="flow"):
        k_of(np.array([1.0]), np.array([1.0]), np.array([0.0]), ["A"])


# --------------------------------------------------------------------------- files

_MSSQ_COLS = [f"mssq_{s}_{t}" for s in ("child", "adult") for t in MSSQ_TYPES]


def _write(path: Path, header: list[str], rows: list[list[object]], comment: str = "") -> Path:
    with open(path, "w", newline="") as fh:
        if comment:
            fh.write(f"# {comment}\n")
        w = csv.writer(fh)
        w.writerow(header)
        w.writerows(rows)
    return path


def _sub_table(tmp_path: Path, rows: list[tuple[str, str, float, float, float]]) -> Path:
    """Subscore-form table: (id, condition, K via ssq_n only, mssq, flow)."""
    header = ["id", "condition", "ssq_n", "ssq_o", "ssq_d", "ssq_total", "mssq", "flow"]
    body = [[i, c, 9.54, 7.58, 13.92, k, ms, f] for i, c, k, ms, f in rows]
    return _write(tmp_path / "data.csv", header, body, comment="made-up")


def test_group_sum_ignores_excluded_participants(tmp_path: Path) -> None:
    data = _sub_table(
        tmp_path,
        [
            ("a", "GR", 10.0, 2.0, 100.0),
            ("b", "GR", 20.0, 6.0, 200.0),
            ("x", "GR", 50.0, 40.0, 5.0),  # low flow: excluded, so not in the GR MS sum
            ("c", "NR", 30.0, 5.0, 50.0),
        ],
    )
    an = analyze_study(read_study(data), exclude_below=10.0, k_of_formula="paper")
    assert [q.id for q in an.included] == ["a", "b", "c"]
    assert an.excluded == (("x", "flow 5 < 10 (--exclude-below)"),)
    # as in test_k_of_hand_table: GR sum = 8 (x's 40 not counted), NR sum = 5
    np.testing.assert_allclose(an.of_scores["k_of"], [25.0, 75.0, 600.0])
    # N_OF from ssq_n = 9.54: a: 9.54 x 2 / (100 x 8) x 1000 = 23.85
    assert an.of_scores["n_of"][0] == pytest.approx(23.85)
    assert any("not possible" in r["note"] for r in an.comparisons)


def test_tests_match_direct_scipy_calls(tmp_path: Path) -> None:
    rng = np.random.default_rng(3)
    rows = []
    for i in range(14):
        rows.append(
            (
                f"p{i}",
                "NR" if i % 2 else "GR",
                float(rng.integers(0, 60) * 3.74),
                float(rng.uniform(1, 30)),
                float(rng.uniform(500, 3000)),
            )
        )
    an = analyze_study(read_study(_sub_table(tmp_path, rows)))
    assert an.conditions == ("GR", "NR")
    g = np.array([q.condition for q in an.included])
    k = an.of_scores["k_of"]
    comp = {r["measure"]: r for r in an.comparisons}
    direct = stats.mannwhitneyu(k[g == "GR"], k[g == "NR"], alternative="two-sided")
    assert comp["K_OF"]["U"] == pytest.approx(direct.statistic)
    assert comp["K_OF"]["p"] == pytest.approx(direct.pvalue)
    assert comp["K_OF"]["mean_a"] == pytest.approx(k[g == "GR"].mean())
    norm = {(r["measure"], r["group"]): r for r in an.normality}
    sw = stats.shapiro(k)
    assert norm[("K_OF", "all")]["W"] == pytest.approx(sw.statistic)
    assert norm[("K_OF", "all")]["p"] == pytest.approx(sw.pvalue)
    sw_nr = stats.shapiro(k[g == "NR"])
    assert norm[("K_OF", "NR")]["p"] == pytest.approx(sw_nr.pvalue)
    # K_OF itself, from the formula, for the first participant (group GR):
    ms = np.array([q.mssq.total for q in an.included])
    flow = np.array([q.flow for q in an.included])
    expect0 = rows[0][2] * ms[0] / (flow[0] * ms[g == "GR"].sum()) * 1000
    assert k[0] == pytest.approx(expect0)


def test_epof_csv_flow_statistics(tmp_path: Path) -> None:
    epof = tmp_path / "s1.csv"
    hdr = ["frame", "time_s", "yaw_deg", "pitch_deg", "roll_deg", "epof_dps", "opacity"]
    _write(epof, hdr, [[i, i / 30, 0, 0, 0, v, 0.5] for i, v in enumerate([1.0, 2.0, 6.0])])
    assert session_flow(epof, "mean") == pytest.approx(3.0)  # (1 + 2 + 6) / 3
    assert session_flow(epof, "median") == pytest.approx(2.0)
    assert session_flow(epof, "sum") == pytest.approx(9.0)
    data = _write(
        tmp_path / "d.csv",
        ["id", "condition", "ssq_n", "ssq_o", "ssq_d", "mssq", "epof_csv"],
        [["a", "GR", 0, 0, 0, 1, "s1.csv"], ["b", "NR", 0, 0, 0, 1, "nothere.csv"]],
    )
    st = read_study(data, flow_stat="sum")
    assert [q.flow for q in st.participants] == [9.0]
    assert len(st.problems) == 1
    assert "row 2 (line 3, id 'b')" in st.problems[0]
    assert "not found" in st.problems[0]


# --------------------------------------------------------------------------- CLI


def _items_row(pid: str, cond: str, items: list[object], flow: float = 1500.0) -> list[object]:
    return [pid, cond, *items, *([1] * 18), flow]


_ITEM_HEADER = ["id", "condition", *SSQ_ITEMS, *_MSSQ_COLS, "flow"]


def test_cli_example_end_to_end(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "rep"
    rc = main(["analyze", str(EXAMPLE), "-o", str(out), "--exclude-below", "1000"])
    assert rc == 0
    names = {"scores.csv", "table.csv", "table.md", "normality.csv", "boxplots.png", "report.md"}
    assert names <= {p.name for p in out.iterdir()}
    assert not [p for p in out.iterdir() if ".tmp-" in p.name]
    err = capsys.readouterr().err
    assert err.count("excluded") == 3  # P04, P09, P15 in the made-up example
    with open(out / "scores.csv") as fh:
        scores = list(csv.DictReader(fh))
    assert len(scores) == 18
    inc = [r for r in scores if r["included"] == "yes"]
    assert len(inc) == 15
    with open(out / "table.csv") as fh:
        table = list(csv.DictReader(fh))
    assert [r["measure"] for r in table] == ["N_OF", "O_OF", "D_OF", "K_OF"]
    for col, row in zip(("n_of", "o_of", "d_of", "k_of"), table):
        a = [float(r[col]) for r in inc if r["condition"] == row["condition_a"]]
        b = [float(r[col]) for r in inc if r["condition"] == row["condition_b"]]
        p = stats.mannwhitneyu(a, b, alternative="two-sided").pvalue
        assert float(row["p"]) == pytest.approx(p, rel=1e-6)
        assert float(row["mean_a"]) == pytest.approx(np.mean(a), rel=1e-6)
    md = (out / "table.md").read_text()
    assert f"{table[3]['condition_a']} vs. {table[3]['condition_b']}" in md
    assert (out / "boxplots.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_cli_missing_columns_named(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    header = [c for c in _ITEM_HEADER if c != "ssq_fatigue"]
    header[header.index("ssq_vertigo")] = "ssq_vertgo"  # typo
    data = _write(tmp_path / "d.csv", header, [["a", "GR", *([0] * 15), *([1] * 18), 100]])
    assert main(["analyze", str(data), "-o", str(tmp_path / "r")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert "ssq_fatigue" in err
    assert "ssq_vertigo (found 'ssq_vertgo'?)" in err
    data = _write(
        tmp_path / "e.csv", ["id", "ssq_n", "ssq_o", "ssq_d", "flow"], [["a", 1, 1, 1, 1]]
    )
    assert main(["analyze", str(data), "-o", str(tmp_path / "r")]) == 2
    err = capsys.readouterr().err
    assert "column 'condition' missing" in err
    assert "MSSQ" in err


def test_cli_out_of_range_rows_reported(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # p8 keeps NR at two participants: one would be refused (a condition with one participant)
    rows = [_items_row(f"p{i}", "GR" if i < 4 else "NR", [1] * 16) for i in range(9)]
    rows[1][2 + 1] = 4  # p1: ssq_fatigue = 4
    rows[5][2 + 16] = "x"  # p5: mssq_child_cars = x
    rows[6][2 + 16 + 9 : 2 + 16 + 18] = ["t"] * 9  # p6: adult section all 't'
    rows[7][2 + 3] = ""  # p7: ssq_eyestrain blank
    data = _write(tmp_path / "d.csv", _ITEM_HEADER, rows, comment="made-up")
    out = tmp_path / "r"
    assert main(["analyze", str(data), "-o", str(out)]) == 0
    err = capsys.readouterr().err.splitlines()
    warn = [ln for ln in err if "warning" in ln]
    assert len(warn) == 4  # one line per bad row
    assert (
        "row 2 (line 4, id 'p1')" in warn[0]
    )  # line 1 comment, 2 header and "ssq_fatigue = 4 outside 0..3" in warn[0]
    assert "id 'p5'" in warn[1] and "mssq_child_cars = 'x'" in warn[1]
    assert "id 'p6'" in warn[2] and "adult section" in warn[2]
    assert "id 'p7'" in warn[3] and "ssq_eyestrain" in warn[3]
    with open(out / "scores.csv") as fh:
        ids = [r["id"] for r in csv.DictReader(fh)]
    assert ids == ["p0", "p2", "p3", "p4", "p8"]
    # 3 GR but 2 NR left: the paper's test is not possible, scores still written
    assert any("not possible" in ln for ln in err)


def test_cli_one_condition(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rows = [_items_row(f"p{i}", "GR", [1] * 16) for i in range(4)]
    data = _write(tmp_path / "d.csv", _ITEM_HEADER, rows)
    assert main(["analyze", str(data), "-o", str(tmp_path / "r")]) == 2
    err = capsys.readouterr().err
    assert "only one condition ('GR')" in err
    assert err.count("\n") == 1


def test_cli_three_conditions_need_choice(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    rows = [_items_row(f"p{i}", "ABC"[i % 3], [i % 4] * 16) for i in range(9)]
    data = _write(tmp_path / "d.csv", _ITEM_HEADER, rows)
    assert main(["analyze", str(data), "-o", str(tmp_path / "r")]) == 2
    assert "--conditions" in capsys.readouterr().err
    assert main(["analyze", str(data), "-o", str(tmp_path / "r"), "--conditions", "C,A"]) == 0
    with open(tmp_path / "r" / "table.csv") as fh:
        row = next(csv.DictReader(fh))
    assert (row["condition_a"], row["condition_b"]) == ("C", "A")
    assert (row["n_a"], row["n_b"]) == ("3", "3")  # B's 3 rows excluded
    assert row["note"] == ""
    assert 0.0 <= float(row["p"]) <= 1.0
