"""The design's statistics against scipy and statsmodels called directly on the same data."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import statsmodels.formula.api as smf
from scipy import stats
from statsmodels.stats.multitest import multipletests
from statsmodels.stats.power import TTestIndPower, TTestPower
from statsmodels.tools.sm_exceptions import ConvergenceWarning

from simulator.analyze import StatsOptions, analyze_study, read_study
from simulator.analyze.simulate import SIM_HEADER, simulated_rows, write_simulated
from simulator.cli import main
from simulator.core.errors import InputError

TOL = 1e-6


def _read(path: Path) -> list[dict]:
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def _frame(rows: list[list[object]]) -> pd.DataFrame:
    df = pd.DataFrame(rows, columns=SIM_HEADER)
    df["condition"] = pd.Categorical(df["condition"], categories=["A", "B"])
    return df.rename(columns={"id": "participant"})


def _main_tests(st) -> dict:
    return {r["measure"]: r for r in st.tests if r["effect_name"]}


def _t_pm(t_plus: float, t_minus: float) -> float:
    return (t_plus - t_minus) / (t_plus + t_minus)


def test_within_matches_scipy_and_statsmodels(tmp_path: Path) -> None:
    rows = simulated_rows(14, effect=6.0, seed=5)
    data = write_simulated(tmp_path / "d.csv", rows)
    opts = StatsOptions(power=0.8, n_boot=200)
    an = analyze_study(read_study(data), stats=opts)
    st = an.statistics
    assert (st.design.name, st.design.paired, st.design.detected) == ("within", True, True)
    df = _frame(rows)
    w = df.pivot(index="participant", columns="condition", values="ssq_total")
    d = (w["B"] - w["A"]).to_numpy()
    ref = stats.wilcoxon(d)
    t = _main_tests(st)["ssq_total"]
    assert t["test"] == "Wilcoxon signed-rank" and t["n"] == 14
    assert t["statistic"] == pytest.approx(ref.statistic, abs=TOL)
    assert t["p"] == pytest.approx(ref.pvalue, abs=TOL)
    r = stats.rankdata(np.abs(d))
    assert t["effect"] == pytest.approx(_t_pm(r[d > 0].sum(), r[d < 0].sum()), abs=TOL)
    assert t["effect_ci_low"] <= t["effect"] <= t["effect_ci_high"]

    # the interval: scipy's BCa bootstrap, same seed (0), same resamples (2000 -> 200 here)
    def rb(x, axis=-1):
        x = np.moveaxis(x, axis, -1)
        rk = stats.rankdata(np.abs(x), axis=-1)  # no zero differences in these data
        return ((rk * (x > 0)).sum(-1) - (rk * (x < 0)).sum(-1)) / rk.sum(-1)

    ci = stats.bootstrap((d,), rb, vectorized=True, n_resamples=200, method="BCa",
                         random_state=np.random.default_rng(0)).confidence_interval  # fmt: skip
    assert (t["effect_ci_low"], t["effect_ci_high"]) == pytest.approx(tuple(ci), abs=TOL)
    # Holm across the four measures, as multipletests does it
    ps = [_main_tests(st)[m]["p"] for m in ("ssq_total", "ssq_n", "ssq_o", "ssq_d")]
    holm = multipletests(ps, method="holm")[1]
    assert [_main_tests(st)[m]["p_holm"] for m in ("ssq_total", "ssq_n", "ssq_o", "ssq_d")] == (
        pytest.approx(list(holm), abs=TOL)
    )
    # the model: (1 | participant), REML, statsmodels directly
    res = smf.mixedlm("ssq_total ~ condition + flow + mssq", df, groups="participant").fit(
        reml=True
    )
    got = {r["term"]: r for r in st.model}
    for term in res.fe_params.index:
        assert got[term]["estimate"] == pytest.approx(res.fe_params[term], abs=TOL)
        assert got[term]["std_error"] == pytest.approx(res.bse_fe[term], abs=TOL)
        assert got[term]["p"] == pytest.approx(res.pvalues[term], abs=TOL)
        assert got[term]["ci_low"] == pytest.approx(res.conf_int().loc[term, 0], abs=TOL)
    assert got["participant Var"]["estimate"] == pytest.approx(res.cov_re.iloc[0, 0], abs=TOL)
    assert st.model_info["converged"] is True
    # power: paired t with d_z = mean / SD of the differences
    dz = d.mean() / d.std(ddof=1)
    pw = st.power[0]
    need = TTestPower().solve_power(effect_size=abs(dz), alpha=0.05, power=0.8)
    assert pw["effect"] == pytest.approx(dz, abs=TOL)
    assert pw["participants_needed"] == math.ceil(need)
    assert pw["observed_power"] == pytest.approx(TTestPower().power(abs(dz), 14, 0.05), abs=TOL)


def test_between_matches_scipy_and_statsmodels(tmp_path: Path) -> None:
    rows = simulated_rows(16, effect=8.0, design="between", seed=7)
    data = write_simulated(tmp_path / "d.csv", rows)
    st = analyze_study(
        read_study(data), stats=StatsOptions(power=0.9, alpha=0.01, n_boot=200)
    ).statistics
    assert (st.design.name, st.design.paired) == ("between", False)
    df = _frame(rows)
    a = df.loc[df.condition == "A", "ssq_n"].to_numpy()
    b = df.loc[df.condition == "B", "ssq_n"].to_numpy()
    ref = stats.mannwhitneyu(a, b, alternative="two-sided")
    t = _main_tests(st)["ssq_n"]
    assert t["statistic"] == pytest.approx(ref.statistic, abs=TOL)
    assert t["p"] == pytest.approx(ref.pvalue, abs=TOL)
    assert t["effect"] == pytest.approx(1 - 2 * ref.statistic / (a.size * b.size), abs=TOL)
    # P(B > A) - P(B < A) by counting pairs, the rank-biserial's definition
    gt = (b[:, None] > a[None, :]).mean() - (b[:, None] < a[None, :]).mean()
    assert t["effect"] == pytest.approx(gt, abs=TOL)
    ta = df.loc[df.condition == "A", "ssq_total"].to_numpy()
    tb = df.loc[df.condition == "B", "ssq_total"].to_numpy()

    def rb(x, y, axis=-1):  # P(B > A) - P(B < A) over all pairs
        x, y = np.moveaxis(x, axis, -1), np.moveaxis(y, axis, -1)
        return np.sign(y[..., :, None] - x[..., None, :]).mean(axis=(-2, -1))

    ci = stats.bootstrap((ta, tb), rb, vectorized=True, n_resamples=200, method="BCa",
                         confidence_level=0.99, random_state=np.random.default_rng(0)).confidence_interval  # fmt: skip
    tt = _main_tests(st)["ssq_total"]
    assert (tt["effect_ci_low"], tt["effect_ci_high"]) == pytest.approx(tuple(ci), abs=TOL)
    sw = {r["test"]: r for r in st.tests if r["measure"] == "ssq_n" and not r["effect_name"]}
    assert sw["Shapiro-Wilk (A)"]["p"] == pytest.approx(stats.shapiro(a).pvalue, abs=TOL)
    res = smf.ols("ssq_total ~ condition + flow + mssq", df).fit()
    got = {r["term"]: r for r in st.model}
    for term in res.params.index:
        assert got[term]["estimate"] == pytest.approx(res.params[term], abs=TOL)
        assert got[term]["p"] == pytest.approx(res.pvalues[term], abs=TOL)
        assert got[term]["ci_high"] == pytest.approx(res.conf_int(0.01).loc[term, 1], abs=TOL)
    sp = math.sqrt((7 * ta.var(ddof=1) + 7 * tb.var(ddof=1)) / 14)
    dd = (tb.mean() - ta.mean()) / sp
    need = TTestIndPower().solve_power(effect_size=abs(dd), alpha=0.01, power=0.9, ratio=1.0)
    assert st.power[0]["effect"] == pytest.approx(dd, abs=TOL)
    assert st.power[0]["participants_needed"] == math.ceil(need)


@pytest.mark.slow  # several full reports (box plots) and crossed models
def test_mixed_three_videos_cli(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rows = simulated_rows(10, videos=3, effect=5.0, seed=11)
    data = write_simulated(tmp_path / "d.csv", rows)
    out = tmp_path / "r"
    argv = ["analyze", str(data), "-o", str(out), "--power", "0.8", "--effect", "0.5"]
    assert main([*argv, "--n-boot", "200"]) == 0
    err = capsys.readouterr().err
    assert "pooling mixes videos of very different flow" in err
    df = _frame(rows)
    # the test compares participant means over the videos, paired
    w = df.groupby(["participant", "condition"], observed=True)["ssq_o"].mean().unstack()
    ref = stats.wilcoxon((w["B"] - w["A"]).to_numpy())
    tests = {(r["measure"], r["test"]): r for r in _read(out / "tests.csv")}
    assert list(_read(out / "tests.csv")[0]) == [
        "measure",
        "test",
        "statistic",
        "p",
        "p_holm",
        "effect",
        "effect_name",
        "effect_ci_low",
        "effect_ci_high",
        "n",
    ]
    assert float(tests[("ssq_o", "Wilcoxon signed-rank")]["p"]) == pytest.approx(
        ref.pvalue, abs=TOL
    )
    # crossed (1 | participant) + (1 | video), as statsmodels' documentation fits them
    vc = {"participant": "0 + C(participant)", "video": "0 + C(video)"}
    res = smf.mixedlm(
        "ssq_total ~ condition + flow + mssq",
        df.assign(g=1),
        groups="g",
        re_formula="0",
        vc_formula=vc,
    ).fit(reml=True)
    model = {r["term"]: r for r in _read(out / "model.csv")}
    assert list(_read(out / "model.csv")[0]) == [
        "term",
        "estimate",
        "std_error",
        "ci_low",
        "ci_high",
        "p",
    ]
    for term in res.fe_params.index:
        assert float(model[term]["estimate"]) == pytest.approx(res.fe_params[term], abs=TOL)
        assert float(model[term]["p"]) == pytest.approx(res.pvalues[term], abs=TOL)
    assert float(model["video Var"]["estimate"]) == pytest.approx(res.vcomp[1], abs=TOL)
    power = _read(out / "power.csv")
    assert list(power[0]) == [
        "design",
        "test",
        "effect",
        "alpha",
        "power",
        "participants_needed",
        "observed_power",
    ]
    assert power[0]["design"] == "mixed" and float(power[0]["effect"]) == 0.5
    assert int(power[0]["participants_needed"]) == math.ceil(
        TTestPower().solve_power(effect_size=0.5, alpha=0.05, power=0.8)
    )
    by_video = _read(out / "tests_by_video.csv")
    assert {r["video"] for r in by_video} == {"V1", "V2", "V3"}
    sub = df[df.video == "V2"].pivot(index="participant", columns="condition", values="ssq_total")
    v2 = next(r for r in by_video if r["video"] == "V2" and r["measure"] == "ssq_total")
    assert float(v2["p"]) == pytest.approx(stats.wilcoxon(sub["B"] - sub["A"]).pvalue, abs=TOL)
    text = (out / "analysis.md").read_text()
    assert "## Per video" in text and "Wilcoxon signed-rank" in text and "not independent" in text


def test_change_scores_from_pre_columns(tmp_path: Path) -> None:
    rng = np.random.default_rng(2)
    header = [
        "id",
        "condition",
        "ssq_n",
        "ssq_o",
        "ssq_d",
        "pre_ssq_n",
        "pre_ssq_o",
        "pre_ssq_d",
        "mssq",
        "flow",
    ]
    rows = []
    for i in range(8):
        for c in ("A", "B"):
            post = rng.uniform(10, 60, 3).round(2)
            pre = rng.uniform(0, 10, 3).round(2)
            rows.append([f"p{i}", c, *post, *pre, 10 + i, 500 + 10 * i + (c == "B")])
    data = tmp_path / "d.csv"
    pd.DataFrame(rows, columns=header).to_csv(data, index=False)
    st = analyze_study(read_study(data), stats=StatsOptions(n_boot=200)).statistics
    assert st.design.change
    df = pd.DataFrame(rows, columns=header)
    ch = (df["ssq_d"] - df["pre_ssq_d"]).to_numpy()
    d = ch[1::2] - ch[::2]
    assert _main_tests(st)["ssq_d"]["p"] == pytest.approx(stats.wilcoxon(d).pvalue, abs=TOL)
    rows[0][5:8] = [150.0, 150.0, 250.0]  # p0 felt worse before than after: a change < -1
    pd.DataFrame(rows, columns=header).to_csv(data, index=False)
    with pytest.raises(InputError, match=r"d.csv: --transform log1p: participant 'p0' has an SSQ"):
        analyze_study(read_study(data), stats=StatsOptions(transform="log1p", n_boot=200))
    with pytest.raises(InputError, match="pre-exposure SSQ subscore columns missing: pre_ssq_o"):
        pd.DataFrame(rows, columns=header).drop(columns="pre_ssq_o").to_csv(data, index=False)
        read_study(data)


def test_log1p_transform(tmp_path: Path) -> None:
    rows = simulated_rows(8, seed=3)
    data = write_simulated(tmp_path / "d.csv", rows)
    st = analyze_study(
        read_study(data), stats=StatsOptions(transform="log1p", n_boot=200)
    ).statistics
    with pytest.warns(ConvergenceWarning, match="on the boundary"):  # statsmodels says so too
        res = smf.mixedlm(
            "np.log1p(ssq_total) ~ condition + flow + mssq", _frame(rows), groups="participant"
        ).fit(reml=True)
    got = {r["term"]: r["estimate"] for r in st.model}
    assert got["condition[T.B]"] == pytest.approx(res.fe_params["condition[T.B]"], abs=TOL)
    assert st.model_info["formula"].startswith("np.log1p(ssq_total)")
    # statsmodels' own warning (a variance on the boundary) is surfaced, not hidden
    assert any("statsmodels warns: The MLE may be on the boundary" in n for n in st.notes)


def test_user_file_among_the_outputs_is_refused(tmp_path, capsys) -> None:
    (tmp_path / "r").mkdir()
    (tmp_path / "r" / "tests.csv").write_text("mine\n")
    rc, _, out = _cli(tmp_path, simulated_rows(6, seed=1))
    assert rc == 2 and "tests.csv: exists and was not written by vimsim analyze" in (
        capsys.readouterr().err
    )
    assert (out / "tests.csv").read_text() == "mine\n"


def _cli(tmp_path: Path, rows, *extra: str, header=SIM_HEADER) -> tuple[int, str, Path]:
    data = tmp_path / "d.csv"
    pd.DataFrame(rows, columns=header).to_csv(data, index=False)
    out = tmp_path / "r"
    rc = main(["analyze", str(data), "-o", str(out), "--n-boot", "200", *extra])
    return rc, data, out


def test_within_missing_condition_dropped_then_refused(tmp_path, capsys) -> None:
    rows = simulated_rows(8, seed=4)
    rows = [r for r in rows if not (r[0] == "P002" and r[1] == "B")]
    rc, _, out = _cli(tmp_path, rows)
    err = capsys.readouterr().err
    assert rc == 0
    assert "1 participant(s) dropped from the paired test" in err and "'P002'" in err
    assert _read(out / "tests.csv")[0]["n"] == "7"
    rows = [r for r in rows if not (r[0] in ("P003", "P004") and r[1] == "A")]
    rc, data, _ = _cli(tmp_path, rows)
    err = capsys.readouterr().err.strip()
    assert rc == 2 and err.count("\n") == 0
    assert str(data) in err and "5 participant(s) have rows in both 'A' and 'B'" in err
    assert ">= 6 complete pairs" in err


@pytest.mark.parametrize(
    ("design", "drop_video", "expect"),
    [
        ("mixed", True, "--design mixed needs column 'video' or 'session'"),
        ("between", False, "participant 'P001' has 2 rows"),
        ("within", False, "several rows per condition"),
    ],
)
def test_forced_design_the_data_cannot_have(tmp_path, capsys, design, drop_video, expect) -> None:
    rows = simulated_rows(6, videos=1 if design != "within" else 2, seed=1)
    header = list(SIM_HEADER)
    if drop_video:
        rows = [r[:2] + r[3:] for r in rows]
        header.remove("video")
    rc, data, _ = _cli(tmp_path, rows, "--design", design, header=header)
    err = capsys.readouterr().err.strip()
    assert rc == 2 and expect in err and str(data) in err and err.count("\n") == 0


def test_condition_with_one_participant_refused(tmp_path, capsys) -> None:
    rows = simulated_rows(6, design="between", seed=1)
    rows = [r for r in rows if r[1] == "A" or r[0] == "P002"]
    rc, data, out = _cli(tmp_path, rows)
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert rc == 2 and "condition 'B' has 1 participant(s) ('P002')" in err and str(data) in err
    assert not (out / "tests.csv").exists()


def test_model_that_cannot_be_fitted_is_reported(tmp_path, capsys) -> None:
    rows = simulated_rows(8, seed=6)
    for r in rows:
        r[-1] = 800.0  # flow constant: collinear with the intercept
        r[-2] = 10.0  # mssq too
    rc, _, out = _cli(tmp_path, rows)
    err = capsys.readouterr().err
    assert rc == 0
    assert "model: the model could not be fitted: Singular matrix" in err
    assert _read(out / "model.csv") == []  # the header only
    assert "could not be fitted" in (out / "analysis.md").read_text()
    assert _read(out / "tests.csv")[0]["test"] == "Wilcoxon signed-rank"  # the rest is written


@pytest.mark.parametrize(
    ("args", "expect"),
    [
        (["--power", "1.5"], "outside (0, 1)"),
        (["--effect", "0"], "infinitely many participants"),
        (["--n-boot", "10"], "below 200"),
        (["--design", "crossover"], "invalid choice"),
    ],
)
def test_bad_options_exit_2(tmp_path, capsys, args, expect) -> None:
    with pytest.raises(SystemExit) as e:
        _cli(tmp_path, simulated_rows(6, seed=1), *args)
    assert e.value.code == 2 and expect in capsys.readouterr().err
    with pytest.raises(InputError, match="--alpha"):
        StatsOptions(alpha=2.0)


def test_bootstrap_is_seeded(tmp_path: Path) -> None:
    data = write_simulated(tmp_path / "d.csv", simulated_rows(10, seed=8))
    st = [
        analyze_study(read_study(data), stats=StatsOptions(seed=s, n_boot=200)).statistics
        for s in (1, 1, 2)
    ]
    ci = [
        (_main_tests(x)["ssq_total"]["effect_ci_low"], _main_tests(x)["ssq_n"]["effect_ci_high"])
        for x in st
    ]
    assert ci[0] == ci[1]


def _study_analysis(tmp_path: Path, conds: list[str], fast: int = 0) -> dict:
    """``vimsim study``'s analysis step on hand-made EPOF CSVs (one viewing per participant)."""
    from types import SimpleNamespace

    from simulator.study.outputs import _analysis

    out = tmp_path / "o"
    (out / "epof").mkdir(parents=True)
    q = tmp_path / "q.csv"
    rows, table = [], []
    for i, c in enumerate(conds):
        pid, vid = f"u{i}", f"clip-u{i}"
        video, k = ("fast", 13) if i < fast else ("clip", 1)
        (out / "epof" / f"{vid}.csv").write_text(
            "frame,time_s,yaw_deg,pitch_deg,roll_deg,epof_dps,opacity\n"
            f"0,0,0,0,0,{k * (100 + 10 * i)},0\n1,0.1,0,0,0,{k * (120 + 10 * i)},0\n"
        )
        rows.append([pid, c, 9.54 * (i % 4), 7.58, 13.92 * (i % 3), 5 + i])
        table.append(
            {"status": "ok", "participant": pid, "condition": c, "viewing": vid, "video": video}
        )
    pd.DataFrame(
        rows, columns=["participant", "condition", "ssq_n", "ssq_o", "ssq_d", "mssq"]
    ).to_csv(q, index=False)
    manifest = SimpleNamespace(
        questionnaires={
            "path": str(q),
            "flow_stat": "mean",
            "exclude_below": None,
            "conditions": None,
        }
    )
    return _analysis(manifest, out, table)


@pytest.mark.slow  # several full reports (box plots) and crossed models
def test_study_and_report_show_the_design_statistics(tmp_path: Path) -> None:
    from simulator.report.pages import Site

    info = _study_analysis(tmp_path / "a", ["GR", "NR"] * 4)
    assert info["error"] is None and "tests.csv" in info["files"] and "model.csv" in info["files"]
    folder = tmp_path / "a" / "o" / "analysis"
    html = Site({"outputs": {"analysis": info}}, [], {}).analysis_page(folder)
    assert "Tests of the design" in html and "<td>Mann-Whitney U</td>" in html
    assert "Mixed model" in html and "In plain words" in html
    # one GR participant: the paper's analysis alone, with the reason in its notes
    info = _study_analysis(tmp_path / "b", ["GR", "NR", "NR", "NR"])
    assert info["error"] is None and "tests.csv" not in info["files"]
    assert any("no design statistics" in n and "'GR' has 1 participant" in n for n in info["notes"])
    # two videos of 13x different flow: per-video tables and the warning on pooling them
    info = _study_analysis(tmp_path / "c", ["GR", "NR"] * 6, fast=6)
    assert "tests_by_video.csv" in info["files"]
    assert any("pooling mixes videos of very different flow" in n for n in info["notes"])


def test_interval_where_every_resample_is_equal(tmp_path: Path) -> None:
    """Every participant higher in B: r = 1 in every resample, BCa undefined, the
    percentile interval [1, 1] reported (not NaN, no warning)."""
    rows = simulated_rows(8, effect=80.0, seed=1, sd_residual=0.5)
    st = analyze_study(read_study(write_simulated(tmp_path / "d.csv", rows)),
                       stats=StatsOptions(n_boot=200)).statistics  # fmt: skip
    t = _main_tests(st)["ssq_total"]
    assert (t["effect"], t["effect_ci_low"], t["effect_ci_high"]) == (1.0, 1.0, 1.0)


def test_sessions_make_a_mixed_design_and_the_options_come_from_one_table(tmp_path) -> None:
    from simulator.analyze.design import design_table
    from simulator.cli import build_parser
    from simulator.core.statsopts import DESIGNS, STATS_OPTIONS

    rows = simulated_rows(8, videos=2, seed=9)
    for r in rows:  # the two "videos" become two sessions of one video
        r[2] = "V1"
    header = ["id", "condition", "session", *SIM_HEADER[3:]]
    rows = [[r[0], r[1], f"S{k % 2 + 1}", *r[3:]] for k, r in enumerate(rows)]
    pd.DataFrame(rows, columns=header).to_csv(tmp_path / "d.csv", index=False)
    study = read_study(tmp_path / "d.csv")
    d = design_table(study, study.participants, ("A", "B"))
    assert (d.name, d.paired, d.videos) == ("mixed", True, ())
    assert len(d.table) == 32 and d.table["participant"].nunique() == 8
    # the parser's options are the table's: names, choices and defaults
    sub = next(a for a in build_parser()._actions if a.dest == "command" or a.choices)
    p = sub.choices["analyze"]
    acts = {a.dest: a for a in p._actions}
    for opt in STATS_OPTIONS:
        assert acts[opt.name].default == opt.default and opt.flag in acts[opt.name].option_strings
    assert tuple(acts["design"].choices) == DESIGNS


def test_model_not_converged_is_a_warning_line() -> None:
    from simulator.analyze.stats import _model_notes

    info = {"error": None, "converged": False, "warnings": ["Gradient optimization failed"]}
    notes = _model_notes(info, "model")
    assert notes[0].startswith("WARNING: model did not converge")
    assert notes[1] == "model: statsmodels warns: Gradient optimization failed"
