"""The statistics' files: tidy CSV tables (tests, model, power, per video) and analysis.md in plain words.

Also the report's shared writers: :func:`write_csv` (atomic, spreadsheet-safe text cells),
:func:`fmt` and :func:`p_text` (p values as ``< 0.001`` below 0.001, never ``0.000``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

from simulator.analyze.stats import MODEL_COLUMNS, POWER_COLUMNS, TEST_COLUMNS, Statistics
from simulator.core.fileio import atomic_output
from simulator.core.fileio import write_csv as core_write_csv

__all__ = ["STATS_FILES", "analysis_markdown", "fmt", "p_text", "write_csv", "write_statistics"]

#: The files :func:`write_statistics` may write (power.csv with ``--power``, the per-video
#: tables with several videos).
STATS_FILES = (
    "tests.csv",
    "model.csv",
    "power.csv",
    "tests_by_video.csv",
    "model_by_video.csv",
    "analysis.md",
)


def fmt(v: object, digits: int = 10) -> str:
    """A CSV cell: numbers with ``digits`` significant digits, NaN and None blank."""
    if v is None:
        return ""
    if isinstance(v, float):
        return "" if math.isnan(v) else f"{v:.{digits}g}"
    return str(v)


def write_csv(path: Path, header: Sequence[str], rows: Sequence[Sequence[object]]) -> None:
    """The report's tables through :func:`simulator.core.fileio.write_csv` (atomic; text
    cells cannot start a spreadsheet formula), numbers by :func:`fmt`."""
    core_write_csv(path, header, rows, fmt=fmt)


def p_text(p: float) -> str:
    """A p value as a report prints it: 3 decimals, ``< 0.001`` below that, ``n/a``."""
    if p is None or math.isnan(p):
        return "n/a"
    return "< 0.001" if p < 0.001 else f"{p:.3f}"


def _n(v: float, digits: int = 3) -> str:
    return "n/a" if v is None or (isinstance(v, float) and math.isnan(v)) else f"{v:.{digits}g}"


def write_statistics(st: Statistics, out: Path) -> list[Path]:
    """Write the tables of ``st`` and ``analysis.md`` into ``out``; returns the paths."""
    written = []

    def put(name: str, header: Sequence[str], rows: Sequence[dict], video: str | None = None):
        lead = [] if video is None else ["video"]
        write_csv(
            out / name, lead + list(header), [[r[k] for k in lead + list(header)] for r in rows]
        )
        written.append(out / name)

    put("tests.csv", TEST_COLUMNS, st.tests)
    put("model.csv", MODEL_COLUMNS, st.model)
    if st.power:
        put("power.csv", POWER_COLUMNS, st.power)
    if st.by_video:
        t = [{"video": v, **r} for v, (tr, _m) in st.by_video.items() for r in tr]
        m = [{"video": v, **r} for v, (_t, mr) in st.by_video.items() for r in mr]
        put("tests_by_video.csv", TEST_COLUMNS, t, video="video")
        put("model_by_video.csv", MODEL_COLUMNS, m, video="video")
    with atomic_output(out / "analysis.md") as tmp:
        tmp.write_text(analysis_markdown(st), encoding="utf-8")
    written.append(out / "analysis.md")
    return written


def _tests_md(rows: Sequence[dict]) -> list[str]:
    out = [
        "| Measure | Test | Statistic | p | p (Holm) | Effect [95 % CI] | n |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        eff = (
            ""
            if not r["effect_name"]
            else (f"{_n(r['effect'])} [{_n(r['effect_ci_low'])}, {_n(r['effect_ci_high'])}]")
        )
        out.append(
            f"| {r['measure']} | {r['test']} | {_n(r['statistic'], 4)} | {p_text(r['p'])}"
            f" | {p_text(r['p_holm'])} | {eff} | {r['n']} |"
        )
    return out


def _model_md(rows: Sequence[dict]) -> list[str]:
    out = ["| Term | Estimate | SE | CI | p |", "|---|---|---|---|---|"]
    for r in rows:
        ci = "" if math.isnan(r["ci_low"]) else f"[{_n(r['ci_low'], 4)}, {_n(r['ci_high'], 4)}]"
        out.append(
            f"| {r['term']} | {_n(r['estimate'], 4)} | {_n(r['std_error'], 3)} | {ci} "
            f"| {p_text(r['p'])} |"
        )
    return out


def _why_test(st: Statistics, a: str, b: str) -> list[str]:
    d, o = st.design, st.options
    ci = f"{100 * (1 - o.alpha):g} %"
    if d.paired:
        what = (
            "Each participant was measured in both conditions, so their two scores are not "
            "independent: the Wilcoxon signed-rank test compares each participant's "
            f"{b} score with their own {a} score (the mean of their rows per condition). "
            "A two-sample test (the paper's Mann-Whitney U in table.csv) would treat them "
            "as different people. The effect, the matched-pairs rank-biserial correlation "
            f"r (Kerby 2014), runs from -1 (every participant lower in {b}) to +1 (every "
            f"participant higher in {b}); 0 means no consistent difference."
        )
    else:
        what = (
            "Each participant was measured in one condition: the two-sided Mann-Whitney U "
            f"test compares the {a} group with the {b} group (each participant's rows "
            "averaged first). The effect, the rank-biserial correlation r (Wendt 1972), is "
            f"P({b} > {a}) - P({b} < {a}) for a random pair of participants: -1..+1, "
            "0 = no difference."
        )
    return [
        what + f" Its {ci} interval is a BCa bootstrap over participants "
        f"({o.n_boot} resamples, seed {o.seed}). p (Holm) corrects for testing four SSQ "
        "measures (Holm 1979). Shapiro-Wilk rows check the normality a t test would "
        "assume (the rank tests do not)."
    ]


def _in_words(st: Statistics, a: str, b: str) -> list[str]:
    """One sentence on the test's effect, one on the model's condition term."""
    out = []
    t = next((r for r in st.tests if r["measure"] == "ssq_total" and r["effect_name"]), None)
    if t is not None and math.isfinite(t["effect"]):
        lo, hi = t["effect_ci_low"], t["effect_ci_high"]
        stats_ = (
            f"r = {_n(t['effect'])}, interval {_n(lo)} to {_n(hi)}; p {p_text(t['p'])}, "
            f"Holm {p_text(t['p_holm'])}"
        )
        if lo <= 0.0 <= hi:
            out.append(
                f"In words: the data show no clear difference in the SSQ total between "
                f"{b} and {a} ({stats_}): the interval includes 0, so an effect either "
                "way, or none, fits them."
            )
        else:
            way = "higher" if t["effect"] > 0 else "lower"
            what = (
                f"the rank-weighted share of participants higher under {b} minus that lower"
                if st.design.paired
                else f"P({b} > {a}) - P({b} < {a}) for a participant of each group"
            )
            out.append(
                f"In words: the SSQ total was {way} under {b} than under {a} ({stats_}); r is "
                f"{what}."
            )
    c = next((r for r in st.model if r["term"].startswith("condition[")), None)
    if c is not None:
        unit = "log(1 + SSQ) units" if st.options.transform == "log1p" else "SSQ points"
        out.append(
            f"The model puts {b} at {_n(c['estimate'], 3)} {unit} from {a} "
            f"(interval {_n(c['ci_low'], 3)} to {_n(c['ci_high'], 3)}, p "
            f"{p_text(c['p'])}) at equal flow and MSSQ-short."
        )
    return out


def _power_md(st: Statistics) -> list[str]:
    out = [
        "| Design | Test | Effect | alpha | Power | Participants needed | Observed power |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in st.power:
        out.append(
            f"| {r['design']} | {r['test']} | {_n(r['effect'])} | {r['alpha']:g} | "
            f"{r['power']:g} | {fmt(r['participants_needed'])} | "
            f"{_n(r['observed_power'])} |"
        )
    r = st.power[0]
    who = "participants (each in both conditions)" if st.design.paired else "participants per group"
    if isinstance(r["participants_needed"], int):
        out += [
            "",
            (
                f"In words: to detect a standardised effect of {_n(abs(r['effect']))} with "
                f"{r['power']:g} power at alpha {r['alpha']:g}, the next study needs "
                f"{r['participants_needed']} {who}. The solver is the t test's; the rank test "
                "needs about 5 % more under normality (asymptotic relative efficiency 3/pi; "
                "Lehmann 1975). "
                + (
                    "The observed power is this study's power for the given effect."
                    if st.options.effect is not None
                    else "The observed power (this study's n at its own effect) follows "
                    "from p and adds no evidence (Hoenig & Heisey 2001)."
                )
            ),
        ]
    return out


def analysis_markdown(st: Statistics) -> str:
    """``analysis.md``: the design, which test and why, the tables, what they mean, notes."""
    d, info = st.design, st.model_info
    a, b = (str(c) for c in d.table["condition"].cat.categories)
    n = d.table["participant"].nunique()
    scores = "change from the pre-exposure SSQ (post - pre)" if d.change else "SSQ after exposure"
    lines = [
        "# Statistics of the design",
        "",
        (
            f"Design: **{d.name}** ({d.why}). Conditions: {a} (reference) vs. {b}. "
            f"{n} participants, {len(d.table)} rows; scores: {scores}."
        ),
        "",
        "## Which test and why",
        "",
        *_why_test(st, a, b),
        "",
        *_tests_md(st.tests),
        "",
        *_in_words(st, a, b)[:1],
        "",
        "## Model",
        "",
        f"`{info['formula']}`; {info.get('method', 'not fitted')}. Converged: "
        f"{'yes' if info['converged'] else 'NO'}."
        + (f" {info['error']}." if info["error"] else ""),
        "",
        (
            "The condition term is the difference between the conditions at equal flow and "
            "susceptibility"
            + (
                ", with each participant's own level as a random effect"
                + (" and each video's" if d.videos[1:] else "")
                if "MixedLM" in info.get("method", "")
                else " (one row per participant: ordinary least squares)"
            )
            + ". K_OF (the "
            "paper's method, table.csv) divides by flow and weights by MSSQ-short, which "
            "assumes sickness is proportional to both; the model estimates how much each "
            "matters instead (Brown & Prescott 2015; Bates et al. 2015)."
        ),
        "",
        *_model_md(st.model),
        "",
        *_in_words(st, a, b)[1:],
    ]
    if st.power:
        lines += ["", "## Power (next study)", "", *_power_md(st)]
    if st.by_video:
        lines += ["", "## Per video", ""]
        for v, (t, m) in st.by_video.items():
            lines += [f"### {v}", "", *_tests_md(t), "", *_model_md(m), ""]
    lines += ["", "## Notes", ""] + ([f"- {s}" for s in st.notes] or ["- none"])
    return "\n".join(lines) + "\n"
