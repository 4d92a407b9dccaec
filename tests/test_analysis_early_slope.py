"""Early-slope prediction on synthetic learning curves whose answer is known."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
import scipy.stats

from analysis import early_slope as es
from analysis.stats import Resampling
from analysis.synthetic import synthetic_curves, synthetic_robots, with_curve_fitness
from evo import fidelity


def learning_runs(rng: np.random.Generator, *, seeds: tuple[int, ...] = (0,), n_robots: int = 30,
                  **curve: object) -> tuple[pd.DataFrame, pd.DataFrame]:
    """E+L robots and their curves; fitness recomputed from the curves (paper Eq. 8)."""
    robots = synthetic_robots(rng, means={"E+L": 0.0}, seeds=seeds, n_robots=n_robots,
                              population_size=5)
    curves = synthetic_curves(robots, rng, **curve)  # type: ignore[arg-type]
    return with_curve_fitness(robots, curves, population_size=5), curves


def metric(table: pd.DataFrame, predictor: str, fraction: float, name: str) -> pd.Series:
    rows = table[(table["predictor"] == predictor) & (table["fraction"] == fraction)
                 & (table["metric"] == name)]
    assert len(rows) == 1, rows
    return rows.iloc[0]


# ---------------------------------------------------------------- one curve


def curve_of(steps: np.ndarray, returns: np.ndarray, episodes: int = 2) -> es.Curve:
    return es.Curve(np.asarray(steps, float), np.asarray(returns, float),
                    np.full(len(steps), float(episodes)))


def test_episode_mean_weights_batches_and_skips_empty_ones() -> None:
    rows = pd.DataFrame({"run": "r", "name": "robot-a", "env_steps": [10, 20, 30],
                         "train/mean_return": [1.0, np.nan, 4.0], "train/episodes": [3, 0, 1],
                         "train/success_rate": np.nan})
    curve = es.Curve.from_rows(rows)
    assert curve.steps.tolist() == [10.0, 30.0]
    assert curve.episode_mean() == pytest.approx((3 * 1.0 + 1 * 4.0) / 4)
    assert es.curve_fitness(rows).loc[("r", "robot-a")] == pytest.approx(7 / 4)
    assert np.isnan(curve.prefix(5).episode_mean())


def test_single_curve_predictors_on_a_straight_line() -> None:
    steps = np.arange(1, 11) * 1000.0
    line = curve_of(steps, 0.5 + 2e-4 * steps)  # slope 0.2 per 1,000 steps
    assert es.late_slope(line, cut=10_000) == pytest.approx(0.2)
    assert es.value_at_cut(line, last=2) == pytest.approx(0.5 + 2e-4 * 9500)
    assert es.prefix_area(line) == pytest.approx(0.5 + 2e-4 * 5500), "mean of a line"
    assert np.isnan(es.late_slope(line.prefix(1000), cut=1000)), "one point: no slope"


def test_saturating_fit_extrapolates_to_the_full_budget() -> None:
    budget = 100_000.0
    tau = np.arange(1, 31) / 100  # the first 30 % of the budget
    truth = es.saturating(tau, 2.0, 2.5, 4.0)
    exact = es.saturating_extrapolation(curve_of(tau * budget, truth), budget, fallback=-9)
    assert exact == pytest.approx(es.saturating(1.0, 2.0, 2.5, 4.0), abs=1e-4)
    noisy = truth + np.random.default_rng(0).normal(0, 0.05, size=len(tau))
    estimate = es.saturating_extrapolation(curve_of(tau * budget, noisy), budget, fallback=-9)
    assert estimate == pytest.approx(es.saturating(1.0, 2.0, 2.5, 4.0), abs=0.3)
    short = curve_of(tau[:3] * budget, truth[:3])
    assert es.saturating_extrapolation(short, budget, fallback=-9) == -9


# ---------------------------------------------------------------- ranking


def test_known_ranking_gives_rho_one_at_late_cuts() -> None:
    rng = np.random.default_rng(0)
    final = rng.permutation(np.linspace(0.5, 3.0, 30))
    robots, curves = learning_runs(rng, start=0.0, final=final, rate=3.0)
    table = es.early_table(robots, curves, fractions=(0.5, 0.75), population_size=5)
    assert len(table) == 60 and table["value"].notna().all()
    metrics = es.rank_metrics(es.predictions(table, "fitness"), Resampling(rng, n_resamples=200))
    for fraction in (0.5, 0.75):
        for predictor in ("value", "area", "curve"):
            row = metric(metrics, predictor, fraction, "spearman")
            assert row["estimate"] == pytest.approx(1.0), (predictor, fraction)
            assert row["ci_low"] == pytest.approx(1.0), "every resample ranks perfectly"
        assert metric(metrics, "value", fraction, "kendall")["estimate"] == pytest.approx(1.0)
        assert metric(metrics, "value", fraction, "top_recall")["estimate"] == 1.0


def test_pure_noise_curves_carry_no_rank_information() -> None:
    rng = np.random.default_rng(1)
    robots, curves = learning_runs(rng, n_robots=60, start=0.0, final=0.0, noise=1.0)
    table = es.early_table(robots, curves, fractions=(0.3,), population_size=5)
    metrics = es.rank_metrics(es.predictions(table, "after_cut"), Resampling(rng, n_resamples=500))
    for name in ("spearman", "kendall"):
        row = metric(metrics, "value", 0.3, name)
        assert abs(row["estimate"]) < 0.3, row
        assert row["ci_low"] < 0 < row["ci_high"], row


def test_slope_catches_late_risers_the_value_misses() -> None:
    """Curves that cross: where a robot starts says less about its future than its rise."""
    rng = np.random.default_rng(2)
    n = 4 * 25
    robots, curves = learning_runs(rng, seeds=(0, 1, 2, 3), n_robots=25,
                                   start=rng.normal(size=n), final=rng.normal(0, 4, size=n),
                                   rate=1.0, noise=0.02)
    table = es.early_table(robots, curves, fractions=(0.2,), population_size=5)
    metrics = es.rank_metrics(es.predictions(table, "after_cut"), Resampling(rng, n_resamples=200))
    value = metric(metrics, "value", 0.2, "spearman")["estimate"]
    combined = metric(metrics, "value+slope", 0.2, "spearman")
    assert combined["estimate"] > value + 0.1, (combined["estimate"], value)
    assert combined["estimate"] > 0.9


# ---------------------------------------------------------------- cross-validation


def test_grouped_folds_never_split_a_group() -> None:
    groups = np.random.default_rng(3).integers(0, 7, size=50)
    folds = es.grouped_folds(groups, n_splits=3)
    assert len(folds) == 3
    assert sorted(np.concatenate(folds).tolist()) == list(range(50))
    homes = [{f for f, fold in enumerate(folds) if g in groups[fold]} for g in set(groups)]
    assert all(len(h) == 1 for h in homes)
    blocks = es.grouped_folds(np.zeros(10), n_splits=3)
    assert [b.tolist() for b in blocks] == [[0, 1, 2, 3], [4, 5, 6], [7, 8, 9]]


def test_cross_validated_linear_recovers_an_exact_linear_target() -> None:
    rng = np.random.default_rng(4)
    rows = pd.DataFrame(dict(value=rng.normal(size=40), slope=rng.normal(size=40),
                             seed=np.repeat([0, 1, 2, 3], 10)))
    rows["target"] = 2 + 3 * rows["value"] - rows["slope"]
    rows.loc[5, "slope"] = np.nan
    predicted = es.cross_validated_linear(rows, "target")
    assert np.isnan(predicted[5])
    assert predicted.drop(index=5).to_numpy() == pytest.approx(rows["target"].drop(index=5))


# ---------------------------------------------------------------- metrics


def test_rank_metrics_agree_with_scipy_and_hand_counts() -> None:
    rng = np.random.default_rng(5)
    x, y = rng.normal(size=25).round(1), rng.normal(size=25).round(1)
    assert fidelity.spearman(x, y) == pytest.approx(scipy.stats.spearmanr(x, y).statistic)
    assert fidelity.kendall(x, y) == pytest.approx(scipy.stats.kendalltau(x, y).statistic)
    ranks = np.arange(20.0)
    assert fidelity.top_recall(ranks, ranks) == 1.0
    assert fidelity.top_recall(-ranks, ranks) == 0.0
    swapped = ranks.copy()
    swapped[[19, 0]] = swapped[[0, 19]]  # the best is predicted worst
    assert fidelity.top_recall(swapped, ranks) == 0.5  # top 2: one of two kept


# ---------------------------------------------------------------- early rejection


def rejection_input(prediction: np.ndarray, fitness: np.ndarray) -> pd.DataFrame:
    n = len(fitness)
    return pd.DataFrame(dict(target="fitness", fraction=0.2, predictor="value",
                             prediction=prediction, actual=fitness, fitness=fitness,
                             budget=np.full(n, 1000), threshold=np.nan))


def test_perfect_predictor_rejects_the_bottom_and_keeps_the_top() -> None:
    fitness = np.arange(20.0)
    table = es.rejection_tradeoff(rejection_input(fitness, fitness), quantile=0.25, top_k=5)
    row = table.iloc[0]
    assert row["rejected"] == 5  # fitness 0..4 are below the 25 % quantile, 4.75
    assert row["steps_saved"] == pytest.approx(5 * 0.8 * 1000)
    assert row["saved_share"] == pytest.approx(0.2)
    assert row["top_k_lost"] == 0 and not row["best_lost"]


def test_inverted_predictor_loses_the_best() -> None:
    fitness = np.arange(20.0)
    row = es.rejection_tradeoff(rejection_input(-fitness, fitness), quantile=0.25,
                                top_k=5).iloc[0]
    assert row["top_k_lost"] == 5 and row["best_lost"]


def test_population_minimum_rule_uses_each_robots_threshold() -> None:
    fitness = np.array([1.0, 2.0, 3.0, 4.0])
    preds = rejection_input(np.array([0.5, 2.5, 2.0, 5.0]), fitness)
    preds["threshold"] = [np.nan, 2.0, 2.5, 2.5]  # the first robot faced no population
    row = es.rejection_tradeoff(preds, threshold_column="threshold", top_k=1).iloc[0]
    assert row["rejected"] == 1 and row["top_k_lost"] == 0
