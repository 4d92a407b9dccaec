"""The ablation's statistics with the robot as the unit (paper §8): summaries with
bootstrap CIs, rank tests, effect sizes and contrasts.

Every function takes a robots table (schema in :mod:`analysis.tables`: one row per
evaluated robot with ``run``, ``method``, ``seed``, ``birth``, ``name``, ``budget``,
``fitness``, ``accepted``, ``parents``) and compares the methods ``R+R``, ``R+L``,
``E+R`` and ``E+L`` on one value column, ``fitness`` by default.

* :func:`summarize`: per method n, max, top-k mean, mean, median, IQM and std, each with
  a bootstrap CI. The resampling unit is the robot, or the whole GA run for an evolved
  method with several seeds (cluster bootstrap; see :mod:`analysis.stats`).
* :func:`kruskal_wallis` and :func:`pairwise_mann_whitney`: rank tests over robots, as
  the paper compares robots; Holm's step-down adjustment (:func:`analysis.stats.holm`)
  controls the family-wise error of the pairwise family. ``per_run`` compares run-level
  aggregates instead, which respects the GA run as the unit of replication when there
  are seeds enough to test.
* :func:`analysis.stats.vargha_delaney_a12`: the probability that a robot of one method
  beats one of another (ties count half).
* :func:`interaction_contrast`: ``(E+L − R+L) − (E+R − R+R)`` on means, the paper's
  claim that evolution helps only together with learning, with bootstrap CIs.
* :data:`PAPER_ABLATION` and :func:`compare_with_paper`: the paper's reported numbers
  beside ours. The paper's rewards come from its Unity task, so absolute values are
  only roughly comparable; the ordering of the methods is what should reproduce.

The std is the sample standard deviation (``ddof=1``); the IQM is the mean of the
middle 50 % (:func:`scipy.stats.trim_mean` with 25 % cut from each end). A bootstrap
interval of the max (and, less so, of the top-k mean) cannot reach above the largest
robot seen: read it as how stable the estimate is under resampling, not as coverage of
the best robot a method could find.
"""

from __future__ import annotations

import itertools
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import partial
from typing import Any

import numpy as np
import pandas as pd
import scipy.stats
from numpy.typing import ArrayLike, NDArray

from analysis.stats import (
    Resampling,
    a12_magnitude,
    bootstrap_ci,
    holm,
    resampling_units,
    vargha_delaney_a12,
)
from analysis.tables import method_order, require_columns
from evo.fidelity import Statistic

# ---------------------------------------------------------------- point statistics


def iqm(x: ArrayLike, axis: int = -1) -> Any:
    """Interquartile mean: the mean of the middle 50 % (25 % trimmed from each end).

    As in :func:`scipy.stats.trim_mean`, ``floor(0.25 n)`` values are cut at each end.

    Args:
        x: Values.
        axis: Axis to reduce.

    Returns:
        The IQM (a float for 1-D input).
    """
    return scipy.stats.trim_mean(np.asarray(x, dtype=float), 0.25, axis=axis)


def top_k_mean(x: ArrayLike, k: int = 5, axis: int = -1) -> Any:
    """Mean of the ``k`` largest values (of all of them when there are fewer than ``k``).

    Args:
        x: Values.
        k: How many of the largest to average.
        axis: Axis to reduce.

    Returns:
        The top-k mean (a float for 1-D input).
    """
    values = np.moveaxis(np.asarray(x, dtype=float), axis, -1)
    return np.sort(values, axis=-1)[..., -k:].mean(axis=-1)


def summary_statistics(k: int = 5) -> dict[str, Statistic]:
    """The statistics :func:`summarize` reports, by name, each ``f(x, axis=-1)``."""
    return {
        "max": np.max,
        f"top{k}_mean": partial(top_k_mean, k=k),
        "mean": np.mean,
        "median": np.median,
        "iqm": iqm,
        "std": partial(np.std, ddof=1),
    }


# ---------------------------------------------------------------- summary with CIs


def summarize(
    robots: pd.DataFrame, resampling: Resampling, *, value: str = "fitness", k: int = 5
) -> pd.DataFrame:
    """Per method and statistic: the estimate and its bootstrap CI.

    Args:
        robots: Robots table.
        resampling: How the intervals are drawn.
        value: Column to summarise.
        k: ``k`` of the top-k mean.

    Returns:
        Long table with columns ``method``, ``statistic``, ``estimate``, ``ci_low``,
        ``ci_high``, ``n`` (robots), ``n_seeds`` and ``unit`` (``"robot"`` or ``"run"``,
        the resampling unit), methods in :data:`analysis.tables.METHODS` order.
    """
    require_columns(robots, ("method", "seed", value), "robots table")
    rows = []
    for method in method_order(robots["method"]):
        group = robots[robots["method"] == method]
        x = group[value].to_numpy(dtype=float)
        units = resampling_units(group)
        for name, stat in summary_statistics(k).items():
            low, high = bootstrap_ci([x], stat, resampling, units=[units])
            min_n = 2 if name == "std" else 1
            estimate = float(stat(x, axis=-1)) if len(x) >= min_n else np.nan
            rows.append(
                dict(method=method, statistic=name, estimate=estimate, ci_low=low,
                     ci_high=high, n=len(x), n_seeds=group["seed"].nunique(),
                     unit="robot" if units is None else "run")
            )
    return pd.DataFrame(rows)


# ---------------------------------------------------------------- tests and effect sizes


@dataclass(frozen=True)
class GroupTest:
    """Result of a test across several methods."""

    statistic: float
    pvalue: float
    methods: tuple[str, ...]


def method_samples(
    robots: pd.DataFrame, value: str = "fitness", per_run: str | None = None
) -> dict[str, NDArray[np.float64]]:
    """The values of each method, or each run's aggregate of them.

    Args:
        robots: Robots table.
        value: Column to compare.
        per_run: None to compare robots; an aggregation name (``"mean"``, ``"max"``, ...)
            to compare one aggregate per run.

    Returns:
        Method → values, in :data:`analysis.tables.METHODS` order.
    """
    require_columns(robots, ("method", "run", value), "robots table")
    table = robots
    if per_run is not None:
        table = robots.groupby(["method", "run"], as_index=False)[value].agg(per_run)
    return {
        m: table.loc[table["method"] == m, value].to_numpy(dtype=float)
        for m in method_order(table["method"])
    }


def kruskal_wallis(
    robots: pd.DataFrame, value: str = "fitness", per_run: str | None = None
) -> GroupTest:
    """Kruskal–Wallis H test that all methods share one distribution of ``value``.

    Args:
        robots: Robots table.
        value: Column to compare.
        per_run: See :func:`method_samples`.

    Returns:
        H statistic, p-value and the methods compared.
    """
    samples = method_samples(robots, value, per_run)
    result = scipy.stats.kruskal(*samples.values())
    return GroupTest(float(result.statistic), float(result.pvalue), tuple(samples))


def pairwise_mann_whitney(
    robots: pd.DataFrame,
    value: str = "fitness",
    *,
    alpha: float = 0.05,
    per_run: str | None = None,
    pairs: Sequence[tuple[str, str]] | None = None,
) -> pd.DataFrame:
    """Two-sided Mann–Whitney U test and A12 for every pair of methods, Holm-adjusted.

    Args:
        robots: Robots table.
        value: Column to compare.
        alpha: Family-wise error level for ``reject``.
        per_run: See :func:`method_samples`.
        pairs: The pairs ``(a, b)`` to test, one Holm family; None for every pair of
            the methods present, in :data:`analysis.tables.METHODS` order.

    Raises:
        ValueError: If a method of ``pairs`` has no robots.

    Returns:
        One row per pair ``(a, b)`` with ``n_a``, ``n_b``, ``u`` (U of ``a``), ``p``,
        ``p_holm``, ``reject`` (``p_holm <= alpha``), ``a12`` (a beats b) and
        ``magnitude``.
    """
    samples = method_samples(robots, value, per_run)
    absent = sorted({m for pair in pairs or () for m in pair} - set(samples))
    if absent:
        raise ValueError(f"robots table has no rows for method(s) {absent}")
    rows = []
    for a, b in itertools.combinations(samples, 2) if pairs is None else pairs:
        x, y = samples[a], samples[b]
        result = scipy.stats.mannwhitneyu(x, y, alternative="two-sided")
        a12 = vargha_delaney_a12(x, y)
        rows.append(dict(a=a, b=b, n_a=len(x), n_b=len(y), u=float(result.statistic),
                         p=float(result.pvalue), a12=a12, magnitude=a12_magnitude(a12)))
    table = pd.DataFrame(rows, columns=["a", "b", "n_a", "n_b", "u", "p", "a12", "magnitude"])
    table.insert(6, "p_holm", holm(table["p"]))
    table.insert(7, "reject", table["p_holm"] <= alpha)
    return table


# ---------------------------------------------------------------- contrasts


def mean_contrast(
    robots: pd.DataFrame,
    weights: Mapping[str, float],
    resampling: Resampling,
    *,
    value: str = "fitness",
) -> tuple[float, float, float]:
    """A weighted sum of method means, ``Σ w_m mean_m``, with a bootstrap CI.

    Methods are resampled independently, each with its own unit (robot or run).

    Args:
        robots: Robots table.
        weights: Method → weight; every method named must be in the table.
        resampling: How the interval is drawn.
        value: Column to compare.

    Returns:
        ``(estimate, ci_low, ci_high)``.

    Raises:
        ValueError: If a weighted method has no robots.
    """
    groups = {m: robots[robots["method"] == m] for m in weights}
    empty = [m for m, g in groups.items() if g.empty]
    if empty:
        raise ValueError(f"robots table has no rows for method(s) {empty}")
    w = np.array(list(weights.values()), dtype=float)

    def contrast(*xs: NDArray[np.float64], axis: int = -1) -> Any:
        return sum(wi * np.mean(xi, axis=axis) for wi, xi in zip(w, xs, strict=True))

    samples = [g[value].to_numpy(dtype=float) for g in groups.values()]
    units = [resampling_units(g) for g in groups.values()]
    low, high = bootstrap_ci(samples, contrast, resampling, units=units)
    return float(contrast(*samples)), low, high


INTERACTION_CONTRASTS: dict[str, dict[str, float]] = {
    "evolution without learning (E+R − R+R)": {"E+R": 1.0, "R+R": -1.0},
    "evolution with learning (E+L − R+L)": {"E+L": 1.0, "R+L": -1.0},
    "interaction (E+L − R+L) − (E+R − R+R)": {"E+L": 1.0, "R+L": -1.0, "E+R": -1.0, "R+R": 1.0},
}


def interaction_contrast(
    robots: pd.DataFrame, resampling: Resampling, *, value: str = "fitness"
) -> pd.DataFrame:
    """Effect of evolution on mean fitness without and with learning, and their difference.

    A positive interaction whose CI excludes 0 supports the paper's reading: evolving
    structures pays off only when behaviours are learned.

    Args:
        robots: Robots table with all four methods.
        resampling: How the intervals are drawn.
        value: Column to compare.

    Returns:
        Rows ``contrast``, ``estimate``, ``ci_low``, ``ci_high``.
    """
    rows = [
        (name, *mean_contrast(robots, weights, resampling, value=value))
        for name, weights in INTERACTION_CONTRASTS.items()
    ]
    return pd.DataFrame(rows, columns=["contrast", "estimate", "ci_low", "ci_high"])


# ---------------------------------------------------------------- the paper's numbers

PAPER_ABLATION = pd.DataFrame(
    [
        ("R+R", "max", -0.47),
        ("E+R", "max", -0.06),
        ("R+L", "max", 1.90),
        ("R+L", "mean", -0.52),
        ("R+L", "std", 0.60),
        ("E+L", "max", 2.47),
        ("E+L", "mean", 0.50),
        ("E+L", "std", 1.07),
    ],
    columns=["method", "statistic", "paper"],
)
"""Numbers the paper reports for its ablation (§8, Figs. 13–15; 30k steps per robot)."""


def compare_with_paper(summary: pd.DataFrame) -> pd.DataFrame:
    """The paper's reported numbers beside ours.

    Args:
        summary: Output of :func:`summarize`.

    Returns:
        One row per number in :data:`PAPER_ABLATION`: ``method``, ``statistic``,
        ``paper``, ``ours``, ``ci_low``, ``ci_high`` and ``paper_in_ci`` (NaN-safe:
        False where we have no estimate).
    """
    ours = summary[["method", "statistic", "estimate", "ci_low", "ci_high"]]
    table = PAPER_ABLATION.merge(ours, on=["method", "statistic"], how="left")
    table = table.rename(columns={"estimate": "ours"})
    table["paper_in_ci"] = (table["ci_low"] <= table["paper"]) & (
        table["paper"] <= table["ci_high"]
    )
    return table
