"""Reading study data (DATA.csv): one participant session a row, bad rows collected as one line each."""

from __future__ import annotations

import difflib
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from simulator.analyze.scores import (
    _MSSQ_ADULT,
    _MSSQ_CHILD,
    _MSSQ_MAX,
    _SSQ_MAX,
    _SSQ_SUBSCORE_COLUMNS,
    _SSQ_TOTAL_WEIGHT,
    SSQ_ITEMS,
    MSSQScore,
    SSQScores,
    mssq_short_score,
    ssq_scores,
)
from simulator.core.choices import FLOW_STATS
from simulator.core.errors import InputError
from simulator.core.fileio import check_input_file, csv_row

__all__ = ["FLOW_STATS", "Study", "read_study", "session_flow"]


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
    video: str = ""  # the ``video`` cell (several videos per participant: a mixed design)
    session: str = ""  # the ``session`` cell
    pre: SSQScores | None = None  # SSQ before exposure (``pre_`` columns): change scores


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
    columns : tuple of str
        The header's column names (normalised), for the checks of a design.
    """

    path: Path
    participants: tuple[Participant, ...]
    problems: tuple[str, ...]
    conditions: tuple[str, ...]
    flow_stat: str = "mean"
    columns: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if self.flow_stat not in FLOW_STATS:
            raise InputError(f"flow statistic must be one of {FLOW_STATS}; got {self.flow_stat!r}")


#: Prefix of the pre-exposure SSQ columns (``pre_ssq_nausea`` .. or ``pre_ssq_n`` ..).
_PRE = "pre_"


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
    # one record per line: an unbalanced quote never swallows the lines after it
    parsed = [csv_row(ln, f"{path}: line {n}") for n, ln in lines]
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
    known = {"id", "condition", "flow", "epof_csv", "mssq", "ssq_total", "video", "session"}
    known |= set(SSQ_ITEMS) | set(_SSQ_SUBSCORE_COLUMNS) | set(_MSSQ_CHILD) | set(_MSSQ_ADULT)
    known |= {_PRE + c for c in (*SSQ_ITEMS, *_SSQ_SUBSCORE_COLUMNS, "ssq_total")}
    unknown = [c for c in header if c not in known]
    problems = []
    for c in ("id", "condition"):
        if c not in cols:
            problems.append(f"column '{c}' missing")
    have_items = any(c in cols for c in SSQ_ITEMS)
    have_sub = all(c in cols for c in _SSQ_SUBSCORE_COLUMNS)
    # a partial item set is a file-level error even where subscores are given too: a
    # missing or misspelt item column would otherwise drop every row that gives items
    if have_items and not all(c in cols for c in SSQ_ITEMS):
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
    if have_answers and not all(c in cols for c in mssq_cols):
        miss = [c for c in mssq_cols if c not in cols]
        problems.append(f"MSSQ-short answer columns missing: {_missing_message(miss, unknown)}")
    elif not have_answers and "mssq" not in cols:
        problems.append(
            "no MSSQ-short columns: expected 'mssq' or the 18 answers mssq_child_cars .. "
            "mssq_adult_funfair"
        )
    if "flow" not in cols and "epof_csv" not in cols:
        problems.append("no flow column: expected 'flow' (a number) or 'epof_csv' (a path)")
    pre_items = [c for c in SSQ_ITEMS if _PRE + c in cols]
    pre_sub = all(_PRE + c in cols for c in _SSQ_SUBSCORE_COLUMNS)
    if pre_items and len(pre_items) < len(SSQ_ITEMS):
        miss = [_PRE + c for c in SSQ_ITEMS if _PRE + c not in cols]
        problems.append(f"pre-exposure SSQ item columns missing: {_missing_message(miss, unknown)}")
    elif not pre_items and not pre_sub and any(c.startswith(_PRE + "ssq") for c in cols):
        miss = [_PRE + c for c in _SSQ_SUBSCORE_COLUMNS if _PRE + c not in cols]
        problems.append(f"pre-exposure SSQ subscore columns missing: {', '.join(miss)}")
    if problems:
        raise InputError(f"{path}: {'; '.join(problems)}; found {list(header)}")
    return {
        "items": all(c in cols for c in SSQ_ITEMS),
        "subscores": have_sub,
        "answers": all(c in cols for c in mssq_cols),
        "pre_items": len(pre_items) == len(SSQ_ITEMS),
        "pre_subscores": pre_sub,
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
        # '#' lines (the settings vimsim writes above the header) are comments.
        rows = [
            (n, csv_row(ln, f"{p}: line {n}"))
            for n, ln in enumerate(fh, start=1)
            if ln.strip() and not ln.lstrip().startswith("#")
        ]
    header = [_norm_col(c) for c in rows[0][1]] if rows else []
    if "epof_dps" not in header:
        raise InputError(f"EPOF CSV {p}: column 'epof_dps' missing; found {header}")
    k = header.index("epof_dps")
    vals = []
    for n, cells in rows[1:]:
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


def _row_ssq(cell: Callable[[str], str], has: dict[str, bool]) -> tuple[SSQScores, str]:
    """A row's SSQ scores and their source (``items`` or ``subscores``); InputError names
    the problem."""
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
    return ssq, ssq_src


def _row_pre(cell: Callable[[str], str], has: dict[str, bool], errs: list[str]) -> SSQScores | None:
    """A row's pre-exposure SSQ (``pre_`` columns; None where the file has none); a problem
    is appended to ``errs``."""
    if not (has["pre_items"] or has["pre_subscores"]):
        return None
    try:
        pre_has = {"items": has["pre_items"], "subscores": has["pre_subscores"]}
        return _row_ssq(lambda c: cell(_PRE + c), pre_has)[0]
    except InputError as e:
        errs.append(f"pre-exposure {e}")
        return None


def _row_mssq(cell: Callable[[str], str], has: dict[str, bool]) -> tuple[MSSQScore, str]:
    """A row's MSSQ-short score and its source (``answers`` or ``score``); InputError names
    the problem."""
    ans = [cell(c) for c in _MSSQ_CHILD + _MSSQ_ADULT] if has["answers"] else []
    if ans and (all(ans) or not cell("mssq")):
        blank = [c for c, t in zip(_MSSQ_CHILD + _MSSQ_ADULT, ans) if not t]
        if blank:
            raise InputError(f"MSSQ-short answers missing: {', '.join(blank)}")
        vals_ = [_rating(c, t, allow_t=True) for c, t in zip(_MSSQ_CHILD + _MSSQ_ADULT, ans)]
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
    return ms, ms_src


def _row_flow(
    cell: Callable[[str], str],
    has_epof: bool,
    folder: Path,
    flow_stat: str,
    flow_cache: dict[Path, float],
) -> tuple[float, str]:
    """A row's flow and its source (``flow`` or the EPOF CSV's cell; the CSV's statistic is
    read once per file through ``flow_cache``); InputError names the problem."""
    ft, et = cell("flow"), cell("epof_csv")
    if ft:
        flow = _number("flow", ft)
        if flow < 0:
            raise InputError(f"flow = {ft} is negative")
        flow_src = "flow"
    elif et:
        ep = Path(et)
        if not ep.is_absolute():
            ep = folder / ep
        if ep not in flow_cache:
            flow_cache[ep] = session_flow(ep, flow_stat)
        flow = flow_cache[ep]
        flow_src = et
    else:
        raise InputError("flow is blank" + (" and epof_csv is blank" if has_epof else ""))
    return flow, flow_src


def read_study(path: str | Path, *, flow_stat: str = "mean") -> Study:
    """Read and score DATA.csv (one row per participant, or per participant and session in a
    repeated design: the same id in several rows; see docs/analyze.md).

    Lines starting with ``#`` are comments. Optional ``video`` and ``session`` cells and the
    pre-exposure SSQ (``pre_`` columns) are carried on each :class:`Participant`. Column names are case-insensitive. Per row,
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
    seen: dict[tuple[str, str, str, str], int] = {}
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
        key = (pid, cond, cell("video"), cell("session"))
        if not pid:
            errs.append("id is blank")
        elif key in seen:
            errs.append(f"id repeats row {seen[key]} (same condition, video and session)")
        else:
            seen[key] = r
        if not cond:
            errs.append("condition is blank")

        ssq = ssq_src = None
        try:
            ssq, ssq_src = _row_ssq(cell, has)
        except InputError as e:
            errs.append(str(e))
        ms = ms_src = None
        try:
            ms, ms_src = _row_mssq(cell, has)
        except InputError as e:
            errs.append(str(e))
        pre = _row_pre(cell, has, errs)
        flow = flow_src = None
        try:
            flow, flow_src = _row_flow(cell, "epof_csv" in idx, p.parent, flow_stat, flow_cache)
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
                video=cell("video"),
                session=cell("session"),
                pre=pre,
            )
        )
    if not rows:
        raise InputError(f"{p}: no data rows after the header; expected one row per participant")
    return Study(
        p, tuple(participants), tuple(problems), tuple(conditions), flow_stat, tuple(header)
    )
