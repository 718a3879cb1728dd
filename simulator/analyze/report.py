"""The study analysis (exclusion, K_OF, Shapiro-Wilk, Mann-Whitney, the design's statistics) and its report files."""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from simulator.analyze.data import Participant, Study
from simulator.analyze.design import design_table
from simulator.analyze.scores import K_OF_TEXT, k_of
from simulator.analyze.stats import Statistics, StatsOptions, study_statistics
from simulator.analyze.summary import STATS_FILES, p_text, write_statistics
from simulator.analyze.summary import write_csv as _write_csv
from simulator.core.errors import InputError
from simulator.core.fileio import OutputFolder, atomic_output

__all__ = ["Analysis", "analyze_study", "p_text", "write_report"]

# Measures of the paper's table, in its order: (column in scores.csv, label, SSQ field).
_OF_MEASURES: tuple[tuple[str, str, str], ...] = (
    ("n_of", "N_OF", "nausea"),
    ("o_of", "O_OF", "oculomotor"),
    ("d_of", "D_OF", "disorientation"),
    ("k_of", "K_OF", "total"),
)


_MIN_PER_GROUP = 3


@dataclass(frozen=True)
class Analysis:
    """Everything :func:`write_report` writes.

    Attributes
    ----------
    study : Study
    conditions : (str, str)
        The two condition labels, in table order ("A vs. B").
    included : tuple of Participant
        Participants used for K_OF and the tests.
    excluded : tuple of (str, str)
        (id, reason) of every participant left out (low flow, other condition).
    of_scores : dict str -> ndarray, shape (len(included),)
        ``n_of``, ``o_of``, ``d_of``, ``k_of`` aligned with ``included``.
    normality : tuple of dict
        Shapiro-Wilk rows: measure, group, n, W, p, note.
    comparisons : tuple of dict
        Mann-Whitney rows: measure, the two conditions, n, means, medians, U, p, note.
    notes : tuple of str
        One line each: tests not possible, undefined scores.
    statistics : Statistics or None
        The design's tests, model and power (:mod:`simulator.analyze.stats`); None when
        :func:`analyze_study` was given no ``stats`` options.
    """

    study: Study
    conditions: tuple[str, str]
    included: tuple[Participant, ...]
    excluded: tuple[tuple[str, str], ...]
    of_scores: dict[str, NDArray[np.float64]] = field(repr=False)
    normality: tuple[dict, ...]
    comparisons: tuple[dict, ...]
    notes: tuple[str, ...]
    exclude_below: float | None = None
    k_of_formula: str = "invariant"
    statistics: Statistics | None = None
    excluded_rows: dict[int, str] = field(default_factory=dict, repr=False)

    def __post_init__(self) -> None:
        if len(self.conditions) != 2 or self.conditions[0] == self.conditions[1]:
            raise InputError(f"expected two different conditions; got {self.conditions}")

    def messages(self) -> list[str]:
        """Notes, then per-measure test notes (measures with the same note on one line)."""
        by_note: dict[str, list[str]] = {}
        for r in self.comparisons:
            if r["note"]:
                by_note.setdefault(r["note"], []).append(r["measure"])
        return list(self.notes) + [f"{', '.join(m)}: {n}" for n, m in by_note.items()]


def _shapiro(values: NDArray[np.float64]) -> tuple[float, float, str]:
    from scipy import stats

    v = values[np.isfinite(values)]
    if v.size < _MIN_PER_GROUP:
        return math.nan, math.nan, f"not possible: n = {v.size} < {_MIN_PER_GROUP}"
    if np.ptp(v) == 0:
        return math.nan, math.nan, "not possible: every value is equal"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = stats.shapiro(v)
    return float(res.statistic), float(res.pvalue), ""


def _pick_conditions(study: Study, conditions: Sequence[str] | None) -> tuple[str, str]:
    """The two condition labels compared: ``conditions`` (checked) or the file's two."""
    path = study.path
    if conditions is not None:
        conds = tuple(conditions)
        if len(conds) != 2 or conds[0] == conds[1]:
            raise InputError(
                f"--conditions: expected two different labels, e.g. NR,GR; got {conds}"
            )
        absent = [c for c in conds if c not in study.conditions]
        if absent:
            raise InputError(
                f"{path}: condition {absent[0]!r} (from --conditions) not found; "
                f"conditions in the file: {list(study.conditions)}"
            )
    else:
        if len(study.conditions) < 2:
            raise InputError(
                f"{path}: only one condition ({', '.join(map(repr, study.conditions)) or 'none'}); "
                "expected two (e.g. GR and NR) to compare"
            )
        if len(study.conditions) > 2:
            raise InputError(
                f"{path}: {len(study.conditions)} conditions {list(study.conditions)}; expected "
                "two: pick them with --conditions A,B"
            )
        conds = (study.conditions[0], study.conditions[1])
    return conds


def _split_participants(
    study: Study, conds: tuple[str, str], exclude_below: float | None
) -> tuple[list[Participant], list[tuple[str, str]]]:
    """``(included, excluded)``: excluded as ``(id, reason)``, in the file's order."""
    included: list[Participant] = []
    excluded: list[tuple[str, str]] = []
    for part in study.participants:
        if part.condition not in conds:
            excluded.append((part.id, f"condition {part.condition!r} not in {list(conds)}"))
        elif part.flow <= 0:
            excluded.append((part.id, f"flow {part.flow:g} <= 0 (K_OF divides by flow)"))
        elif exclude_below is not None and part.flow < exclude_below:
            excluded.append((part.id, f"flow {part.flow:g} < {exclude_below:g} (--exclude-below)"))
        else:
            included.append(part)
    return included, excluded


def _normality_rows(
    label: str, vals: NDArray[np.float64], g_arr: NDArray, conds: tuple[str, str]
) -> list[dict]:
    """Shapiro-Wilk of one measure over all participants and per condition."""
    normality: list[dict] = []
    for grp in ("all", *conds):
        v = vals if grp == "all" else vals[g_arr == grp]
        w, pv, note = _shapiro(v)
        normality.append(
            {
                "measure": label,
                "group": grp,
                "n": int(np.isfinite(v).sum()),
                "W": w,
                "p": pv,
                "note": note,
            }
        )
    return normality


def _mann_whitney(
    label: str, a: NDArray[np.float64], b: NDArray[np.float64], conds: tuple[str, str]
) -> dict:
    """The two-sided Mann-Whitney U row of one measure (condition a vs b; NaN scores dropped)."""
    from scipy import stats

    a, b = a[np.isfinite(a)], b[np.isfinite(b)]
    row = {
        "measure": label,
        "condition_a": conds[0],
        "condition_b": conds[1],
        "n_a": int(a.size),
        "n_b": int(b.size),
        "mean_a": float(a.mean()) if a.size else math.nan,
        "mean_b": float(b.mean()) if b.size else math.nan,
        "median_a": float(np.median(a)) if a.size else math.nan,
        "median_b": float(np.median(b)) if b.size else math.nan,
        "U": math.nan,
        "p": math.nan,
        "note": "",
    }
    if a.size < _MIN_PER_GROUP or b.size < _MIN_PER_GROUP:
        row["note"] = (
            f"Mann-Whitney U not possible: n = {a.size} ({conds[0]}) and {b.size} "
            f"({conds[1]}); needs >= {_MIN_PER_GROUP} per group"
        )
    else:
        res = stats.mannwhitneyu(a, b, alternative="two-sided")
        row["U"], row["p"] = float(res.statistic), float(res.pvalue)
    return row


def analyze_study(
    study: Study,
    *,
    exclude_below: float | None = None,
    conditions: Sequence[str] | None = None,
    k_of_formula: str = "invariant",
    notes: Sequence[str] = (),
    stats: StatsOptions | None = None,
) -> Analysis:
    """Exclude low-flow sessions, compute K_OF (N, O, D, K) and run the paper's tests.

    Parameters
    ----------
    study : Study
    exclude_below : float, optional
        Sessions whose flow is below this (same unit and statistic as the flow column or
        ``--flow-stat``) are excluded and reported by id. Sessions with flow 0 are always
        excluded (K_OF divides by flow).
    conditions : (str, str), optional
        The two condition labels in table order; rows with another label are excluded.
        Default: the two labels of the file, in order of first appearance.
    k_of_formula : ``"invariant"`` (default: independent of group size) or ``"paper"``
        (:func:`simulator.analyze.scores.k_of`).
    notes : lines the caller adds to the report's notes (e.g. a study's confounds).
    stats : StatsOptions, optional
        Also run the design's statistics (tests with effect sizes, mixed model, power).

    Raises
    ------
    InputError
        Not exactly two conditions, or no usable participant (nothing can be computed); with
        ``stats``, data that do not fit the design (:func:`~simulator.analyze.design.design_table`).
    """
    conds = _pick_conditions(study, conditions)
    if not study.participants:
        raise InputError(f"{study.path}: no usable participant row (every row has a problem)")

    included, excluded = _split_participants(study, conds, exclude_below)
    inc_rows = {q.row for q in included}
    ex_rows = {q.row: why for q, (_pid, why) in
               zip([q for q in study.participants if q.row not in inc_rows], excluded)}  # fmt: skip
    statistics = None
    if stats is not None:
        statistics = study_statistics(design_table(study, included, conds, stats.design), stats)

    notes = list(notes)
    groups = [q.condition for q in included]
    ms = np.array([q.mssq.total for q in included], dtype=np.float64)
    flow = np.array([q.flow for q in included], dtype=np.float64)
    of_scores: dict[str, NDArray[np.float64]] = {}
    for col, _label, attr in _OF_MEASURES:
        s = np.array([getattr(q.ssq, attr) for q in included], dtype=np.float64)
        of_scores[col] = k_of(s, ms, flow, groups, k_of_formula) if included else s
    notes += _group_size_notes(groups, conds, k_of_formula)
    for c in conds:
        sel = [g == c for g in groups]
        if any(sel) and float(ms[np.array(sel)].sum()) == 0.0:
            notes.append(
                f"condition {c!r}: every MSSQ-short score is 0, so K_OF is 0/0 (left blank)"
            )

    g_arr = np.array(groups, dtype=object)
    normality: list[dict] = []
    comparisons: list[dict] = []
    for col, label, _attr in _OF_MEASURES:
        vals = of_scores[col]
        normality += _normality_rows(label, vals, g_arr, conds)
        a, b = vals[g_arr == conds[0]], vals[g_arr == conds[1]]
        comparisons.append(_mann_whitney(label, a, b, conds))
    n_a = sum(g == conds[0] for g in groups)
    n_b = sum(g == conds[1] for g in groups)
    if n_a < _MIN_PER_GROUP or n_b < _MIN_PER_GROUP:
        notes.append(
            f"tests not possible: {n_a} participant(s) in {conds[0]!r} and {n_b} in {conds[1]!r} "
            f"after exclusion; Mann-Whitney U and per-condition Shapiro-Wilk need >= "
            f"{_MIN_PER_GROUP} per group (scores are still written)"
        )
    if statistics is not None:
        notes += list(statistics.notes)
        if statistics.design.name != "between":
            notes.append(f"{statistics.design.name} design: the paper's Mann-Whitney U "
                         "(table.csv) treats every row as another participant; tests.csv has "
                         "the design's test")  # fmt: skip
    return Analysis(
        study=study,
        conditions=conds,
        included=tuple(included),
        excluded=tuple(excluded),
        of_scores=of_scores,
        normality=tuple(normality),
        comparisons=tuple(comparisons),
        notes=tuple(notes),
        exclude_below=exclude_below,
        k_of_formula=k_of_formula,
        statistics=statistics,
        excluded_rows=ex_rows,
    )


def _group_size_notes(groups: list[str], conds: tuple[str, str], formula: str) -> list[str]:
    """A warning line when the condition groups differ in size (what it does to K_OF)."""
    n_a, n_b = (sum(g == c for g in groups) for c in conds)
    if n_a == n_b or not (n_a and n_b):
        return []
    what = (
        "the paper's K_OF scales with 1 / group size, so its values are not comparable "
        "across these groups (the default --k-of invariant is)"
        if formula == "paper"
        else "K_OF uses the group-size-invariant formula (--k-of paper gives the paper's, "
        "which would scale with 1 / group size)"
    )
    return [f"WARNING: unequal groups, {n_a} {conds[0]} vs. {n_b} {conds[1]}: {what}"]


def _table_markdown(an: Analysis) -> str:
    a, b = an.conditions
    out = [
        "| Subscore | Means | *p* value |",
        "|---|---|---|",
    ]
    for row in an.comparisons:
        ma = "n/a" if math.isnan(row["mean_a"]) else f"{row['mean_a']:.2f}"
        mb = "n/a" if math.isnan(row["mean_b"]) else f"{row['mean_b']:.2f}"
        out.append(f"| **{row['measure']}** | | |")
        out.append(f"| {a} vs. {b} | {ma} vs. {mb} | {p_text(row['p'])} |")
    return "\n".join(out) + "\n"


def _boxplot(an: Analysis, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    groups = np.array([q.condition for q in an.included], dtype=object)
    fig, axes = plt.subplots(1, len(_OF_MEASURES), figsize=(3.2 * len(_OF_MEASURES), 3.6))
    rng = np.random.default_rng(0)  # fixed jitter: same PNG for the same data
    for ax, (col, label, _attr) in zip(axes, _OF_MEASURES):
        data = []
        for c in an.conditions:
            v = an.of_scores[col][groups == c] if groups.size else np.zeros(0)
            data.append(v[np.isfinite(v)])
        ax.boxplot(data, showmeans=True, showfliers=False)  # points drawn below
        ax.set_xticks(
            range(1, len(data) + 1), [f"{c}\n(n={d.size})" for c, d in zip(an.conditions, data)]
        )
        for k, d in enumerate(data, start=1):
            ax.plot(k + rng.uniform(-0.08, 0.08, d.size), d, "o", ms=3, alpha=0.6, color="k")
        ax.set_title(label)
    axes[0].set_ylabel(
        "score x MS / (flow x group MS) x 1000"
        + (" x n_g / n_mean" if an.k_of_formula == "invariant" else "")
    )
    fig.tight_layout()
    with atomic_output(path) as tmp:
        fig.savefig(tmp, dpi=100)
    plt.close(fig)


def _report_lines(an: Analysis, table_md: str) -> list[str]:
    """The lines of ``report.md``: data, participants, the K_OF formula, the tables,
    exclusions, row problems and notes."""
    a, b = an.conditions
    lines = [
        "# Study analysis",
        "",
        (
            f"Data: `{an.study.path}`; session flow = {an.study.flow_stat} of `epof_dps` where "
            "an EPOF CSV is given, else the `flow` column."
        ),
        (
            f"Participants: {len(an.study.participants)} usable rows, {len(an.included)} included "
            f"({sum(q.condition == a for q in an.included)} {a}, "
            f"{sum(q.condition == b for q in an.included)} {b}), {len(an.excluded)} excluded, "
            f"{len(an.study.problems)} rows with problems."
        ),
        "",
        (
            f"K_OF formula ({an.k_of_formula}): {K_OF_TEXT[an.k_of_formula]}; the same for N, "
            "O and D."
        ),
        "",
        "## SSQ per unit of optical flow (Mann-Whitney U, two-sided)",
        "",
        table_md,
        "## Shapiro-Wilk",
        "",
        "| Measure | Group | n | W | *p* | Note |",
        "|---|---|---|---|---|---|",
    ]
    for r in an.normality:
        w = "n/a" if math.isnan(r["W"]) else f"{r['W']:.3f}"
        lines.append(
            f"| {r['measure']} | {r['group']} | {r['n']} | {w} | {p_text(r['p'])} | {r['note']} |"
        )
    if an.statistics is not None:
        d = an.statistics.design
        lines += ["", "## The design's statistics", "",
                  (f"Design {d.name} ({d.why}): the tests with effect sizes (`tests.csv`), the "
                   "mixed model (`model.csv`) and, with `--power`, `power.csv`; explained in "
                   "plain words in `analysis.md`.")]  # fmt: skip
    lines += ["", "## Excluded", ""]
    lines += [f"- {pid}: {why}" for pid, why in an.excluded] or ["- none"]
    lines += ["", "## Rows with problems (not used)", ""]
    lines += [f"- {s}" for s in an.study.problems] or ["- none"]
    lines += ["", "## Notes", ""]
    lines += [f"- {s}" for s in an.messages()] or ["- none"]
    return lines


#: What :func:`write_report` writes, in this order; ``report.md`` (the completion marker) last.
REPORT_FILES = ("scores.csv", "table.csv", "normality.csv", "table.md", "boxplots.png",
                *STATS_FILES, "report.md")  # fmt: skip


def write_report(an: Analysis, out_dir: str | Path) -> list[Path]:
    """Write the analysis into ``out_dir`` (created if needed), each file atomically.

    Files: ``scores.csv`` (one row per participant, excluded ones too, with the reason),
    ``table.csv`` and ``table.md`` (the paper's table: means per condition and Mann-Whitney
    p per subscore), ``normality.csv`` (Shapiro-Wilk per measure, pooled and per
    condition), ``boxplots.png``, ``report.md`` (all of it plus exclusions, row problems
    and notes). Returns the paths written.
    """
    folder = OutputFolder(out_dir, REPORT_FILES, "analyze")
    # refuses an input among our names (DATA.csv, an EPOF CSV) and files we did not write;
    # clears our previous run's files so an interrupted run never looks complete
    out = folder.prepare(inputs=[an.study.path])
    written: list[Path] = []

    reasons = an.excluded_rows
    of_by_row = {
        q.row: {col: float(an.of_scores[col][i]) for col, _l, _a in _OF_MEASURES}
        for i, q in enumerate(an.included)
    }
    header = [
        "id", "condition", "row", "included", "excluded_reason", "flow", "flow_source",
        "ssq_n", "ssq_o", "ssq_d", "ssq_total", "ssq_source",
        "mssq", "mssq_child", "mssq_adult", "mssq_source",
        "n_of", "o_of", "d_of", "k_of",
    ]  # fmt: skip
    rows = []
    for q in an.study.participants:
        of = of_by_row.get(q.row, {})
        rows.append(
            [
                q.id, q.condition, q.row, "yes" if q.row in of_by_row else "no",
                reasons.get(q.row, ""), q.flow, q.flow_source,
                q.ssq.nausea, q.ssq.oculomotor, q.ssq.disorientation, q.ssq.total, q.ssq_source,
                q.mssq.total, q.mssq.child, q.mssq.adult, q.mssq_source,
                *(of.get(col, math.nan) for col, _l, _a in _OF_MEASURES),
            ]
        )  # fmt: skip
    _write_csv(out / "scores.csv", header, rows)
    written.append(out / "scores.csv")

    t_header = ["measure", "condition_a", "condition_b", "n_a", "n_b", "mean_a", "mean_b",
                "median_a", "median_b", "U", "p", "note"]  # fmt: skip
    _write_csv(out / "table.csv", t_header, [[r[k] for k in t_header] for r in an.comparisons])
    written.append(out / "table.csv")

    n_header = ["measure", "group", "n", "W", "p", "note"]
    _write_csv(out / "normality.csv", n_header, [[r[k] for k in n_header] for r in an.normality])
    written.append(out / "normality.csv")

    table_md = _table_markdown(an)
    with atomic_output(out / "table.md") as tmp:
        tmp.write_text(table_md, encoding="utf-8")
    written.append(out / "table.md")

    _boxplot(an, out / "boxplots.png")
    written.append(out / "boxplots.png")

    if an.statistics is not None:
        written += write_statistics(an.statistics, out)
    lines = _report_lines(an, table_md)
    # the manifest, then the completion marker
    folder.complete([p.name for p in written] + ["report.md"])
    with atomic_output(out / "report.md") as tmp:
        tmp.write_text("\n".join(lines) + "\n", encoding="utf-8")
    written.append(out / "report.md")
    return written
