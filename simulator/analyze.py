"""Study analysis: SSQ, MSSQ-short, the paper's flow-normalised scores and its tests.

The pilot study of the paper (section 4.4) scored the Simulator Sickness Questionnaire
(SSQ, Kennedy et al. 1993) and the Motion Sickness Susceptibility Questionnaire short form
(MSSQ-short, Golding 2006), divided each SSQ score by the participant's session optical
flow and weighted it by their susceptibility (eq. for K_OF), excluded sessions with
unrealistically low flow, ran Shapiro-Wilk, then a two-sided Mann-Whitney U test between
the two conditions (GR vs NR), and reported the means per condition and the p values.

Data flow: :func:`read_study` (DATA.csv -> :class:`Study`, bad rows collected as one line
each) -> :func:`analyze_study` (exclusion, K_OF, tests -> :class:`Analysis`) ->
:func:`write_report` (CSV, Markdown and PNG files in a folder, each written atomically).

Formulas
--------
SSQ: each of the 16 items is rated 0 (none) .. 3 (severe). Raw subscale sums over the items
of :data:`SSQ_MEMBERSHIP` (several items count in two subscales); N = 9.54 x N_raw,
O = 7.58 x O_raw, D = 13.92 x D_raw, Total = 3.74 x (N_raw + O_raw + D_raw).

MSSQ-short: 9 motion types, each answered for childhood (before age 12) and for the last
10 years: 0 never felt sick, 1 rarely, 2 sometimes, 3 frequently, or ``t`` (never
travelled / never experienced). Section score = (sum of the answers) x 9 / (9 - number of
``t``); MSSQ = child section + adult section (0 .. 54).

K_OF (paper eq. in 4.4.1): K_OF,i = K_i x MS_i / (Flow_i x sum_{j in group of i} MS_j) x
1000, and the same for N, O and D. The group sum runs over the participants of the same
condition that remain after exclusion.
"""

from __future__ import annotations

import csv
import difflib
import math
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from simulator.errors import InputError
from simulator.fileio import atomic_output, check_input_file, check_output_dir

__all__ = [
    "FLOW_STATS",
    "MSSQ_TYPES",
    "SSQ_ITEMS",
    "SSQ_MEMBERSHIP",
    "Analysis",
    "FlowStat",
    "MSSQScore",
    "SSQScores",
    "Study",
    "analyze_study",
    "k_of",
    "mssq_section_score",
    "mssq_short_score",
    "read_study",
    "session_flow",
    "ssq_scores",
    "write_report",
]

FlowStat = Literal["mean", "median", "sum"]
FLOW_STATS: tuple[str, ...] = ("mean", "median", "sum")

# Kennedy et al. (1993), table of the 16 items; letters = subscales the item counts in.
SSQ_MEMBERSHIP: Mapping[str, str] = {
    "ssq_general_discomfort": "NO",
    "ssq_fatigue": "O",
    "ssq_headache": "O",
    "ssq_eyestrain": "O",
    "ssq_difficulty_focusing": "OD",
    "ssq_increased_salivation": "N",
    "ssq_sweating": "N",
    "ssq_nausea": "ND",
    "ssq_difficulty_concentrating": "NO",
    "ssq_fullness_of_head": "D",
    "ssq_blurred_vision": "OD",
    "ssq_dizzy_eyes_open": "D",
    "ssq_dizzy_eyes_closed": "D",
    "ssq_vertigo": "D",
    "ssq_stomach_awareness": "N",
    "ssq_burping": "N",
}
SSQ_ITEMS: tuple[str, ...] = tuple(SSQ_MEMBERSHIP)
_SSQ_WEIGHTS = {"N": 9.54, "O": 7.58, "D": 13.92}
_SSQ_TOTAL_WEIGHT = 3.74
_SSQ_SUBSCORE_COLUMNS = ("ssq_n", "ssq_o", "ssq_d")
# Largest possible value of each precomputed subscore (every item rated 3).
_SSQ_MAX = {
    "ssq_n": 21 * 9.54,
    "ssq_o": 21 * 7.58,
    "ssq_d": 21 * 13.92,
    "ssq_total": 63 * 3.74,
}

# Golding (2006), in the questionnaire's order.
MSSQ_TYPES: tuple[str, ...] = (
    "cars",
    "buses",
    "trains",
    "aircraft",
    "small_boats",
    "ships",
    "swings",
    "roundabouts",
    "funfair",
)
_MSSQ_CHILD = tuple(f"mssq_child_{t}" for t in MSSQ_TYPES)
_MSSQ_ADULT = tuple(f"mssq_adult_{t}" for t in MSSQ_TYPES)
_MSSQ_MAX = 54.0

# Measures of the paper's table, in its order: (column in scores.csv, label, SSQ field).
_OF_MEASURES: tuple[tuple[str, str, str], ...] = (
    ("n_of", "N_OF", "nausea"),
    ("o_of", "O_OF", "oculomotor"),
    ("d_of", "D_OF", "disorientation"),
    ("k_of", "K_OF", "total"),
)
_MIN_PER_GROUP = 3


# --------------------------------------------------------------------------- scoring


@dataclass(frozen=True)
class SSQScores:
    """Weighted SSQ scores of one participant (Kennedy et al. 1993).

    Attributes
    ----------
    nausea, oculomotor, disorientation, total : float
        N = 9.54 N_raw, O = 7.58 O_raw, D = 13.92 D_raw, Total = 3.74 (N_raw+O_raw+D_raw).
    """

    nausea: float
    oculomotor: float
    disorientation: float
    total: float

    def __post_init__(self) -> None:
        for name in ("nausea", "oculomotor", "disorientation", "total"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0.0):
                raise InputError(f"SSQ {name} score must be a finite number >= 0; got {v!r}")


@dataclass(frozen=True)
class MSSQScore:
    """MSSQ-short score of one participant (Golding 2006).

    Attributes
    ----------
    total : float
        Child + adult section scores, 0 .. 54.
    child, adult : float or None
        Section scores, each 0 .. 27; None where only a precomputed total was given.
    """

    total: float
    child: float | None = None
    adult: float | None = None

    def __post_init__(self) -> None:
        if not (math.isfinite(self.total) and 0.0 <= self.total <= _MSSQ_MAX + 1e-9):
            raise InputError(f"MSSQ-short score must be in 0..54; got {self.total!r}")


def _check_rating(name: str, v: object) -> int:
    if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)):
        raise InputError(f"{name} must be an integer rating 0..3; got {v!r}")
    if not (float(v) in (0.0, 1.0, 2.0, 3.0)):
        raise InputError(f"{name} must be an integer rating 0..3; got {v!r}")
    return int(v)


def ssq_scores(ratings: Mapping[str, int] | Sequence[int]) -> SSQScores:
    """Score the 16 SSQ items.

    Parameters
    ----------
    ratings : mapping item name -> int, or sequence of 16 ints
        Ratings 0 (none) .. 3 (severe), keyed by the names of :data:`SSQ_ITEMS` or in
        that order.

    Returns
    -------
    SSQScores
        Weighted nausea, oculomotor, disorientation and total scores.
    """
    if isinstance(ratings, Mapping):
        missing = [k for k in SSQ_ITEMS if k not in ratings]
        if missing:
            raise InputError(f"SSQ ratings: items missing: {', '.join(missing)}")
        values = [ratings[k] for k in SSQ_ITEMS]
    else:
        values = list(ratings)
        if len(values) != len(SSQ_ITEMS):
            raise InputError(f"SSQ ratings: expected 16 values; got {len(values)}")
    raw = {"N": 0, "O": 0, "D": 0}
    for name, v in zip(SSQ_ITEMS, values):
        r = _check_rating(name, v)
        for scale in SSQ_MEMBERSHIP[name]:
            raw[scale] += r
    return SSQScores(
        nausea=raw["N"] * _SSQ_WEIGHTS["N"],
        oculomotor=raw["O"] * _SSQ_WEIGHTS["O"],
        disorientation=raw["D"] * _SSQ_WEIGHTS["D"],
        total=(raw["N"] + raw["O"] + raw["D"]) * _SSQ_TOTAL_WEIGHT,
    )


def mssq_section_score(answers: Sequence[int | None]) -> float:
    """Score one MSSQ-short section (child or adult) of 9 answers.

    Parameters
    ----------
    answers : sequence of 9 (int 0..3 or None)
        One answer per motion type of :data:`MSSQ_TYPES`; None = ``t`` (never travelled).

    Returns
    -------
    float
        (sum of the answers) x 9 / (9 - number of None), 0 .. 27.

    Raises
    ------
    InputError
        A value outside 0..3, not 9 answers, or every answer None (the section cannot be
        scored: 0/0).
    """
    if len(answers) != len(MSSQ_TYPES):
        raise InputError(f"MSSQ-short section: expected 9 answers; got {len(answers)}")
    given = [
        _check_rating(f"MSSQ answer {i + 1}", a) for i, a in enumerate(answers) if a is not None
    ]
    if not given:
        raise InputError(
            "MSSQ-short section: every answer is 't' (never experienced); cannot score"
        )
    return sum(given) * 9.0 / len(given)


def mssq_short_score(child: Sequence[int | None], adult: Sequence[int | None]) -> MSSQScore:
    """MSSQ-short score = child section score + adult section score (Golding 2006)."""
    c = mssq_section_score(child)
    a = mssq_section_score(adult)
    return MSSQScore(total=c + a, child=c, adult=a)


def k_of(
    scores: NDArray[np.float64],
    ms: NDArray[np.float64],
    flow: NDArray[np.float64],
    groups: Sequence[str],
) -> NDArray[np.float64]:
    """The paper's flow- and susceptibility-normalised score.

    K_OF,i = K_i x MS_i / (Flow_i x sum_{j in group(i)} MS_j) x 1000.

    Parameters
    ----------
    scores : ndarray, shape (n,), float
        SSQ score (total or a subscore) per participant.
    ms : ndarray, shape (n,), float
        MSSQ-short score per participant.
    flow : ndarray, shape (n,), float
        Session optical flow per participant, > 0 (any unit; the result scales with 1/unit).
    groups : sequence of str, length n
        Condition label per participant; the MS sum runs over each label.

    Returns
    -------
    ndarray, shape (n,), float64
        NaN for participants whose group's MS sum is 0 (0/0).
    """
    s = np.asarray(scores, dtype=np.float64)
    m = np.asarray(ms, dtype=np.float64)
    f = np.asarray(flow, dtype=np.float64)
    g = np.asarray(list(groups), dtype=object)
    if not (s.shape == m.shape == f.shape == g.shape) or s.ndim != 1:
        raise InputError(
            f"k_of: scores, ms, flow and groups must be 1-D of one length; got shapes "
            f"{s.shape}, {m.shape}, {f.shape}, {g.shape}"
        )
    if np.any(~np.isfinite(f) | (f <= 0)):
        raise InputError("k_of: every flow value must be finite and > 0")
    out = np.full(s.shape, np.nan)
    for label in dict.fromkeys(g.tolist()):
        sel = g == label
        total_ms = float(m[sel].sum())
        if total_ms > 0:
            out[sel] = s[sel] * m[sel] / (f[sel] * total_ms) * 1000.0
    return out


# --------------------------------------------------------------------------- reading


@dataclass(frozen=True)
class Participant:
    """One usable row of DATA.csv."""

    row: int  # 1-based data row (header not counted)
    line: int  # 1-based line of the file
    id: str
    condition: str
    ssq: SSQScores
    mssq: MSSQScore
    flow: float
    ssq_source: str  # "items" or "subscores"
    mssq_source: str  # "answers" or "score"
    flow_source: str  # "flow" or the EPOF CSV path


@dataclass(frozen=True)
class Study:
    """DATA.csv read and scored: the usable rows and one line per unusable row.

    Attributes
    ----------
    path : Path
    participants : tuple of Participant
    problems : tuple of str
        One line per row that could not be used (id, row and line number, what is wrong).
    conditions : tuple of str
        Condition labels of every row with one, in order of first appearance.
    flow_stat : str
    """

    path: Path
    participants: tuple[Participant, ...]
    problems: tuple[str, ...]
    conditions: tuple[str, ...]
    flow_stat: str = "mean"

    def __post_init__(self) -> None:
        if self.flow_stat not in FLOW_STATS:
            raise InputError(f"flow statistic must be one of {FLOW_STATS}; got {self.flow_stat!r}")


def _norm_col(name: str) -> str:
    return name.strip().lower().replace(" ", "_").replace("-", "_")


def _read_rows(path: Path) -> tuple[list[str], list[tuple[int, list[str]]]]:
    """Header and (line number, cells) of every data line; '#' lines and blanks skipped."""
    try:
        text = path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError:
        raise InputError(f"{path}: not UTF-8 text; expected a CSV file") from None
    lines = [
        (i + 1, ln)
        for i, ln in enumerate(text.splitlines())
        if ln.strip() and not ln.lstrip().startswith("#")
    ]
    if not lines:
        raise InputError(f"{path}: no header line; expected a CSV with columns id,condition,...")
    parsed = list(csv.reader([ln for _, ln in lines]))
    header = [_norm_col(c) for c in parsed[0]]
    if len(header) == 1 and ";" in lines[0][1]:
        raise InputError(f"{path}: header is separated by ';'; expected commas (CSV)")
    dup = sorted({c for c in header if header.count(c) > 1 and c})
    if dup:
        raise InputError(f"{path}: duplicate columns {dup}; expected each column once")
    rows = [(lines[k][0], parsed[k]) for k in range(1, len(lines))]
    return header, rows


def _missing_message(missing: Sequence[str], unknown: Sequence[str]) -> str:
    parts = []
    for m in missing:
        close = difflib.get_close_matches(m, unknown, n=1, cutoff=0.8)
        parts.append(f"{m} (found {close[0]!r}?)" if close else m)
    return ", ".join(parts)


def _check_columns(path: Path, header: Sequence[str]) -> dict[str, bool]:
    """Which alternatives the header offers; InputError naming every missing column."""
    cols = set(header)
    known = {"id", "condition", "flow", "epof_csv", "mssq", "ssq_total"}
    known |= set(SSQ_ITEMS) | set(_SSQ_SUBSCORE_COLUMNS) | set(_MSSQ_CHILD) | set(_MSSQ_ADULT)
    unknown = [c for c in header if c not in known]
    problems = []
    for c in ("id", "condition"):
        if c not in cols:
            problems.append(f"column '{c}' missing")
    have_items = any(c in cols for c in SSQ_ITEMS)
    have_sub = all(c in cols for c in _SSQ_SUBSCORE_COLUMNS)
    if have_items and not all(c in cols for c in SSQ_ITEMS) and not have_sub:
        miss = [c for c in SSQ_ITEMS if c not in cols]
        problems.append(f"SSQ item columns missing: {_missing_message(miss, unknown)}")
    elif not have_items and not have_sub:
        miss = [c for c in _SSQ_SUBSCORE_COLUMNS if c not in cols]
        problems.append(
            "no SSQ columns: expected the 16 items (ssq_general_discomfort .. ssq_burping) "
            f"or the subscores ssq_n, ssq_o, ssq_d (missing: {_missing_message(miss, unknown)})"
        )
    mssq_cols = _MSSQ_CHILD + _MSSQ_ADULT
    have_answers = any(c in cols for c in mssq_cols)
    if have_answers and not all(c in cols for c in mssq_cols) and "mssq" not in cols:
        miss = [c for c in mssq_cols if c not in cols]
        problems.append(f"MSSQ-short answer columns missing: {_missing_message(miss, unknown)}")
    elif not have_answers and "mssq" not in cols:
        problems.append(
            "no MSSQ-short columns: expected 'mssq' or the 18 answers mssq_child_cars .. "
            "mssq_adult_funfair"
        )
    if "flow" not in cols and "epof_csv" not in cols:
        problems.append("no flow column: expected 'flow' (a number) or 'epof_csv' (a path)")
    if problems:
        raise InputError(f"{path}: {'; '.join(problems)}; found {list(header)}")
    return {
        "items": all(c in cols for c in SSQ_ITEMS),
        "subscores": have_sub,
        "answers": all(c in cols for c in mssq_cols),
    }


def _number(name: str, text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise InputError(f"{name} = {text!r} is not a number") from None
    if not math.isfinite(v):
        raise InputError(f"{name} = {text!r} is not a finite number")
    return v


def _rating(name: str, text: str, *, allow_t: bool = False) -> int | None:
    if allow_t and text.lower() == "t":
        return None
    expected = "0..3 or 't'" if allow_t else "0..3"
    try:
        v = float(text)
    except ValueError:
        raise InputError(f"{name} = {text!r} is not a rating {expected}") from None
    if v not in (0.0, 1.0, 2.0, 3.0):
        raise InputError(f"{name} = {text} outside {expected}")
    return int(v)


def session_flow(path: str | Path, stat: str = "mean") -> float:
    """Session flow of an EPOF CSV (``vimsim epof``): mean, median or sum of ``epof_dps``."""
    if stat not in FLOW_STATS:
        raise InputError(f"flow statistic must be one of {FLOW_STATS}; got {stat!r}")
    p = check_input_file(path, "EPOF CSV")
    with open(p, newline="", encoding="utf-8-sig") as fh:
        reader = csv.reader(fh)
        header = [_norm_col(c) for c in next(reader, [])]
        if "epof_dps" not in header:
            raise InputError(f"EPOF CSV {p}: column 'epof_dps' missing; found {header}")
        k = header.index("epof_dps")
        vals = []
        for n, cells in enumerate(reader, start=2):
            if not cells:
                continue
            try:
                v = float(cells[k])
            except (ValueError, IndexError):
                raise InputError(f"EPOF CSV {p}: line {n}: epof_dps is not a number") from None
            if not math.isfinite(v):
                raise InputError(f"EPOF CSV {p}: line {n}: epof_dps = {v} is not finite")
            vals.append(v)
    if not vals:
        raise InputError(f"EPOF CSV {p}: no data rows")
    a = np.asarray(vals)
    return float({"mean": np.mean, "median": np.median, "sum": np.sum}[stat](a))


def read_study(path: str | Path, *, flow_stat: str = "mean") -> Study:
    """Read and score DATA.csv (one row per participant; see docs/analyze.md).

    Lines starting with ``#`` are comments. Column names are case-insensitive. Per row,
    SSQ item ratings take precedence over subscores, MSSQ answers over ``mssq``, and
    ``flow`` over ``epof_csv`` (a path relative to DATA.csv's folder); a blank cell falls
    back to the alternative where the file has it.

    Raises
    ------
    InputError
        The file cannot be read or lacks required columns (message names them). Rows with
        missing or out-of-range answers do not raise: they are listed in
        :attr:`Study.problems`, one line each.
    """
    if flow_stat not in FLOW_STATS:
        raise InputError(f"flow statistic must be one of {FLOW_STATS}; got {flow_stat!r}")
    p = check_input_file(path, "study data")
    header, rows = _read_rows(p)
    has = _check_columns(p, header)
    idx = {c: i for i, c in enumerate(header)}
    participants: list[Participant] = []
    problems: list[str] = []
    conditions: dict[str, None] = {}
    seen: dict[str, int] = {}
    flow_cache: dict[Path, float] = {}

    for r, (line, cells) in enumerate(rows, start=1):

        def cell(name: str, cells: list[str] = cells) -> str:
            i = idx.get(name)
            return cells[i].strip() if i is not None and i < len(cells) else ""

        pid = cell("id")
        cond = cell("condition")
        if cond:
            conditions.setdefault(cond, None)
        errs: list[str] = []
        if len(cells) > len(header):
            errs.append(f"{len(cells)} cells but the header has {len(header)} columns")
        if not pid:
            errs.append("id is blank")
        elif pid in seen:
            errs.append(f"id repeats row {seen[pid]}")
        else:
            seen[pid] = r
        if not cond:
            errs.append("condition is blank")

        ssq = ssq_src = None
        try:
            item_cells = [cell(c) for c in SSQ_ITEMS] if has["items"] else []
            sub_cells = [cell(c) for c in _SSQ_SUBSCORE_COLUMNS] if has["subscores"] else []
            if has["items"] and (all(item_cells) or not (sub_cells and all(sub_cells))):
                blank = [c for c, t in zip(SSQ_ITEMS, item_cells) if not t]
                if blank:
                    raise InputError(f"SSQ answers missing: {', '.join(blank)}")
                ssq = ssq_scores([_rating(c, t) for c, t in zip(SSQ_ITEMS, item_cells)])
                ssq_src = "items"
            else:
                blank = [c for c, t in zip(_SSQ_SUBSCORE_COLUMNS, sub_cells) if not t]
                if blank:
                    raise InputError(f"SSQ subscores missing: {', '.join(blank)}")
                vals = {c: _number(c, t) for c, t in zip(_SSQ_SUBSCORE_COLUMNS, sub_cells)}
                tot = cell("ssq_total")
                if tot:
                    vals["ssq_total"] = _number("ssq_total", tot)
                else:  # Total = 3.74 x (N_raw + O_raw + D_raw)
                    vals["ssq_total"] = _SSQ_TOTAL_WEIGHT * (
                        vals["ssq_n"] / 9.54 + vals["ssq_o"] / 7.58 + vals["ssq_d"] / 13.92
                    )
                for c, v in vals.items():
                    if not (0.0 <= v <= _SSQ_MAX[c] + 1e-6):
                        raise InputError(f"{c} = {v:g} outside 0..{_SSQ_MAX[c]:.2f}")
                ssq = SSQScores(vals["ssq_n"], vals["ssq_o"], vals["ssq_d"], vals["ssq_total"])
                ssq_src = "subscores"
        except InputError as e:
            errs.append(str(e))

        ms = ms_src = None
        try:
            ans = [cell(c) for c in _MSSQ_CHILD + _MSSQ_ADULT] if has["answers"] else []
            if ans and (all(ans) or not cell("mssq")):
                blank = [c for c, t in zip(_MSSQ_CHILD + _MSSQ_ADULT, ans) if not t]
                if blank:
                    raise InputError(f"MSSQ-short answers missing: {', '.join(blank)}")
                vals_ = [
                    _rating(c, t, allow_t=True) for c, t in zip(_MSSQ_CHILD + _MSSQ_ADULT, ans)
                ]
                for label, part in (("child", vals_[:9]), ("adult", vals_[9:])):
                    if all(v is None for v in part):
                        raise InputError(
                            f"MSSQ-short {label} section: every answer is 't' (never "
                            "experienced); the section cannot be scored"
                        )
                ms = mssq_short_score(vals_[:9], vals_[9:])
                ms_src = "answers"
            else:
                t = cell("mssq")
                if not t:
                    raise InputError("mssq is blank")
                v = _number("mssq", t)
                if not 0.0 <= v <= _MSSQ_MAX:
                    raise InputError(f"mssq = {v:g} outside 0..54")
                ms = MSSQScore(total=v)
                ms_src = "score"
        except InputError as e:
            errs.append(str(e))

        flow = flow_src = None
        try:
            ft, et = cell("flow"), cell("epof_csv")
            if ft:
                flow = _number("flow", ft)
                if flow < 0:
                    raise InputError(f"flow = {ft} is negative")
                flow_src = "flow"
            elif et:
                ep = Path(et)
                if not ep.is_absolute():
                    ep = p.parent / ep
                if ep not in flow_cache:
                    flow_cache[ep] = session_flow(ep, flow_stat)
                flow = flow_cache[ep]
                flow_src = et
            else:
                raise InputError(
                    "flow is blank" + (" and epof_csv is blank" if "epof_csv" in idx else "")
                )
        except InputError as e:
            errs.append(str(e))

        if errs:
            who = f"id {pid!r}" if pid else "no id"
            problems.append(f"{p}: row {r} (line {line}, {who}): {'; '.join(errs)}")
            continue
        assert ssq is not None and ms is not None and flow is not None
        participants.append(
            Participant(
                row=r,
                line=line,
                id=pid,
                condition=cond,
                ssq=ssq,
                mssq=ms,
                flow=float(flow),
                ssq_source=str(ssq_src),
                mssq_source=str(ms_src),
                flow_source=str(flow_src),
            )
        )
    if not rows:
        raise InputError(f"{p}: no data rows after the header; expected one row per participant")
    return Study(p, tuple(participants), tuple(problems), tuple(conditions), flow_stat)


# --------------------------------------------------------------------------- analysis


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


def analyze_study(
    study: Study,
    *,
    exclude_below: float | None = None,
    conditions: Sequence[str] | None = None,
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

    Raises
    ------
    InputError
        Not exactly two conditions, or no usable participant (nothing can be computed).
    """
    from scipy import stats

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
    if not study.participants:
        raise InputError(f"{path}: no usable participant row (every row has a problem)")

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

    notes: list[str] = []
    groups = [q.condition for q in included]
    ms = np.array([q.mssq.total for q in included], dtype=np.float64)
    flow = np.array([q.flow for q in included], dtype=np.float64)
    of_scores: dict[str, NDArray[np.float64]] = {}
    for col, _label, attr in _OF_MEASURES:
        s = np.array([getattr(q.ssq, attr) for q in included], dtype=np.float64)
        of_scores[col] = k_of(s, ms, flow, groups) if included else s
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
        a = vals[g_arr == conds[0]]
        b = vals[g_arr == conds[1]]
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
        comparisons.append(row)
    n_a = sum(g == conds[0] for g in groups)
    n_b = sum(g == conds[1] for g in groups)
    if n_a < _MIN_PER_GROUP or n_b < _MIN_PER_GROUP:
        notes.append(
            f"tests not possible: {n_a} participant(s) in {conds[0]!r} and {n_b} in {conds[1]!r} "
            f"after exclusion; Mann-Whitney U and per-condition Shapiro-Wilk need >= "
            f"{_MIN_PER_GROUP} per group (scores are still written)"
        )
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
    )


# --------------------------------------------------------------------------- writing


def _fmt(v: object, digits: int = 10) -> str:
    if v is None:
        return ""
    if isinstance(v, float):
        return "" if math.isnan(v) else f"{v:.{digits}g}"
    return str(v)


def _write_csv(path: Path, header: Sequence[str], rows: Sequence[Sequence[object]]) -> None:
    with atomic_output(path) as tmp, open(tmp, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(header)
        for r in rows:
            w.writerow([_fmt(v) for v in r])


def _p_text(p: float) -> str:
    return "n/a" if math.isnan(p) else f"{p:.3f}"


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
        out.append(f"| {a} vs. {b} | {ma} vs. {mb} | {_p_text(row['p'])} |")
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
    axes[0].set_ylabel("score x MS / (flow x group MS) x 1000")
    fig.tight_layout()
    with atomic_output(path) as tmp:
        fig.savefig(tmp, dpi=100)
    plt.close(fig)


def write_report(an: Analysis, out_dir: str | Path) -> list[Path]:
    """Write the analysis into ``out_dir`` (created if needed), each file atomically.

    Files: ``scores.csv`` (one row per participant, excluded ones too, with the reason),
    ``table.csv`` and ``table.md`` (the paper's table: means per condition and Mann-Whitney
    p per subscore), ``normality.csv`` (Shapiro-Wilk per measure, pooled and per
    condition), ``boxplots.png``, ``report.md`` (all of it plus exclusions, row problems
    and notes). Returns the paths written.
    """
    out = check_output_dir(out_dir)
    written: list[Path] = []

    reasons = dict(an.excluded)
    of_by_id = {
        q.id: {col: float(an.of_scores[col][i]) for col, _l, _a in _OF_MEASURES}
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
        of = of_by_id.get(q.id, {})
        rows.append(
            [
                q.id, q.condition, q.row, "yes" if q.id in of_by_id else "no",
                reasons.get(q.id, ""), q.flow, q.flow_source,
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
            f"| {r['measure']} | {r['group']} | {r['n']} | {w} | {_p_text(r['p'])} | {r['note']} |"
        )
    lines += ["", "## Excluded", ""]
    lines += [f"- {pid}: {why}" for pid, why in an.excluded] or ["- none"]
    lines += ["", "## Rows with problems (not used)", ""]
    lines += [f"- {s}" for s in an.study.problems] or ["- none"]
    lines += ["", "## Notes", ""]
    lines += [f"- {s}" for s in an.messages()] or ["- none"]
    with atomic_output(out / "report.md") as tmp:
        tmp.write_text("\n".join(lines) + "\n", encoding="utf-8")
    written.append(out / "report.md")
    return written
