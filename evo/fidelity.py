"""Fitness fidelity (SPEC section 10): how well one training's fitness ranks structures as
another training's does.

The noise ceiling trains every structure of a sample K >= 2 times under independent
seeds (``task=retrain``, :mod:`evo.retrain`) and asks how much of its fitness is the
structure, not the seed. Its statistics are defined here, once, as functions of the
fitness columns (one column per seed, one row per structure) that work along an axis,
so a bootstrap can call them on many resamples at a time: the noise sweep's trials
(:mod:`evo.sweep`) take their point estimates as objectives, and
``analysis.noise_ceiling`` reports them with intervals. The early-slope study ranks
robots with the same rank statistics.

* ``spearman``, ``kendall``: rank correlation between seeds (the mean over seed pairs
  when K > 2);
* ``icc``: ICC(1) of a one-way random-effects model, the share of fitness variance that
  lies between structures rather than between seeds;
* ``top_quarter``: the share of one seed's top 25 % that is also in the other's;
* ``clears_baseline``: the share of structures whose fitness (mean over seeds) clears
  the random learner's on the same structure by more than :data:`CLEAR_MARGIN`.

scipy is imported inside the functions that use it: it is the slowest import on the path
of ``evo/main.py``, which loads this module whether or not the run uses it.
"""

from __future__ import annotations

import itertools
import math
import warnings
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np
import pandas as pd
from numpy.typing import ArrayLike, NDArray

Statistic = Callable[..., Any]
"""A statistic of one or more aligned columns along ``axis`` (scipy.stats.bootstrap's
form)."""

ESTIMATORS: dict[str, str] = {
    "fitness": "Eq. 8: mean return of every episode completed in training",
    "fitness_late": "mean return of the episodes completed in the second half of the budget",
}
"""The fitness estimators a retraining records, and what each is."""
METRICS: tuple[str, ...] = ("spearman", "kendall", "icc", "top_quarter", "clears_baseline")
"""The noise ceiling's statistics."""
TOP_SHARE = 0.25
"""Top-quarter agreement compares each seed's top 25 %."""
CLEAR_MARGIN = 0.01
"""Fitness by which a structure must beat the random learner to count as learning: a
hundredth of the time penalty's range, well above the float noise of a robot that
cannot move (its fitness is −1 to about 1e-6)."""


def spearman(x: ArrayLike, y: ArrayLike, axis: int = -1) -> Any:
    """Spearman ρ along ``axis`` (Pearson correlation of average ranks)."""
    import scipy.stats  # where it is used: see the module's docstring

    rx = scipy.stats.rankdata(x, axis=axis)
    ry = scipy.stats.rankdata(y, axis=axis)
    return scipy.stats.pearsonr(rx, ry, axis=axis).statistic


def kendall(x: ArrayLike, y: ArrayLike, axis: int = -1) -> Any:
    """Kendall τ-b along ``axis``."""
    import scipy.stats  # where it is used: see the module's docstring

    return scipy.stats.kendalltau(x, y, axis=axis).statistic


def top_recall(prediction: ArrayLike, actual: ArrayLike, share: float = 0.1,
               axis: int = -1) -> Any:
    """Share of the actual top ``ceil(share·n)`` that the prediction also puts on top.

    Ties are broken by position, so duplicates drawn by a bootstrap count separately.

    Args:
        prediction: Predicted values.
        actual: Actual values, aligned with ``prediction``.
        share: Size of the top as a share of the robots (at least one robot).
        axis: Axis along which robots lie.

    Returns:
        Recall in [0, 1] (an array when the inputs have more dimensions).
    """
    p = np.moveaxis(np.asarray(prediction, dtype=float), axis, -1)
    a = np.moveaxis(np.asarray(actual, dtype=float), axis, -1)
    n = p.shape[-1]
    k = max(1, math.ceil(share * n))

    def on_top(v: NDArray[np.float64]) -> NDArray[np.bool_]:
        ranks = np.argsort(np.argsort(v, axis=-1, kind="stable"), axis=-1)
        return np.asarray(ranks >= n - k, dtype=bool)

    return (on_top(p) & on_top(a)).sum(axis=-1) / k


def icc(*columns: ArrayLike, axis: int = -1) -> Any:
    """ICC(1) of a one-way random-effects model: each column one seed, each row
    (along ``axis``) one structure.

    ``(MSB − MSW) / (MSB + (K − 1)·MSW)``, with MSB the between-structure and MSW the
    within-structure mean square: the share of fitness variance due to the structure
    (1 when seeds agree exactly, about 0 when structure explains nothing; it can dip
    below 0 by chance).
    """
    x = np.stack([np.moveaxis(np.asarray(c, dtype=float), axis, -1) for c in columns])
    k, n = x.shape[0], x.shape[-1]
    means = x.mean(axis=0)
    grand = means.mean(axis=-1, keepdims=True)
    msb = k * ((means - grand) ** 2).sum(axis=-1) / (n - 1)
    msw = ((x - means) ** 2).sum(axis=0).sum(axis=-1) / (n * (k - 1))
    with np.errstate(divide="ignore", invalid="ignore"):
        return (msb - msw) / (msb + (k - 1) * msw)


def top_quarter(a: ArrayLike, b: ArrayLike, axis: int = -1) -> Any:
    """Share of ``a``'s top quarter that is also in ``b``'s (ties broken by position)."""
    return top_recall(a, b, share=TOP_SHARE, axis=axis)


def pairwise_mean(metric: Statistic, k: int) -> Statistic:
    """``metric`` of two seed columns, averaged over all pairs of ``k`` columns."""
    pairs = list(itertools.combinations(range(k), 2))

    def mean(*cols: NDArray[np.float64], axis: int = -1) -> Any:
        return np.mean([metric(cols[i], cols[j], axis=axis) for i, j in pairs], axis=0)

    return mean


def clears(k: int) -> Statistic:
    """Share of rows whose mean over the first ``k`` columns exceeds the last column by
    more than :data:`CLEAR_MARGIN`."""

    def share(*cols: NDArray[np.float64], axis: int = -1) -> Any:
        mean = np.mean(np.stack(cols[:k]), axis=0)
        return np.mean(mean > cols[k] + CLEAR_MARGIN, axis=axis)

    return share


def statistics(k: int) -> dict[str, Statistic]:
    """The seed-to-seed statistics of ``k`` seed columns (``clears_baseline`` aside: it
    takes the baseline as a last column, :func:`clears`)."""
    return {"spearman": pairwise_mean(spearman, k), "kendall": pairwise_mean(kendall, k),
            "icc": icc, "top_quarter": pairwise_mean(top_quarter, k)}


def by_role(trainings: pd.DataFrame) -> tuple[pd.DataFrame, pd.DataFrame]:
    """The seed trainings and the baseline (random learner) trainings of a
    ``trainings.csv`` table."""
    return (trainings[trainings["role"] == "seed"], trainings[trainings["role"] == "baseline"])


def seed_columns(seeds: pd.DataFrame, value: str, *, structure: str = "structure",
                 seed: str = "replicate") -> pd.DataFrame:
    """One row per structure trained under every seed, one column per seed, of ``value``
    (a structure trained under only some seeds is left out)."""
    return seeds.pivot_table(index=structure, columns=seed, values=value,
                             aggfunc="mean").dropna()


def agreement(trainings: pd.DataFrame, value: str = "fitness") -> dict[str, float]:
    """The point estimates of every statistic of :data:`METRICS` over the seed trainings
    of a ``trainings.csv`` table, for the estimator ``value``; NaN with fewer than 3
    structures trained under every seed. ``n_structures`` and ``n_seeds`` say how many."""
    seeds, base = by_role(trainings)
    wide = seed_columns(seeds, value)
    k = wide.shape[1]
    columns = [wide[c].to_numpy(dtype=float) for c in wide.columns]
    out: dict[str, float] = dict.fromkeys(METRICS, math.nan)
    if k >= 2 and len(wide) >= 3:
        import scipy.stats  # where it is used: see the module's docstring

        with warnings.catch_warnings():
            warnings.simplefilter("ignore", scipy.stats.ConstantInputWarning)
            out.update({name: float(statistic(*columns))
                        for name, statistic in statistics(k).items()})
            baseline = base.groupby("structure")[value].mean().reindex(wide.index)
            if len(base) and np.isfinite(baseline.to_numpy(dtype=float)).all():
                out["clears_baseline"] = float(
                    clears(k)(*columns, baseline.to_numpy(dtype=float)))
    return {**out, "n_structures": float(len(wide)), "n_seeds": float(k)}


def ceiling_line(metrics: Mapping[str, float]) -> str:
    """The noise ceiling's point estimates in one line."""
    shown = ", ".join(f"{name} {metrics[name]:.3f}" for name in METRICS
                      if math.isfinite(metrics[name]))
    return (f"{int(metrics['n_structures'])} structures × {int(metrics['n_seeds'])} seeds: "
            f"{shown or 'too few structures trained under every seed for a ranking'}")
