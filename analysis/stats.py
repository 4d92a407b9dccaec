"""Intervals and tests every study shares: the bootstrap, t intervals, Holm, effect sizes.

* **The bootstrap.** :func:`bootstrap_ci` draws every bootstrap interval with
  :func:`scipy.stats.bootstrap` (percentile method by default: it is defined for every
  statistic used here, including ``max``, where BCa degenerates on ties). Randomness is
  an explicit :class:`numpy.random.Generator`, carried with the level and the resample
  count in one :class:`Resampling`.
* **t intervals.** :func:`mean_interval`: the mean of one sample (or of paired
  differences) with its t interval and the one-sample t-test; :func:`welch_contrast`: a
  weighted sum of group means with unequal variances (Welch, Satterthwaite df), of which
  Welch's two-sample test is the case ``(1, −1)``. Both return a :class:`Contrast`.
* **Holm.** :func:`holm`: statsmodels' step-down adjustment, NaN-safe.
* **Effect sizes and rank agreement.** :func:`vargha_delaney_a12` and its label;
  :func:`spearman`, :func:`kendall` and :func:`top_recall`, vectorised for the
  bootstrap.

**Resampling unit (decision).** Robots of a random-structure method (``R+R``, ``R+L``)
are independent draws, so a robot is the unit. Robots of one evolved run (``E+R``,
``E+L``) are not: offspring inherit their parents' subtrees, so their fitnesses are
correlated and robot-level resampling would give intervals that are too narrow. When an
evolved method has more than one GA seed, its unit is the whole run (a cluster
bootstrap: draw seeds with replacement, keep all their robots). With a single seed there
is nothing to resample at run level; robots are then the unit and the interval is
descriptive of that one run, not of the method.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, TypedDict

import numpy as np
import pandas as pd
import scipy.stats
from numpy.typing import ArrayLike, NDArray
from statsmodels.stats.multitest import multipletests

from analysis.tables import is_evolved, require_columns
from evo.fidelity import Statistic

CONFIDENCE = 0.95
"""The level of every interval unless a caller asks for another."""

# ---------------------------------------------------------------- the bootstrap

# A statistic (evo.fidelity.Statistic) is ``f(*samples, axis=-1)``: it reduces each sample
# along ``axis`` (vectorised) to a value, what a scipy or numpy reduction returns.


def resampling_units(rows: pd.DataFrame) -> NDArray[np.int64] | None:
    """Cluster label per row for :func:`bootstrap_ci`, or None when every row is its own unit.

    Rows of an evolved method with more than one seed share a label per ``(method,
    seed)``; every other row gets a label of its own (see the module docstring).

    Args:
        rows: Rows of a robots-like table with ``method`` and ``seed`` columns.

    Returns:
        Integer labels aligned with ``rows``, or None if no two rows share one.
    """
    require_columns(rows, ("method", "seed"), "table to resample")
    methods = rows["method"].to_numpy()
    seeds = rows["seed"].to_numpy()
    labels = np.arange(len(rows), dtype=np.int64)
    clustered = np.zeros(len(rows), dtype=bool)
    for method in pd.unique(methods):
        mask = methods == method
        if is_evolved(str(method)) and len(pd.unique(seeds[mask])) > 1:
            clustered |= mask
    if not clustered.any():
        return None
    keys = pd.Series(methods[clustered].astype(str)) + "\x00" + seeds[clustered].astype(str)
    labels[clustered] = len(rows) + pd.factorize(keys)[0]
    return labels


@dataclass(frozen=True)
class Resampling:
    """How every confidence interval of a study is drawn.

    One value passed down instead of a generator, a level and a count at every layer.
    Intervals drawn one after another consume the generator in turn, so a study with
    the same seed gives the same intervals.

    Attributes:
        rng: Source of the resampling randomness.
        confidence: Two-sided confidence level.
        n_resamples: Bootstrap resamples per interval.
        method: ``"percentile"``, ``"basic"`` or ``"BCa"`` (:func:`scipy.stats.bootstrap`).
    """

    rng: np.random.Generator
    confidence: float = 0.95
    n_resamples: int = 2000
    method: str = "percentile"

    @classmethod
    def seeded(cls, seed: int, n_resamples: int = 2000) -> Resampling:
        """Resampling from a fresh generator seeded with ``seed``."""
        return cls(np.random.default_rng(seed), n_resamples=n_resamples)


class _Options(TypedDict):
    """The keyword arguments of :func:`scipy.stats.bootstrap` that a Resampling sets."""

    n_resamples: int
    confidence_level: float
    method: str
    rng: np.random.Generator


def bootstrap_ci(
    samples: Sequence[ArrayLike],
    statistic: Statistic,
    resampling: Resampling,
    *,
    units: Sequence[ArrayLike | None] | None = None,
    paired: bool = False,
) -> tuple[float, float]:
    """Confidence interval of ``statistic(*samples)``, resampling rows or whole clusters.

    Args:
        samples: One or more 1-D samples; with ``paired`` they have equal length and are
            resampled together (rows of one table).
        statistic: ``f(*samples, axis=-1)``; must accept ``axis`` and reduce along it.
        resampling: Randomness, level and resample count.
        units: Per sample, cluster labels (see :func:`resampling_units`) or None for
            "each observation is a unit"; with ``paired`` only ``units[0]`` is used.
        paired: Resample the samples' rows jointly (for correlations).

    Returns:
        ``(low, high)``; ``(nan, nan)`` when a sample has fewer than two units.
    """
    arrays = [np.asarray(s, dtype=float) for s in samples]
    labels: list[ArrayLike | None] = [None] * len(arrays) if units is None else list(units)
    if paired:
        labels = labels[:1]  # one table: its rows share one labelling
    elif len(labels) != len(arrays):
        raise ValueError(f"got {len(arrays)} samples but {len(labels)} unit labellings")
    if any(_n_units(a, u) < 2 for a, u in zip(arrays, labels, strict=False)):
        return (np.nan, np.nan)
    options = _Options(
        n_resamples=resampling.n_resamples, confidence_level=resampling.confidence,
        method=resampling.method, rng=resampling.rng,
    )
    if all(u is None for u in labels):
        res = scipy.stats.bootstrap(
            tuple(arrays), statistic, paired=paired, vectorized=True, axis=-1, **options
        )
    else:
        data, clustered_statistic, vectorized = _cluster_resampler(
            arrays, labels, statistic, paired
        )
        res = scipy.stats.bootstrap(
            data, clustered_statistic, vectorized=vectorized, axis=-1, **options
        )
    return float(res.confidence_interval.low), float(res.confidence_interval.high)


def _n_units(sample: NDArray[np.float64], labels: ArrayLike | None) -> int:
    return len(sample) if labels is None else len(np.unique(np.asarray(labels)))


def _cluster_resampler(
    arrays: list[NDArray[np.float64]],
    labels: list[ArrayLike | None],
    statistic: Statistic,
    paired: bool,
) -> tuple[tuple[NDArray[np.int64], ...], Statistic, bool]:
    """Recast the samples as cluster indices and ``statistic`` as a function of them.

    scipy then resamples cluster indices; the wrapped statistic gathers the drawn
    clusters' rows and evaluates the original statistic on them. When every sample's
    clusters are of equal size (runs of equal length) the gather is vectorised over
    resamples; otherwise the statistic runs once per resample.

    Returns:
        The cluster-index samples, the wrapped statistic and whether it is vectorised.
    """
    blocks = [np.column_stack(arrays)] if paired else [a[:, None] for a in arrays]
    clusters: list[list[NDArray[np.float64]]] = []
    for block, lab in zip(blocks, labels, strict=True):
        codes = pd.factorize(np.arange(len(block)) if lab is None else np.asarray(lab))[0]
        clusters.append([block[codes == c] for c in range(codes.max() + 1)])
    data = tuple(np.arange(len(cl)) for cl in clusters)
    if all(len({len(c) for c in cl}) == 1 for cl in clusters):
        stacked = [np.stack(cl) for cl in clusters]  # (clusters, rows, columns)

        def gathered(*indices: NDArray[np.int64], axis: int = -1) -> Any:
            drawn = [st[ix].reshape(*ix.shape[:-1], -1, st.shape[-1])
                     for st, ix in zip(stacked, indices, strict=True)]
            return statistic(*(d[..., j] for d in drawn for j in range(d.shape[-1])), axis=-1)

        return data, gathered, True

    def concatenated(*indices: NDArray[np.int64]) -> float:
        drawn = [np.concatenate([cl[int(i)] for i in ix])
                 for cl, ix in zip(clusters, indices, strict=True)]
        return float(statistic(*(col for d in drawn for col in d.T), axis=-1))

    return data, concatenated, False


# ---------------------------------------------------------------- t intervals


@dataclass(frozen=True)
class Contrast:
    """An estimate (a mean, or a contrast of group means), its standard error, the t-test
    of it against 0 and its two-sided t interval.

    Attributes:
        estimate: The mean, or ``Σ w_g mean_g``.
        se: Its standard error.
        df: Degrees of freedom of the t reference.
        t: ``estimate / se``.
        p: Two-sided p-value.
        ci_low: Lower end of the two-sided interval.
        ci_high: Upper end.
    """

    estimate: float
    se: float
    df: float
    t: float
    p: float
    ci_low: float
    ci_high: float

    @classmethod
    def from_t(cls, estimate: float, se: float, df: float, confidence: float = CONFIDENCE
               ) -> Contrast:
        """The test and interval of ``estimate`` with standard error ``se`` on ``df``."""
        if se > 0:
            t = estimate / se
        else:  # no spread: any difference is certain, none is undefined
            t = float(np.copysign(np.inf, estimate)) if estimate else np.nan
        p = float(2 * scipy.stats.t.sf(abs(t), df))
        half = float(scipy.stats.t.ppf(0.5 + confidence / 2, df)) * se
        return cls(float(estimate), float(se), float(df), float(t), p,
                   float(estimate - half), float(estimate + half))

    @classmethod
    def undefined(cls, estimate: float) -> Contrast:
        """An estimate without a test or an interval (too few values)."""
        return cls(float(estimate), *(np.nan,) * 6)


def mean_interval(values: ArrayLike, confidence: float = CONFIDENCE) -> Contrast:
    """The mean of the finite ``values`` with its t interval, and the one-sample t-test
    against 0 (of paired differences: the paired t-test).

    The interval is :func:`scipy.stats.t.interval` around the mean with
    :func:`scipy.stats.sem` as its scale, the p-value :func:`scipy.stats.ttest_1samp`'s.

    Returns:
        The :class:`Contrast` on ``n − 1`` df; with fewer than two values the mean alone
        (NaN when there is none), and when they all agree the mean as a point interval
        with a NaN p (no spread: no test).
    """
    x = np.asarray(values, dtype=float)
    x = x[np.isfinite(x)]
    if len(x) < 2:
        return Contrast.undefined(float(x.mean()) if len(x) else np.nan)
    mean, se = float(x.mean()), float(scipy.stats.sem(x))
    if se == 0:
        return Contrast(mean, 0.0, float(len(x) - 1), np.nan, np.nan, mean, mean)
    low, high = scipy.stats.t.interval(confidence, len(x) - 1, loc=mean, scale=se)
    test = scipy.stats.ttest_1samp(x, 0.0)
    return Contrast(mean, se, float(len(x) - 1), float(test.statistic), float(test.pvalue),
                    float(low), float(high))


def welch_contrast(groups: Sequence[ArrayLike], weights: Sequence[float],
                   confidence: float = CONFIDENCE) -> Contrast:
    """Welch's test of a contrast of means with unequal variances (Satterthwaite df).

    For two groups and weights ``(1, −1)`` this is Welch's two-sample t-test
    (:func:`scipy.stats.ttest_ind` with ``equal_var=False``); scipy has no test of a
    contrast of more groups (the ablation's interaction), so the formula is written
    here once for all.

    Args:
        groups: One sample per group (each of two values or more).
        weights: One weight per group.
        confidence: Level of the interval.

    Returns:
        The contrast; NaN test and interval when a group has fewer than two values.
    """
    samples = [np.asarray(g, dtype=float) for g in groups]
    w = np.asarray(weights, dtype=float)
    estimate = float(sum(wi * s.mean() for wi, s in zip(w, samples, strict=True)))
    if min(len(s) for s in samples) < 2:
        return Contrast.undefined(estimate)
    parts = np.array([wi**2 * s.var(ddof=1) / len(s) for wi, s in zip(w, samples, strict=True)])
    se = float(np.sqrt(parts.sum()))
    denominator = sum(v**2 / (len(s) - 1) for v, s in zip(parts, samples, strict=True))
    df = float(parts.sum() ** 2 / denominator) if denominator > 0 else np.inf
    return Contrast.from_t(estimate, se, df, confidence)


# ---------------------------------------------------------------- tests and effect sizes


def holm(pvalues: ArrayLike) -> NDArray[np.float64]:
    """Holm's step-down adjusted p-values (family-wise error control), by
    :func:`statsmodels.stats.multitest.multipletests`.

    Rejecting where the adjusted value is ≤ α is Holm's procedure at level α. NaN
    p-values stay NaN and do not count towards the family's size.

    Args:
        pvalues: Raw p-values.

    Returns:
        Adjusted p-values in the input order.
    """
    p = np.asarray(pvalues, dtype=float)
    adjusted = np.full_like(p, np.nan)
    finite = ~np.isnan(p)
    if finite.any():
        adjusted[finite] = multipletests(p[finite], method="holm")[1]
    return adjusted


def vargha_delaney_a12(x: ArrayLike, y: ArrayLike) -> float:
    """Vargha–Delaney A12: P(X > Y) + ½ P(X = Y) for a random draw from each sample.

    0.5 means no effect; 1 means every ``x`` beats every ``y``. Equals
    ``U_x / (n_x n_y)`` of the Mann–Whitney test.

    Args:
        x: Sample of the first method.
        y: Sample of the second method.

    Returns:
        A12 in [0, 1]; NaN if a sample is empty.
    """
    a, b = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    if len(a) == 0 or len(b) == 0:
        return np.nan
    ranks = scipy.stats.rankdata(np.concatenate([a, b]))
    return float((ranks[: len(a)].sum() / len(a) - (len(a) + 1) / 2) / len(b))


def wilson(hits: int, trials: int) -> tuple[float, float, float]:
    """``hits / trials`` with its Wilson 95 % interval (NaN without a trial)."""
    if not trials:
        return np.nan, np.nan, np.nan
    ci = scipy.stats.binomtest(hits, trials).proportion_ci(method="wilson")
    return hits / trials, float(ci.low), float(ci.high)


def a12_magnitude(a12: float) -> str:
    """Vargha & Delaney's (2000) label for an A12: negligible, small, medium or large."""
    distance = max(a12, 1 - a12)
    for bound, label in ((0.71, "large"), (0.64, "medium"), (0.56, "small")):
        if distance >= bound:
            return label
    return "negligible"


# ---------------------------------------------------------------- rank agreement

# The rank statistics (Spearman ρ, Kendall τ-b, top-k recall) are defined once, with the
# fitness-fidelity statistics the noise sweep optimises (evo.fidelity), and used here.
