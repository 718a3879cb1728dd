"""Questionnaire scores: SSQ, MSSQ-short and the paper's flow-normalised K_OF.
The pilot study of the paper (section 4.4) scored the Simulator Sickness Questionnaire
(SSQ, Kennedy et al. 1993) and the Motion Sickness Susceptibility Questionnaire short form
(MSSQ-short, Golding 2006), divided each SSQ score by the participant's session optical
flow and weighted it by their susceptibility (eq. for K_OF), excluded sessions with
unrealistically low flow, ran Shapiro-Wilk, then a two-sided Mann-Whitney U test between
the two conditions (GR vs NR), and reported the means per condition and the p values.

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
condition that remain after exclusion. Its values scale with 1 / (group size): with 48
against 4 participants the larger group's scores are 12x smaller for the same answers.
The default (``formula="invariant"``) multiplies by n_g / n_mean (the group's size over
the mean group size), i.e. divides by the group's *mean* MS times n_mean: it equals the
paper's value exactly when the groups are equal, and duplicating every participant of a
group changes no ratio between two participants' scores. ``formula="paper"`` is the
paper's formula as printed.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from simulator.core.errors import InputError

#: The K_OF formulas :func:`k_of` computes (the first is the default).
K_OF_FORMULAS: tuple[str, ...] = ("invariant", "paper")

#: What the report says of each formula.
K_OF_TEXT: dict[str, str] = {
    "invariant": "K_OF,i = K_i x MS_i / (Flow_i x sum_{j in group(i)} MS_j) x 1000 x n_g / "
    "n_mean (the paper's formula scaled by the group's size over the mean group size: "
    "independent of group size, equal to the paper's with equal groups)",
    "paper": "K_OF,i = K_i x MS_i / (Flow_i x sum_{j in group(i)} MS_j) x 1000 (the paper's "
    "formula as printed: its values scale with 1 / group size)",
}

__all__ = [
    "K_OF_FORMULAS",
    "K_OF_TEXT",
    "MSSQ_TYPES",
    "SSQ_ITEMS",
    "SSQ_MEMBERSHIP",
    "MSSQScore",
    "SSQScores",
    "k_of",
    "mssq_section_score",
    "mssq_short_score",
    "ssq_scores",
]

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
    formula: str = "invariant",
) -> NDArray[np.float64]:
    """The flow- and susceptibility-normalised score (the module text gives both formulas).

    paper: K_OF,i = K_i x MS_i / (Flow_i x sum_{j in group(i)} MS_j) x 1000;
    invariant (default): the same x n_g / n_mean (n_g: size of i's group, n_mean: the mean
    size of the groups present), equal to the paper's when the groups are equal.

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
    formula : ``"invariant"`` (default) or ``"paper"``

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
    if formula not in K_OF_FORMULAS:
        raise InputError(f"k_of: formula {formula!r}; expected one of {', '.join(K_OF_FORMULAS)}")
    out = np.full(s.shape, np.nan)
    labels = list(dict.fromkeys(g.tolist()))
    n_mean = s.size / max(1, len(labels))
    for label in labels:
        sel = g == label
        total_ms = float(m[sel].sum())
        if total_ms > 0:
            out[sel] = s[sel] * m[sel] / (f[sel] * total_ms) * 1000.0
            if formula == "invariant":
                out[sel] *= int(sel.sum()) / n_mean  # exactly 1.0 with equal groups
    return out
