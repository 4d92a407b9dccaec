"""Early-slope prediction (paper §8, §9): does the start of a learning curve rank robots?

The paper conjectures that how fast the mean return rises early in training predicts a
robot's final fitness, and that the slope catches the late risers the early value
misses. These pure functions test that on a robots table and a curves table (schemas in
:mod:`analysis.tables`).

**Prefix.** A robot's curve cut at ``fraction × budget`` env steps: its collector
batches with ``env_steps`` at or below the cut. Batches that completed no episode
(``train/mean_return`` NaN) carry no information and are skipped.

**Predictors** (one number per robot and cut):

* ``value``: mean return of the episodes completed in the last ``last`` informative
  batches of the prefix (episode-weighted).
* ``slope``: Theil–Sen slope of the batch mean return over the second half of the
  prefix (``env_steps ≥ cut / 2``), in return per 1,000 env steps; robust to the odd
  batch that ends one lucky or unlucky episode.
* ``area``: trapezoidal area under the prefix divided by its span: the prefix's
  time-averaged return, comparable across robots whose budgets differ.
* ``curve``: ``a − b·exp(−c·τ)`` (``τ = env_steps / budget``) fitted to the prefix,
  evaluated at ``τ = 1``, the full budget. A grid over ``c`` ∈ [0.1, 100] (where the
  model is linear in ``a``, ``b``) gives the start; :func:`scipy.optimize.curve_fit`
  refines it with a robust soft-L1 loss. With fewer than four points it falls back to
  ``value``; if the refinement fails, to the grid fit.
* ``value+slope``: least squares on ``(1, value, slope)``, cross-validated: a robot's
  prediction comes from a model fitted on folds that hold no robot of its GA seed
  (:func:`grouped_folds`), so the model never sees the run it predicts.

**Targets.** ``fitness``: the paper's fitness, the mean return over the whole training;
the prefix is part of it, which gives every predictor a head start. ``after_cut``: the
mean return of the episodes completed after the cut, the part still unseen at the cut.

**Metrics** (:func:`rank_metrics`): Spearman ρ, Kendall τ-b and top-10 % recall
(:mod:`analysis.stats`), each with a paired bootstrap CI whose unit follows
:func:`analysis.stats.resampling_units`.
:func:`rejection_tradeoff` prices an early-rejection rule: env steps saved against how
many of the final top-k robots it would have thrown away. It is an offline, first-order
estimate: it keeps the rest of each run as it happened, whereas a GA that rejects early
would have bred other offspring afterwards. :func:`analysis.noise_ceiling.noise_ceiling`
bounds what any predictor can reach: the rank agreement of the same structures trained
twice.

This package is the study: these functions compute it; :mod:`analysis.early_slope.report`
runs them on loaded runs (``early_slope_study``), writes the report
(``write_early_slope_report``) and is its command line,
``python -m analysis.early_slope RUN... --out DIR`` (or ``python -m analysis early_slope
...``); the notebook ``analysis/early_slope.pct.py`` runs the same steps cell by cell.
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import partial

import numpy as np
import pandas as pd
from numpy.typing import ArrayLike, NDArray

from analysis.population import population_trace
from analysis.stats import Resampling, bootstrap_ci, resampling_units
from analysis.tables import CURVE_COLUMNS, require_columns
from evo.early_rejection import (  # noqa: F401 - the predictors, shared with the GA
    RATE_BOUNDS,
    SLOPE_STEPS,
    Curve,
    late_slope,
    prefix_area,
    saturating,
    saturating_extrapolation,
    value_at_cut,
)
from evo.fidelity import Statistic, kendall, spearman, top_recall

FRACTIONS: tuple[float, ...] = (0.1, 0.2, 0.3, 0.5, 0.75)
PREDICTORS: tuple[str, ...] = ("value", "slope", "area", "curve", "value+slope")
TARGETS: tuple[str, ...] = ("fitness", "after_cut")

# ---------------------------------------------------------------- one robot's curve

def curve_fitness(curves: pd.DataFrame) -> pd.Series:
    """The paper's fitness (Eq. 8) of every robot, recomputed from its curve.

    Args:
        curves: Curves table.

    Returns:
        Episode-weighted mean return per robot, indexed by ``(run, name)``.
    """
    require_columns(curves, CURVE_COLUMNS, "curves table")
    done = curves[(curves["train/episodes"] > 0) & np.isfinite(curves["train/mean_return"])]
    totals = ((done["train/mean_return"] * done["train/episodes"])
              .groupby([done["run"], done["name"]]))
    return (totals.sum() / done.groupby(["run", "name"])["train/episodes"].sum()).rename("fitness")


def robot_predictors(curve: Curve, budget: float, fraction: float, *,
                     last: int = 3) -> dict[str, float]:
    """The single-robot predictors at one cut, and the ``after_cut`` target.

    Args:
        curve: One robot's curve.
        budget: Its env-step budget.
        fraction: Cut as a fraction of the budget.
        last: Batches averaged by ``value``.

    Returns:
        ``value``, ``slope``, ``area``, ``curve`` and ``after_cut``.
    """
    cut = fraction * budget
    prefix = curve.prefix(cut)
    value = value_at_cut(prefix, last)
    return dict(
        value=value,
        slope=late_slope(prefix, cut),
        area=prefix_area(prefix),
        curve=saturating_extrapolation(prefix, budget, fallback=value),
        after_cut=curve.after(cut).episode_mean(),
    )


# ---------------------------------------------------------------- all robots


def early_table(
    robots: pd.DataFrame,
    curves: pd.DataFrame,
    fractions: Sequence[float] = FRACTIONS,
    *,
    last: int = 3,
    population_size: int = 20,
) -> pd.DataFrame:
    """Predictors and targets of every robot at every cut.

    Args:
        robots: Robots table.
        curves: Curves table.
        fractions: Cuts, as fractions of each robot's budget.
        last: Batches averaged by ``value``.
        population_size: Initial population size, to replay the population minimum
            each robot had to beat (``threshold``; see :mod:`analysis.population`).

    Returns:
        One row per robot and cut: ``run``, ``method``, ``seed``, ``birth``, ``name``,
        ``budget``, ``fitness``, ``threshold``, ``fraction``, the single-robot
        predictors and ``after_cut``; sorted by run, birth and fraction. Robots without
        a curve get NaN predictors.
    """
    require_columns(robots, ("run", "method", "seed", "birth", "name", "budget", "fitness",
                             "accepted"), "robots table")
    require_columns(curves, CURVE_COLUMNS, "curves table")
    trace = population_trace(robots, population_size)[["run", "name", "threshold"]]
    base = robots.merge(trace, on=["run", "name"], how="left").sort_values(["run", "birth"])
    by_robot = {key: Curve.from_rows(rows)
                for key, rows in curves.groupby(["run", "name"], sort=False)}
    no_curve = Curve.from_rows(curves.iloc[:0])
    rows = []
    for robot in base.itertuples(index=False):
        curve = by_robot.get((robot.run, robot.name), no_curve)
        for fraction in fractions:
            predictors = robot_predictors(curve, float(robot.budget), fraction, last=last)
            rows.append(dict(fraction=fraction, **predictors))
    table = pd.DataFrame(rows)
    keep = ["run", "method", "seed", "birth", "name", "budget", "fitness", "threshold"]
    repeated = base[keep].loc[base.index.repeat(len(fractions))].reset_index(drop=True)
    return pd.concat([repeated, table], axis=1)


def grouped_folds(groups: ArrayLike, n_splits: int = 5) -> list[NDArray[np.int64]]:
    """Test-index folds that never split a group (a GA seed) across folds.

    Groups go, largest first, to the fold holding the fewest rows so far (as
    scikit-learn's ``GroupKFold``). With a single group there is nothing to hold out
    by group; the rows are then cut into ``n_splits`` contiguous blocks in the given
    order (birth order keeps relatives, born close together, mostly in one block).

    Args:
        groups: Group label per row.
        n_splits: Number of folds (fewer when there are fewer groups or rows).

    Returns:
        One array of row indices per fold; together they cover every row once (no
        folds when there are no rows).
    """
    codes, labels = pd.factorize(np.asarray(groups))
    n = len(codes)
    if n == 0:
        return []
    if len(labels) < 2:
        return [block.astype(np.int64) for block in np.array_split(np.arange(n),
                                                                     min(n_splits, n))]
    k = min(n_splits, len(labels))
    sizes = np.bincount(codes)
    fold_of_group = np.empty(len(labels), dtype=np.int64)
    load = np.zeros(k)
    for g in np.argsort(-sizes, kind="stable"):
        fold_of_group[g] = int(np.argmin(load))
        load[fold_of_group[g]] += sizes[g]
    fold = fold_of_group[codes]
    return [np.flatnonzero(fold == f) for f in range(k)]


def cross_validated_linear(
    rows: pd.DataFrame,
    target: str,
    *,
    columns: Sequence[str] = ("value", "slope"),
    group: str = "seed",
    n_splits: int = 5,
) -> pd.Series:
    """Out-of-fold predictions of ``target`` from a linear model on ``columns``.

    Args:
        rows: One cut's rows of :func:`early_table`, in birth order within a run.
        target: Column to predict.
        columns: Feature columns (an intercept is added).
        group: Column whose values are never split across folds.
        n_splits: Number of folds.

    Returns:
        Predictions aligned with ``rows``; NaN where a feature or the target is missing.
    """
    x = rows[list(columns)].to_numpy(dtype=float)
    y = rows[target].to_numpy(dtype=float)
    usable = np.flatnonzero(np.isfinite(x).all(axis=1) & np.isfinite(y))
    design = np.column_stack([np.ones(len(usable)), x[usable]])
    out = np.full(len(rows), np.nan)
    for test in grouped_folds(rows[group].to_numpy()[usable], n_splits):
        train = np.setdiff1d(np.arange(len(usable)), test)
        if len(train) < design.shape[1]:
            continue
        coef, *_ = np.linalg.lstsq(design[train], y[usable][train], rcond=None)
        out[usable[test]] = design[test] @ coef
    return pd.Series(out, index=rows.index, name="+".join(columns))


def predictions(
    table: pd.DataFrame, target: str = "fitness", *, group: str = "seed", n_splits: int = 5
) -> pd.DataFrame:
    """Long table of every predictor's prediction next to the target's actual value.

    Args:
        table: Output of :func:`early_table`.
        target: ``"fitness"`` or ``"after_cut"``.
        group: Grouping column for the cross-validated ``value+slope`` model.
        n_splits: Folds of that model.

    Returns:
        The robot columns of ``table`` plus ``target`` (its name), ``actual``,
        ``predictor`` and ``prediction``; one row per robot, cut and predictor.
    """
    if target not in TARGETS:
        raise ValueError(f"target must be one of {TARGETS}, got {target!r}")
    wide = table.sort_values(["run", "birth", "fraction"]).copy()
    wide["value+slope"] = pd.concat([
        cross_validated_linear(rows, target, group=group, n_splits=n_splits)
        for _, rows in wide.groupby("fraction", sort=True)
    ])
    wide["target"], wide["actual"] = target, wide[target]
    ids = [c for c in wide.columns if c not in (*PREDICTORS, "after_cut")]
    return wide.melt(id_vars=ids, value_vars=list(PREDICTORS), var_name="predictor",
                     value_name="prediction")


# ---------------------------------------------------------------- metrics


def rank_metrics(preds: pd.DataFrame, resampling: Resampling, *, share: float = 0.1
                 ) -> pd.DataFrame:
    """Spearman ρ, Kendall τ and top-``share`` recall of every predictor at every cut.

    Args:
        preds: Output of :func:`predictions` (possibly several targets concatenated).
        resampling: How the intervals are drawn.
        share: Top share for the recall (0.1: top 10 %).

    Returns:
        Long table ``target``, ``fraction``, ``predictor``, ``metric``, ``estimate``,
        ``ci_low``, ``ci_high``, ``n`` (robots with both a prediction and a target).
    """
    metrics: dict[str, Statistic] = {
        "spearman": spearman, "kendall": kendall, "top_recall": partial(top_recall, share=share)
    }
    rows = []
    for (target, fraction, predictor), group in preds.groupby(
            ["target", "fraction", "predictor"], sort=False):
        ok = group[np.isfinite(group["prediction"]) & np.isfinite(group["actual"])]
        pair = [ok["prediction"].to_numpy(dtype=float), ok["actual"].to_numpy(dtype=float)]
        units = resampling_units(ok)
        for name, metric in metrics.items():
            too_few = len(ok) < 3
            estimate = np.nan if too_few else float(metric(*pair))
            low, high = (np.nan, np.nan) if too_few else bootstrap_ci(
                pair, metric, resampling, units=[units], paired=True)
            rows.append(dict(target=target, fraction=fraction, predictor=predictor,
                             metric=name, estimate=estimate, ci_low=low, ci_high=high,
                             n=len(ok)))
    return pd.DataFrame(rows)


# ---------------------------------------------------------------- early rejection


def _thresholds(group: pd.DataFrame, prediction: NDArray[np.float64], quantile: float,
                threshold_column: str | None) -> NDArray[np.float64]:
    """Each robot's rejection threshold at one cut: the ``quantile`` of the finite
    predictions, or its own ``threshold_column``. A robot is rejected when its
    prediction is below (NaN on either side compares False: never rejected)."""
    if threshold_column is not None:
        own: NDArray[np.float64] = group[threshold_column].to_numpy(dtype=float)
        return own
    finite = prediction[np.isfinite(prediction)]
    cut_value = np.quantile(finite, quantile) if len(finite) else np.nan
    return np.full(len(group), cut_value)


def rejection_tradeoff(
    preds: pd.DataFrame,
    *,
    quantile: float = 0.25,
    threshold_column: str | None = None,
    top_k: int = 10,
) -> pd.DataFrame:
    """Env steps an early-rejection rule saves against the good robots it loses.

    A robot is rejected at the cut when its prediction is below the threshold: the
    ``quantile`` of all predictions at that cut, or, with ``threshold_column`` (e.g.
    ``"threshold"``, the population minimum it had to beat), its own value there; a NaN
    prediction or threshold never rejects. The second rule compares predictions with
    fitness, so it only makes sense for predictors on the return scale; ``slope`` is
    left out under it.

    Args:
        preds: Output of :func:`predictions`.
        quantile: Share of robots the quantile rule rejects.
        threshold_column: Per-robot threshold column, or None for the quantile rule.
        top_k: Size of the final top (by ``fitness``) whose losses are counted.

    Returns:
        Per ``target``, ``fraction``, ``predictor``: ``n``, ``rejected``,
        ``steps_saved`` (the rejected robots' budgets beyond the cut), ``steps_total``,
        ``saved_share``, ``top_k_lost``, ``best_lost``, ``best_kept`` (the best
        fitness among the robots kept) and ``fitness_lost`` (the best fitness minus
        ``best_kept``: what the rule costs the search's result; 0 when the best is kept).
    """
    if threshold_column is not None:
        preds = preds[preds["predictor"] != "slope"]
    rows = []
    for (target, fraction, predictor), group in preds.groupby(
            ["target", "fraction", "predictor"], sort=False):
        prediction = group["prediction"].to_numpy(dtype=float)
        rejected = prediction < _thresholds(group, prediction, quantile, threshold_column)
        budget = group["budget"].to_numpy(dtype=float)
        fitness = group["fitness"].to_numpy(dtype=float)
        rank = group["fitness"].rank(ascending=False, method="first").to_numpy()
        kept = fitness[~rejected & np.isfinite(fitness)]
        best_kept = float(kept.max()) if len(kept) else np.nan
        rows.append(dict(
            target=target, fraction=fraction, predictor=predictor, n=len(group),
            rejected=int(rejected.sum()),
            steps_saved=float(((1 - fraction) * budget)[rejected].sum()),
            steps_total=float(budget.sum()),
            top_k_lost=int((rejected & (rank <= top_k)).sum()),
            best_lost=bool((rejected & (rank == 1)).any()),
            best_kept=best_kept, fitness_lost=float(np.nanmax(fitness)) - best_kept,
        ))
    columns = ["target", "fraction", "predictor", "n", "rejected", "steps_saved",
               "steps_total", "top_k_lost", "best_lost", "best_kept", "fitness_lost"]
    table = pd.DataFrame(rows, columns=columns)
    table.insert(7, "saved_share", table["steps_saved"] / table["steps_total"])
    return table
