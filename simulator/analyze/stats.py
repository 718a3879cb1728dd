"""The design's statistics: rank tests with effect sizes and bootstrap intervals, the mixed model, power.

Tests (``tests.csv``) compare participants: the mean of each participant's rows per
condition. Paired designs use the Wilcoxon signed-rank test of B - A with the matched-pairs
rank-biserial correlation (Kerby 2014); between designs use the two-sided Mann-Whitney U with
the rank-biserial correlation (Wendt 1972). Both effects are signed so that positive means
higher scores in B (the second condition) than in A (the reference), and get a seeded BCa
bootstrap interval (``scipy.stats.bootstrap``; participants resampled, within each group
for between). Holm's
correction runs across the four SSQ measures (total, N, O, D). Shapiro-Wilk of the
differences (paired) or of each group (between) is kept beside them.

The model (``model.csv``) is ``ssq_total ~ condition + flow + mssq`` with a random intercept
per participant and, with several videos, a crossed random intercept per video (statsmodels
``MixedLM``, REML; crossed effects as variance components in one group, as statsmodels'
documentation does). With one row per participant it is the ordinary least squares model.

Power (``power.csv``) solves statsmodels' ``TTestPower`` (paired, d_z = mean difference / SD
of the differences) or ``TTestIndPower`` (between, Cohen's d with the pooled SD, participants
per group) for the participants needed.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, fields

import numpy as np
import pandas as pd
from numpy.typing import NDArray
from scipy import stats
from threadpoolctl import threadpool_limits

from simulator.analyze.design import MEASURES, Design
from simulator.core.errors import InputError
from simulator.core.statsopts import STATS_OPTIONS, check_stats_option

__all__ = [
    "MODEL_COLUMNS",
    "POWER_COLUMNS",
    "TEST_COLUMNS",
    "Statistics",
    "StatsOptions",
    "fit_model",
    "power_rows",
    "rank_tests",
    "study_statistics",
]

TEST_COLUMNS = (
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
)
MODEL_COLUMNS = ("term", "estimate", "std_error", "ci_low", "ci_high", "p")
POWER_COLUMNS = (
    "design",
    "test",
    "effect",
    "alpha",
    "power",
    "participants_needed",
    "observed_power",
)

_D = {o.name: o.default for o in STATS_OPTIONS}


@dataclass(frozen=True)
class StatsOptions:
    """The options of :data:`simulator.core.statsopts.STATS_OPTIONS` (defaults and checks
    from that table).

    Attributes
    ----------
    design : str
    transform : str
    power : float or None
        Target power; None: no power analysis.
    alpha : float
    effect : float or None
        Given standardised effect; None: the observed one.
    seed, n_boot : int
    """

    design: str = _D["design"]
    transform: str = _D["transform"]
    power: float | None = _D["power"]
    alpha: float = _D["alpha"]
    effect: float | None = _D["effect"]
    seed: int = _D["seed"]
    n_boot: int = _D["n_boot"]

    def __post_init__(self) -> None:
        for f in fields(self):
            object.__setattr__(self, f.name, check_stats_option(f.name, getattr(self, f.name)))


@dataclass(frozen=True)
class Statistics:
    """Everything of the design's statistics: tidy rows (dicts keyed by the columns).

    Attributes
    ----------
    design : Design
    options : StatsOptions
    tests, model, power : tuple of dict
        Rows of ``tests.csv``, ``model.csv``, ``power.csv`` (pooled over videos).
    by_video : dict video -> (tests rows, model rows)
        Per video, with several videos.
    model_info : dict
        formula, method, converged, warnings (the model's own words).
    notes : tuple of str
    """

    design: Design
    options: StatsOptions
    tests: tuple[dict, ...]
    model: tuple[dict, ...]
    power: tuple[dict, ...]
    by_video: dict
    model_info: dict
    notes: tuple[str, ...]


def participant_means(df: pd.DataFrame, col: str) -> pd.DataFrame:
    """Participant x condition means of ``col``: one row per participant (in id order), one
    column per condition (reference first; NaN where a participant has no row)."""
    m = df.groupby(["participant", "condition"], observed=True)[col].mean().unstack("condition")
    return m.reindex(columns=df["condition"].cat.categories)


def _rb_paired(d: NDArray[np.float64]) -> NDArray[np.float64]:
    """Matched-pairs rank-biserial r of each row of d (B - A): (T+ - T-) / (T+ + T-), zero
    differences dropped as scipy's default ``zero_method="wilcox"``."""
    a = np.abs(d)
    zeros = (a == 0).sum(axis=1, keepdims=True)
    # zeros take the lowest ranks, so the others' ranks among themselves are shifted by them
    r = stats.rankdata(a, axis=1) - zeros
    tp = np.where(d > 0, r, 0.0).sum(axis=1)
    tm = np.where(d < 0, r, 0.0).sum(axis=1)
    tot = tp + tm
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(tot > 0, (tp - tm) / tot, 0.0)


def _rb_between(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    """Rank-biserial r of each row pair (B vs A): 1 - 2 U_A / (n_A n_B), ties at half."""
    na, nb = a.shape[1], b.shape[1]
    ranks = stats.rankdata(np.concatenate([a, b], axis=1), axis=1)
    u_a = ranks[:, :na].sum(axis=1) - na * (na + 1) / 2.0
    return 1.0 - 2.0 * u_a / (na * nb)


def _last_axis(f):
    """A statistic of 2-D rows made a ``scipy.stats.bootstrap`` statistic (``axis=``)."""

    def stat(*samples, axis=-1):
        xs = [np.moveaxis(np.asarray(x, dtype=np.float64), axis, -1) for x in samples]
        lead = np.broadcast_shapes(*(x.shape[:-1] for x in xs))
        xs = [np.broadcast_to(x, lead + x.shape[-1:]) for x in xs]
        rows = f(*(x.reshape(-1, x.shape[-1]) for x in xs))
        return rows.reshape(lead)

    return stat


def _interval(samples: tuple, f, opts: StatsOptions, rng) -> tuple[float, float]:
    """BCa bootstrap interval of ``f`` (scipy.stats.bootstrap, participants resampled,
    each sample on its own); the percentile interval of the same resamples where BCa is
    undefined (every resample equal, e.g. r = 1 throughout)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # a degenerate distribution: handled below
        res = stats.bootstrap(samples, _last_axis(f), vectorized=True, n_resamples=opts.n_boot,
                              confidence_level=1.0 - opts.alpha, method="BCa", random_state=rng)  # fmt: skip
    lo, hi = res.confidence_interval
    if not (math.isfinite(lo) and math.isfinite(hi)):
        a = opts.alpha
        lo, hi = np.quantile(res.bootstrap_distribution, [a / 2.0, 1.0 - a / 2.0])
    return float(lo), float(hi)


def _paired_row(col: str, d: NDArray[np.float64], opts: StatsOptions, rng) -> dict:
    row = {
        "measure": col,
        "test": "Wilcoxon signed-rank",
        "statistic": math.nan,
        "p": math.nan,
        "p_holm": math.nan,
        "effect": math.nan,
        "effect_name": "matched-pairs rank-biserial r (B - A)",
        "effect_ci_low": math.nan,
        "effect_ci_high": math.nan,
        "n": int(d.size),
    }
    if np.any(d != 0):
        res = stats.wilcoxon(d)
        row["statistic"], row["p"] = float(res.statistic), float(res.pvalue)
    row["effect"] = float(_rb_paired(d[None, :])[0])
    row["effect_ci_low"], row["effect_ci_high"] = _interval((d,), _rb_paired, opts, rng)
    return row


def _between_row(col: str, a, b, opts: StatsOptions, rng) -> dict:
    res = stats.mannwhitneyu(a, b, alternative="two-sided")
    lo, hi = _interval((a, b), _rb_between, opts, rng)
    return {
        "measure": col,
        "test": "Mann-Whitney U",
        "statistic": float(res.statistic),
        "p": float(res.pvalue),
        "p_holm": math.nan,
        "effect": float(_rb_between(a[None, :], b[None, :])[0]),
        "effect_name": "rank-biserial r (B vs. A)",
        "effect_ci_low": lo,
        "effect_ci_high": hi,
        "n": int(a.size + b.size),
    }


def _shapiro_row(col: str, label: str, v: NDArray[np.float64]) -> dict:
    row = dict.fromkeys(TEST_COLUMNS, math.nan)
    row.update(measure=col, test=f"Shapiro-Wilk ({label})", effect_name="", n=int(v.size))
    if v.size >= 3 and np.ptp(v) > 0:
        res = stats.shapiro(v)
        row["statistic"], row["p"] = float(res.statistic), float(res.pvalue)
    return row


def rank_tests(design: Design, opts: StatsOptions, table: pd.DataFrame | None = None) -> list[dict]:
    """``tests.csv`` rows of ``table`` (default: the design's): per measure the design's
    rank test (Holm-corrected across the measures) and Shapiro-Wilk."""
    from statsmodels.stats.multitest import multipletests

    df = design.table if table is None else table
    a_lab, b_lab = (str(c) for c in df["condition"].cat.categories)
    rng = np.random.default_rng(opts.seed)
    main: list[dict] = []
    extra: list[dict] = []
    for col, _attr in MEASURES:
        wide = participant_means(df, col)
        if design.paired:
            wide = wide.dropna()
            d = (wide[b_lab] - wide[a_lab]).to_numpy(dtype=np.float64)
            main.append(_paired_row(col, d, opts, rng))
            extra.append(_shapiro_row(col, f"differences {b_lab} - {a_lab}", d))
        else:
            a = wide[a_lab].dropna().to_numpy(dtype=np.float64)
            b = wide[b_lab].dropna().to_numpy(dtype=np.float64)
            main.append(_between_row(col, a, b, opts, rng))
            extra += [_shapiro_row(col, a_lab, a), _shapiro_row(col, b_lab, b)]
    ok = [i for i, r in enumerate(main) if math.isfinite(r["p"])]
    if ok:
        adj = multipletests([main[i]["p"] for i in ok], method="holm")[1]
        for i, p in zip(ok, adj):
            main[i]["p_holm"] = float(p)
    return main + extra


def _formula(transform: str) -> str:
    y = "np.log1p(ssq_total)" if transform == "log1p" else "ssq_total"
    return f"{y} ~ condition + flow + mssq"


def fit_model(table: pd.DataFrame, transform: str, alpha: float, crossed_video: bool):
    """Fit the model of ``table``; returns ``(rows, info)``. A fit that fails or does not
    converge is reported in ``info`` (``converged``, ``warnings``, ``error``), never raised."""
    import statsmodels.formula.api as smf

    formula = _formula(transform)
    info: dict = {"formula": formula, "warnings": [], "error": None, "converged": None}
    repeated = bool(table["participant"].duplicated().any())
    # the model's matrices are small (rows x participants): BLAS threads only cost here, up to
    # 6x on a loaded 2-core machine (bench/analyze_coverage.py)
    with warnings.catch_warnings(record=True) as caught, threadpool_limits(1, user_api="blas"):
        warnings.simplefilter("always")
        try:
            if not repeated:
                info["method"] = "OLS (one row per participant)"
                res = smf.ols(formula, table).fit()
                info["converged"] = True
            elif crossed_video:
                info["method"] = (
                    "MixedLM REML: (1 | participant) + (1 | video), crossed "
                    "(variance components, one group)"
                )
                vc = {"participant": "0 + C(participant)", "video": "0 + C(video)"}
                t = table.assign(_all=1)
                res = smf.mixedlm(formula, t, groups="_all", re_formula="0", vc_formula=vc).fit(
                    reml=True
                )
            else:
                info["method"] = "MixedLM REML: (1 | participant)"
                res = smf.mixedlm(formula, table, groups="participant").fit(reml=True)
        except (ValueError, np.linalg.LinAlgError) as e:
            info["error"] = f"the model could not be fitted: {str(e).splitlines()[0]}"
            res = None
    info["warnings"] = list(dict.fromkeys(str(w.message).splitlines()[0] for w in caught))
    if res is None:
        return [], info
    if info["converged"] is None:
        info["converged"] = bool(res.converged)
    return _model_rows(res, alpha, repeated, crossed_video), info


def _model_rows(res, alpha: float, repeated: bool, crossed: bool) -> list[dict]:
    """Tidy rows: the fixed effects (Wald), then the variance components (estimate only)."""
    fe = res.fe_params if repeated else res.params
    bse = res.bse_fe if repeated else res.bse
    ci = res.conf_int(alpha=alpha)
    pv = res.pvalues
    rows = [
        {
            "term": t,
            "estimate": float(fe[t]),
            "std_error": float(bse[t]),
            "ci_low": float(ci.loc[t, 0]),
            "ci_high": float(ci.loc[t, 1]),
            "p": float(pv[t]),
        }
        for t in fe.index
    ]
    blank = {"std_error": math.nan, "ci_low": math.nan, "ci_high": math.nan, "p": math.nan}
    if repeated and crossed:
        for name, v in zip(res.model.exog_vc.names, res.vcomp):
            rows.append({"term": f"{name} Var", "estimate": float(v), **blank})
    elif repeated:
        rows.append({"term": "participant Var", "estimate": float(res.cov_re.iloc[0, 0]), **blank})
    rows.append({"term": "Residual Var", "estimate": float(res.scale), **blank})
    return rows


def power_rows(design: Design, opts: StatsOptions) -> tuple[list[dict], list[str]]:
    """``power.csv``'s row for ssq_total (the model's response scale) and notes."""
    from statsmodels.stats.power import TTestIndPower, TTestPower

    df = design.table
    y = np.log1p(df["ssq_total"]) if opts.transform == "log1p" else df["ssq_total"]
    wide = participant_means(df.assign(ssq_total=y), "ssq_total")
    a_lab, b_lab = (str(c) for c in df["condition"].cat.categories)
    notes: list[str] = []
    if design.paired:
        d = (wide[b_lab] - wide[a_lab]).dropna().to_numpy(dtype=np.float64)
        sd = float(np.std(d, ddof=1))
        observed = float(np.mean(d)) / sd if sd > 0 else math.nan
        test, solver, n_now, ratio = "paired t (d_z)", TTestPower(), d.size, None
    else:
        a, b = (wide[c].dropna().to_numpy(dtype=np.float64) for c in (a_lab, b_lab))
        sp = math.sqrt(
            ((a.size - 1) * a.var(ddof=1) + (b.size - 1) * b.var(ddof=1)) / (a.size + b.size - 2)
        )
        observed = (b.mean() - a.mean()) / sp if sp > 0 else math.nan
        test, solver, n_now, ratio = (
            "two-sample t (Cohen's d)",
            TTestIndPower(),
            a.size,
            b.size / a.size,
        )
    eff = opts.effect if opts.effect is not None else observed
    row = {
        "design": design.name,
        "test": test,
        "effect": float(eff),
        "alpha": opts.alpha,
        "power": opts.power,
        "participants_needed": math.nan,
        "observed_power": math.nan,
    }
    if not math.isfinite(eff) or eff == 0:
        notes.append(
            "power: the observed effect is 0 or undefined (no variation); give "
            "--effect D for the effect the next study should detect"
        )
        return [row], notes
    kw = {} if ratio is None else {"ratio": 1.0}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        n = solver.solve_power(effect_size=abs(eff), alpha=opts.alpha, power=opts.power, **kw)
        kw_now = {} if ratio is None else {"ratio": ratio}
        row["observed_power"] = float(solver.power(abs(eff), n_now, opts.alpha, **kw_now))
    n = float(np.squeeze(n))
    row["participants_needed"] = math.ceil(n) if math.isfinite(n) else math.nan
    return [row], notes


def _flow_notes(design: Design) -> list[str]:
    """A warning when pooled videos differ much in flow (mean flow, max / min > 2)."""
    vids = design.videos
    if len(vids) < 2:
        return []
    m = design.table.groupby("video", sort=False)["flow"].mean()
    m = m[[v for v in vids]]
    if m.min() > 0 and m.max() / m.min() <= 2.0:
        return []
    ratio = "inf" if m.min() <= 0 else f"{m.max() / m.min():.1f}"
    per = ", ".join(f"{v} {x:.4g}" for v, x in m.items())
    return [
        (
            f"WARNING: pooling mixes videos of very different flow (mean flow {per}: "
            f"{ratio}x); read the per-video tables and the model's flow term"
        )
    ]


def study_statistics(design: Design, opts: StatsOptions) -> Statistics:
    """The tests, the model, power (when ``opts.power``) and per-video tables of ``design``."""
    low = design.table.loc[design.table["ssq_total"] <= -1, "participant"]
    if opts.transform == "log1p" and len(low):
        raise InputError(
            f"{design.source}: --transform log1p: participant {low.iloc[0]!r} has an SSQ total "
            "change (post - pre) of -1 or below, which has no log(1 + x); use --transform none"
        )
    notes = (
        [
            f"{len(design.dropped)} participant(s) dropped from the paired test "
            f"(a condition missing): " + "; ".join(design.dropped)
        ]
        if design.dropped
        else []
    )
    tests = rank_tests(design, opts)
    crossed = len(design.videos) > 1
    model, info = fit_model(design.table, opts.transform, opts.alpha, crossed)
    notes += _model_notes(info, "model")
    power: list[dict] = []
    if opts.power is not None:
        power, pn = power_rows(design, opts)
        notes += pn
    by_video: dict = {}
    if crossed:
        notes += _flow_notes(design)
        for v in design.videos:
            sub = design.table[design.table["video"] == v].reset_index(drop=True)
            try:
                t = rank_tests(design, opts, sub)
            except ValueError as e:  # too few participants in this video
                t = []
                notes.append(f"video {v!r}: tests not possible: {e}")
            m, vinfo = fit_model(sub, opts.transform, opts.alpha, False)
            notes += _model_notes(vinfo, f"model of video {v!r}")
            by_video[v] = (tuple(t), tuple(m))
    return Statistics(
        design, opts, tuple(tests), tuple(model), tuple(power), by_video, info, tuple(notes)
    )


def _model_notes(info: dict, what: str) -> list[str]:
    out = []
    if info["error"]:
        out.append(
            f"{what}: {info['error']} (model.csv left without rows); check that flow "
            "and mssq vary, or try --transform log1p"
        )
    elif not info["converged"]:
        out.append(
            f"WARNING: {what} did not converge: its estimates are not reliable; try "
            "--transform log1p or more participants"
        )
    out += [f"{what}: statsmodels warns: {w}" for w in info["warnings"]]
    return out
