"""The study's design (between, within, mixed), detected or forced, and its tidy table of sessions.

One row of DATA.csv is one participant's session: an id in more than one row makes the design
repeated. ``within``: each participant in both conditions, one row each; ``mixed``: several
videos or sessions per participant (and condition). The tests compare participants (the mean
of their rows per condition), so a participant who misses a condition in a repeated design
is dropped from the paired test (counted and named), and fewer than :data:`MIN_PAIRS` complete
pairs are refused: with 5 pairs the smallest two-sided Wilcoxon p is 0.0625.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import pandas as pd

from simulator.analyze.data import Participant, Study
from simulator.core.errors import InputError
from simulator.core.statsopts import DESIGNS

__all__ = ["MEASURES", "MIN_PAIRS", "Design", "design_table"]

#: SSQ measures of the tests: (column of the table, SSQScores field); total first.
MEASURES: tuple[tuple[str, str], ...] = (
    ("ssq_total", "total"),
    ("ssq_n", "nausea"),
    ("ssq_o", "oculomotor"),
    ("ssq_d", "disorientation"),
)

#: Fewer complete pairs than this are refused (exact two-sided Wilcoxon p >= 0.0625 at 5).
MIN_PAIRS = 6


@dataclass(frozen=True)
class Design:
    """The design of the analysed table and what was dropped to fit it.

    Attributes
    ----------
    name : ``"between"``, ``"within"`` or ``"mixed"``
    detected : bool
        True when detected from the data, False when forced with ``--design``.
    paired : bool
        Condition varies within participants: the paired test (Wilcoxon signed-rank).
    table : DataFrame
        One row per session: participant, condition (categorical, reference first), video,
        session, flow, mssq and the measures of :data:`MEASURES` (change scores when the
        file gives pre-exposure SSQ).
    change : bool
        Measures are post - pre changes.
    dropped : tuple of str
        Participants left out of the paired test (a condition missing), one line each.
    why : str
        One sentence: why this design.
    source : str
        The data's path (messages name it).
    """

    name: str
    detected: bool
    paired: bool
    table: pd.DataFrame = field(repr=False)
    change: bool = False
    dropped: tuple[str, ...] = ()
    why: str = ""
    source: str = ""  # DATA.csv's path, for messages

    @property
    def videos(self) -> tuple[str, ...]:
        return tuple(v for v in dict.fromkeys(self.table["video"]) if v)


def _table(included: Sequence[Participant], conds: tuple[str, str]) -> tuple[pd.DataFrame, bool]:
    change = bool(included) and all(q.pre is not None for q in included)
    rows = []
    for q in included:
        rec = {
            "participant": q.id,
            "condition": q.condition,
            "video": q.video,
            "session": q.session,
            "flow": q.flow,
            "mssq": q.mssq.total,
            "row": q.row,
        }
        for col, attr in MEASURES:
            v = getattr(q.ssq, attr)
            rec[col] = v - getattr(q.pre, attr) if change and q.pre is not None else v
        rows.append(rec)
    cols = ["participant", "condition", "video", "session", "flow", "mssq", "row"]
    df = pd.DataFrame(rows, columns=cols + [c for c, _ in MEASURES])
    df["condition"] = pd.Categorical(df["condition"], categories=list(conds))
    return df, change


def _detect(df: pd.DataFrame) -> tuple[str, str]:
    """(design, why) from the table: repeated ids, videos and sessions per participant."""
    per_id = df.groupby("participant", sort=False).size()
    if int(per_id.max()) == 1:
        return "between", "each participant has one row"
    n_vid = df.groupby("participant", sort=False)["video"].nunique()
    per_cell = df.groupby(["participant", "condition"], sort=False, observed=True).size()
    if int(n_vid.max()) > 1 or int(per_cell.max()) > 1:
        return "mixed", "participants have several videos or sessions"
    return "within", "participants have one row in each condition"


def _check_forced(study: Study, df: pd.DataFrame, forced: str, found: str) -> None:
    """InputError when the data cannot have the forced design (names the participant or
    column and the fix)."""
    path = study.path
    per_id = df.groupby("participant", sort=False)["row"].apply(list)
    rep = per_id[per_id.map(len) > 1]
    if forced == "mixed" and not {"video", "session"} & set(study.columns):
        raise InputError(
            f"{path}: --design mixed needs column 'video' or 'session' (which "
            f"video or session each row is); found {list(study.columns)}"
        )
    if forced == "between" and len(rep):
        pid, rows = rep.index[0], rep.iloc[0]
        raise InputError(
            f"{path}: --design between but participant {pid!r} has {len(rows)} "
            f"rows (rows {', '.join(map(str, rows))}); a between design has one "
            f"row per participant: use --design {found}"
        )
    if forced in ("within", "mixed") and not len(rep):
        raise InputError(
            f"{path}: --design {forced} but every participant id has one row; "
            "a repeated design has each participant in several rows (same id): "
            "use --design between"
        )
    if forced == "within" and found == "mixed":
        raise InputError(
            f"{path}: --design within but participants have several rows per "
            "condition (videos or sessions): use --design mixed"
        )


def _pairs(df: pd.DataFrame, conds: tuple[str, str], path: object) -> tuple[pd.DataFrame, list]:
    """The table without participants who miss a condition; InputError below MIN_PAIRS."""
    have = df.groupby("participant", sort=False)["condition"].agg(lambda s: set(s.astype(str)))
    complete = have.map(lambda s: set(conds) <= s)
    full = set(have.index[complete])
    dropped = [
        f"participant {pid!r}: no row in condition {next(c for c in conds if c not in have[pid])!r}"
        for pid in have.index[~complete]
    ]
    if len(full) < MIN_PAIRS:
        raise InputError(
            f"{path}: {len(full)} participant(s) have rows in both {conds[0]!r} and "
            f"{conds[1]!r} ({len(dropped)} miss one); the paired test needs >= "
            f"{MIN_PAIRS} complete pairs: add participants or use --design between "
            "if each participant saw one condition"
        )
    return df[df["participant"].isin(full)].reset_index(drop=True), dropped


def design_table(
    study: Study, included: Sequence[Participant], conds: tuple[str, str], design: str = "auto"
) -> Design:
    """The design of the included rows (detected, or ``design`` checked against the data).

    Raises
    ------
    InputError
        A forced design the data cannot have, a condition with fewer than 2 participants,
        or fewer than :data:`MIN_PAIRS` complete pairs in a paired design (message names
        the file, the participant or column, and the fix).
    """
    if design not in DESIGNS:
        raise InputError(f"--design: {design!r}; expected one of {', '.join(DESIGNS)}")
    df, change = _table(included, conds)
    if df.empty:
        raise InputError(f"{study.path}: no included row; nothing to test")
    found, why = _detect(df)
    if design != "auto":
        _check_forced(study, df, design, found)
        why = f"forced with --design {design} ({why})"
    name = found if design == "auto" else design
    both = df.groupby("participant", sort=False)["condition"].nunique()
    paired = name != "between" and int(both.max()) == 2
    dropped: list[str] = []
    if paired:
        df, dropped = _pairs(df, conds, study.path)
    else:
        for c in conds:
            ids = df.loc[df["condition"] == c, "participant"].unique()
            if len(ids) < 2:
                who = f" ({ids[0]!r})" if len(ids) else ""
                raise InputError(
                    f"{study.path}: condition {c!r} has {len(ids)} participant(s)"
                    f"{who} after exclusion; comparing conditions needs >= 2 each "
                    "(3 for the tests): add participants or pick conditions with "
                    "--conditions"
                )
    return Design(name, design == "auto", paired, df, change, tuple(dropped), why, str(study.path))
