"""Bootstrap confidence intervals whose resampling unit can be a whole cluster of rows.

All intervals come from :func:`scipy.stats.bootstrap` (percentile method by default: it
is defined for every statistic used here, including ``max``, where BCa degenerates on
ties). Randomness is an explicit :class:`numpy.random.Generator`, carried with the level
and the resample count in one :class:`Resampling`.

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

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, TypedDict

import numpy as np
import pandas as pd
import scipy.stats
from numpy.typing import ArrayLike, NDArray

from analysis.tables import is_evolved, require_columns

Statistic = Callable[..., Any]
"""``f(*samples, axis=-1)``: reduces each sample along ``axis`` (vectorised) to a value.

The value is what a scipy or numpy reduction returns (a float for 1-D samples, an array
for more dimensions); scipy carries no types, so it is Any here, at that seam."""


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
