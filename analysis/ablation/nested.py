"""Statistics whose unit is the GA run: robots are nested in runs.

The robots of one evolved run share ancestors, so their fitnesses are correlated; the
robots of one random-structure run share at most the run's seed. A test that treats
every robot as independent then overstates its evidence whenever runs differ (the run
effect). This module answers the ablation's questions with the run as the unit:

* :func:`run_summaries`: one row per run with the mean fitness of its robots, its best
  robot and the mean of its final population (the steady-state replay of
  :mod:`analysis.population`).
* :func:`run_level_tests`: per question (:data:`PAIRS` and the interaction of
  :data:`INTERACTION`, then :data:`EXTRA_PAIRS`), a Welch t-test on one summary per
  run (:func:`analysis.stats.welch_contrast`), Holm over the paper's pairs only.
  Welch, not Mann–Whitney: with three runs against three a rank test cannot go below
  p = 0.1, and the per-method spread of run means differs by a factor of ten or more
  between the methods, which the pooled t-test would ignore.
* :func:`mixed_model_tests`: the same questions from a linear mixed model on robots,
  ``value ~ method`` with a random intercept per run (statsmodels' ``MixedLM``, REML),
  its Wald statistic referred to a t distribution with the between-run ("containment")
  degrees of freedom, runs minus fixed effects, because a z reference is liberal with a
  handful of runs. A pair is fitted on that pair's robots only (the model has one
  residual variance, and the methods' spreads differ); the interaction on all four.
* :func:`variance_components`: per method, the within-run and between-run standard
  deviations (one-way random-effects ANOVA, method of moments), the input of
  :mod:`analysis.ablation.power`.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import NotRequired, TypedDict, TypeVar

import numpy as np
import pandas as pd
import statsmodels.formula.api as smf
from statsmodels.tools.sm_exceptions import ConvergenceWarning

from analysis.population import final_population
from analysis.stats import Contrast, holm, mean_interval, welch_contrast
from analysis.tables import method_order, require_columns

PAIRS: tuple[tuple[str, str], ...] = (("E+L", "R+L"), ("R+L", "E+R"), ("E+R", "R+R"))
"""The paper's order E+L > R+L > E+R > R+R as three adjacent pairs: one Holm family."""
INTERACTION: dict[str, float] = {"E+L": 1.0, "R+L": -1.0, "E+R": -1.0, "R+R": 1.0}
"""``(E+L − R+L) − (E+R − R+R)``: does evolution pay off only with learning?"""
INTERACTION_NAME = "interaction (E+L − R+L) − (E+R − R+R)"
EXTRA_PAIRS: tuple[tuple[str, str], ...] = (("E+L+I", "E+L"),)
"""Questions beyond the paper's, each its own test outside the Holm family of
:data:`PAIRS` (so the paper's p-values are the same with or without them): does
inheriting a parent's policy pay off? E+L+I's fitness includes what its robots
inherited, so it measures policy and body together, not the body alone."""
FIT_METHODS = ["powell", "lbfgs"]
"""MixedLM optimisers in turn: statsmodels' default (BFGS first) stops short of the REML
optimum on small balanced designs; Powell reaches it and L-BFGS polishes."""
RUN_SUMMARIES: tuple[str, ...] = ("mean", "best", "final_population_mean")
"""The per-run summaries :func:`run_summaries` gives and :func:`run_level_tests` tests."""


def question_name(a: str, b: str) -> str:
    """A pair as a question, ``"E+L vs R+L"``."""
    return f"{a} vs {b}"


def questions() -> list[tuple[str, dict[str, float]]]:
    """Every question as (name, contrast weights): the paper's pairs, the interaction,
    then :data:`EXTRA_PAIRS`."""
    pairs = [(question_name(a, b), {a: 1.0, b: -1.0}) for a, b in PAIRS]
    extra = [(question_name(a, b), {a: 1.0, b: -1.0}) for a, b in EXTRA_PAIRS]
    return [*pairs, (INTERACTION_NAME, dict(INTERACTION)), *extra]


def in_holm_family(question: str) -> bool:
    """Whether a question is one of the paper's pairs, the Holm family of :data:`PAIRS`
    (the interaction and :data:`EXTRA_PAIRS` are each their own test)."""
    return question in {question_name(a, b) for a, b in PAIRS}


# ---------------------------------------------------------------- per-run summaries


def run_summaries(
    robots: pd.DataFrame, population_size: int | Mapping[str, int] = 20,
    value: str = "fitness",
) -> pd.DataFrame:
    """One row per run: its robots' mean, its best robot and its final population's mean.

    Args:
        robots: Robots table (``run``, ``method``, ``seed``, ``birth``, ``name``,
            ``accepted`` and ``value``), fully trained robots only.
        population_size: Initial population size, one for all runs or per run id.
        value: Column to summarise.

    Returns:
        Columns ``run``, ``method``, ``seed``, ``robots``, ``mean``, ``best`` and
        ``final_population_mean``, runs in method then seed order.
    """
    require_columns(robots, ("run", "method", "seed", "birth", "name", "accepted", value),
                    "robots table")
    rows = []
    for run, group in robots.groupby("run", sort=True):
        size = (population_size if isinstance(population_size, int)
                else population_size.get(str(run), 20))
        final = final_population(group.assign(fitness=group[value]), size)["fitness"]
        rows.append(dict(run=run, method=group["method"].iloc[0],
                         seed=int(group["seed"].iloc[0]), robots=len(group),
                         mean=float(group[value].mean()), best=float(group[value].max()),
                         final_population_mean=float(final.mean())))
    table = pd.DataFrame(rows, columns=["run", "method", "seed", "robots", *RUN_SUMMARIES])
    order = {m: i for i, m in enumerate(method_order(table["method"]))}
    return table.sort_values(["method", "seed"], key=lambda s: s.map(order)
                             if s.name == "method" else s).reset_index(drop=True)


# ---------------------------------------------------------------- Welch on run summaries


class HolmRow(TypedDict):
    """What Holm's step reads (``question``, ``p``) and adds (``p_holm``, ``reject``)."""

    question: str
    p: float
    p_holm: NotRequired[float]
    reject: NotRequired[bool]


Row = TypeVar("Row", bound=HolmRow)


class WelchRow(HolmRow):
    """One row of :func:`run_level_tests`."""

    summary: str
    runs: str  # runs per method, "/"-joined
    estimate: float
    ci_low: float
    ci_high: float
    t: float
    df: float


class MixedRow(HolmRow):
    """One row of :func:`mixed_model_tests`."""

    runs: int
    robots: int
    estimate: float
    se: float
    ci_low: float
    ci_high: float
    t: float
    df: float
    sd_between: float
    sd_within: float
    converged: bool


def run_level_tests(
    runs: pd.DataFrame, summaries: Sequence[str] = RUN_SUMMARIES, alpha: float = 0.05
) -> pd.DataFrame:
    """Every question answered on one summary per run by Welch's t-test.

    Args:
        runs: :func:`run_summaries`.
        summaries: The per-run summaries to test.
        alpha: Family-wise level; Holm over :data:`PAIRS` within each summary; the
            interaction and each of :data:`EXTRA_PAIRS` are their own questions at
            ``alpha``.

    Returns:
        One row per summary and question: ``summary``, ``question``, ``runs`` (per
        method, ``/``-joined), ``estimate`` (difference of mean run summaries),
        ``ci_low``, ``ci_high``, ``t``, ``df``, ``p``, ``p_holm`` and ``reject``.
        Questions whose methods are missing are left out.
    """
    present = set(runs["method"])
    rows: list[WelchRow] = []
    for summary in summaries:
        part: list[WelchRow] = []
        for name, weights in questions():
            if not set(weights) <= present:
                continue
            groups = [runs.loc[runs["method"] == m, summary] for m in weights]
            c = welch_contrast(groups, list(weights.values()))
            part.append(WelchRow(summary=summary, question=name,
                                 runs="/".join(str(len(g)) for g in groups),
                                 estimate=c.estimate, ci_low=c.ci_low, ci_high=c.ci_high,
                                 t=c.t, df=c.df, p=c.p))
        rows += _with_holm(part, alpha)
    return pd.DataFrame(rows, columns=["summary", "question", "runs", "estimate", "ci_low",
                                       "ci_high", "t", "df", "p", "p_holm", "reject"])


def _with_holm(rows: list[Row], alpha: float) -> list[Row]:
    """``p_holm`` over the rows of the paper's pairs (the interaction and the extra
    pairs keep their p) and ``reject``."""
    pairs = [r for r in rows if in_holm_family(r["question"])]
    for row, adjusted in zip(pairs, holm([r["p"] for r in pairs]), strict=True):
        row["p_holm"] = float(adjusted)
    for row in rows:
        if "p_holm" not in row:
            row["p_holm"] = row["p"]
        row["reject"] = bool(row["p_holm"] <= alpha)
    return rows


def run_level_means(runs: pd.DataFrame, summary: str = "mean",
                    confidence: float = 0.95) -> pd.DataFrame:
    """Per method: the mean of a run summary over runs with a t interval (runs as unit).

    Returns:
        Columns ``method``, ``runs``, ``estimate``, ``ci_low``, ``ci_high``, ``sd``
        (between the runs' summaries).
    """
    rows = []
    for method in method_order(runs["method"]):
        x = runs.loc[runs["method"] == method, summary]
        c = mean_interval(x, confidence)
        rows.append(dict(method=method, runs=len(x), estimate=c.estimate, ci_low=c.ci_low,
                         ci_high=c.ci_high, sd=float(x.std(ddof=1)) if len(x) > 1 else np.nan))
    return pd.DataFrame(rows, columns=["method", "runs", "estimate", "ci_low", "ci_high", "sd"])


# ---------------------------------------------------------------- mixed model


@dataclass(frozen=True)
class MixedFit:
    """One mixed-model contrast: the test and the fitted variance components.

    Attributes:
        contrast: Estimate, standard error, t on the containment df, p, interval.
        sd_between: Standard deviation of the run intercepts.
        sd_within: Residual (robot) standard deviation.
        converged: Whether the optimiser converged without a warning (a run variance
            estimated at its boundary, 0, is a fit, not a failure).
    """

    contrast: Contrast
    sd_between: float
    sd_within: float
    converged: bool


def mixed_contrast(robots: pd.DataFrame, weights: Mapping[str, float], value: str = "fitness",
                   confidence: float = 0.95) -> MixedFit:
    """Fit ``value ~ 0 + method`` with a random intercept per run; test a contrast.

    Args:
        robots: Robots table; only the methods named in ``weights`` are used.
        weights: Method → contrast weight.
        value: Column modelled.
        confidence: Level of the interval.

    Returns:
        The contrast of the method means, referred to t with ``runs − methods`` df.

    Raises:
        ValueError: If a method has no robots or there are no more runs than methods.
    """
    methods = list(weights)
    data = robots.loc[robots["method"].isin(methods), ["method", "run", value]]
    data = data.rename(columns={value: "y"}).reset_index(drop=True)
    missing = [m for m in methods if m not in set(data["method"])]
    df = data["run"].nunique() - len(methods)
    if missing or df < 1:
        raise ValueError(f"mixed model of {methods} needs robots of each and more runs than "
                         f"methods; missing {missing}, {data['run'].nunique()} runs")
    data["method"] = pd.Categorical(data["method"], categories=methods)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        fit = smf.mixedlm("y ~ 0 + method", data, groups=data["run"]).fit(
            reml=True, method=FIT_METHODS)
    names = [f"method[{m}]" for m in methods]
    w = np.array(list(weights.values()), dtype=float)
    estimate = float(w @ fit.fe_params[names].to_numpy())
    cov = fit.cov_params().loc[names, names].to_numpy()
    se = float(np.sqrt(w @ cov @ w))
    converged = bool(fit.converged) and not any(
        issubclass(c.category, ConvergenceWarning) and "boundary" not in str(c.message)
        for c in caught)
    return MixedFit(Contrast.from_t(estimate, se, df, confidence),
                    sd_between=float(np.sqrt(max(float(fit.cov_re.iloc[0, 0]), 0.0))),
                    sd_within=float(np.sqrt(fit.scale)), converged=converged)


def mixed_model_tests(robots: pd.DataFrame, value: str = "fitness",
                      alpha: float = 0.05) -> pd.DataFrame:
    """Every question from the mixed model: pairs on their robots, the interaction on all.

    Args:
        robots: Robots table, fully trained robots only.
        value: Column modelled.
        alpha: Family-wise level (Holm over :data:`PAIRS`; the interaction and each
            of :data:`EXTRA_PAIRS` on their own).

    Returns:
        One row per question that can be fitted: ``question``, ``runs``, ``robots``,
        ``estimate``, ``se``, ``ci_low``, ``ci_high``, ``t``, ``df``, ``p``, ``p_holm``,
        ``reject``, ``sd_between``, ``sd_within`` and ``converged``.
    """
    rows: list[MixedRow] = []
    for name, weights in questions():
        part = robots[robots["method"].isin(list(weights))]
        try:
            fit = mixed_contrast(part, weights, value)
        except (ValueError, np.linalg.LinAlgError):  # too few runs, or a singular fit
            continue
        c = fit.contrast
        rows.append(MixedRow(question=name, runs=part["run"].nunique(), robots=len(part),
                             estimate=c.estimate, se=c.se, ci_low=c.ci_low, ci_high=c.ci_high,
                             t=c.t, df=c.df, p=c.p, sd_between=fit.sd_between,
                             sd_within=fit.sd_within, converged=fit.converged))
    rows = _with_holm(rows, alpha)
    return pd.DataFrame(rows, columns=["question", "runs", "robots", "estimate", "se", "ci_low",
                                       "ci_high", "t", "df", "p", "p_holm", "reject",
                                       "sd_between", "sd_within", "converged"])


# ---------------------------------------------------------------- variance components


def variance_components(robots: pd.DataFrame, value: str = "fitness") -> pd.DataFrame:
    """Per method: within-run and between-run standard deviations of ``value``.

    One-way random-effects ANOVA by the method of moments: ``sd_within²`` is the mean
    within-run variance; ``sd_between²`` is the variance of the run means less
    ``sd_within² / m`` (``m`` the mean robots per run), floored at 0.

    Returns:
        Columns ``method``, ``runs``, ``robots_per_run``, ``mean``, ``sd_within``,
        ``sd_between`` and ``sd_run_mean`` (the observed spread of the run means).
    """
    require_columns(robots, ("method", "run", value), "robots table")
    rows = []
    for method in method_order(robots["method"]):
        per_run = robots[robots["method"] == method].groupby("run")[value]
        means, variances, sizes = per_run.mean(), per_run.var(ddof=1), per_run.size()
        m = float(sizes.mean())
        within = float(variances.mean())
        spread = float(means.var(ddof=1)) if len(means) > 1 else np.nan
        between = max(spread - within / m, 0.0) if len(means) > 1 else np.nan
        rows.append(dict(method=method, runs=len(means), robots_per_run=m,
                         mean=float(means.mean()), sd_within=np.sqrt(within),
                         sd_between=np.sqrt(between), sd_run_mean=np.sqrt(spread)))
    return pd.DataFrame(rows)
