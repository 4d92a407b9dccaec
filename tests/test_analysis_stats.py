"""Ablation statistics on small arrays and synthetic tables with known answers."""

from __future__ import annotations

import gc

import numpy as np
import pandas as pd
import pytest
import scipy.stats

from analysis import stats
from analysis.ablation import robot_level
from analysis.population import best_so_far, population_trace
from analysis.stats import Resampling, bootstrap_ci, resampling_units
from analysis.synthetic import synthetic_robots
from analysis.tables import require_columns

# ---------------------------------------------------------------- point statistics


def test_iqm_is_the_mean_of_the_middle_half() -> None:
    assert robot_level.iqm([1, 2, 3, 4, 5, 6, 7, 100]) == pytest.approx(4.5)  # mean of 3..6
    assert robot_level.iqm(np.arange(10)) == pytest.approx(4.5)  # cuts 2 each end: mean of 2..7
    assert robot_level.iqm([[0, 1, 2, 3], [4, 4, 8, 8]]).tolist() == pytest.approx([1.5, 6.0])


def test_top_k_mean_takes_the_largest_k() -> None:
    assert robot_level.top_k_mean([5, 1, 4, 2, 3], k=2) == pytest.approx(4.5)
    assert robot_level.top_k_mean([1.0, 2.0], k=5) == pytest.approx(1.5), "fewer than k: all"


# ---------------------------------------------------------------- bootstrap


def tight_90(seed: int) -> Resampling:
    """A 90 % interval from enough resamples that its quantiles are the exact ones."""
    return Resampling(np.random.default_rng(seed), confidence=0.90, n_resamples=20_000)


def test_percentile_bootstrap_matches_hand_computed_quantiles() -> None:
    # Means of resamples of [0, 0, 1] are k/3 with k ~ Binomial(3, 1/3):
    # P(0) = 8/27, P(1/3) = 12/27, P(2/3) = 6/27, P(1) = 1/27, so the 5 % quantile is 0
    # and the 95 % one 2/3 (P(k <= 2) = 26/27 = 0.963 > 0.95).
    low, high = bootstrap_ci([[0.0, 0.0, 1.0]], np.mean, tight_90(0))
    assert (low, high) == pytest.approx((0.0, 2 / 3))


def test_cluster_bootstrap_resamples_whole_clusters() -> None:
    x = np.repeat([0.0, 0.0, 1.0], 3)  # three clusters of three
    labels = np.repeat([0, 1, 2], 3)
    # Clusters as units: the same Binomial(3, 1/3)/3 as above -> (0, 2/3).
    clustered = bootstrap_ci([x], np.mean, tight_90(1), units=[labels])
    assert clustered == pytest.approx((0.0, 2 / 3))
    # Robots as units: k/9 with k ~ Binomial(9, 1/3): P(k=0) = 0.026 < 0.05 <= P(k<=1),
    # P(k<=4) = 0.855 < 0.95 <= P(k<=5) = 0.958 -> (1/9, 5/9), a narrower interval.
    robots = bootstrap_ci([x], np.mean, tight_90(1))
    assert robots == pytest.approx((1 / 9, 5 / 9))


def test_cluster_bootstrap_handles_unequal_clusters() -> None:
    # Clusters A = [0, 0], B = [1], C = [1]; drawing k copies of A (k ~ Binomial(3, 1/3))
    # gives the mean (3 - k) / (3 + k): 1, 1/2, 1/5, 0 with P = 8, 12, 6, 1 (/27).
    # P(0) = 0.037 < 0.05, so the 5 % quantile is 1/5; the 95 % one is 1.
    x = np.array([0.0, 0.0, 1.0, 1.0])
    ci = bootstrap_ci([x], np.mean, tight_90(2), units=[[0, 0, 1, 2]])
    assert ci == pytest.approx((0.2, 1.0))
    with pytest.raises(ValueError, match="unit labellings"):
        bootstrap_ci([x, x], np.mean, Resampling.seeded(2), units=[None])


def test_bootstrap_needs_two_units() -> None:
    assert np.isnan(bootstrap_ci([[1.0]], np.mean, Resampling.seeded(0))).all()
    one_cluster = bootstrap_ci([[1.0, 2.0]], np.mean, Resampling.seeded(0), units=[[7, 7]])
    assert np.isnan(one_cluster).all()


def test_resampling_units_cluster_evolved_methods_with_several_seeds() -> None:
    table = pd.DataFrame(dict(method=["R+L", "R+L", "E+L", "E+L", "E+L", "E+R", "E+R"],
                              seed=[0, 1, 0, 0, 1, 0, 0]))
    units = resampling_units(table)
    assert units is not None
    assert len(set(units[:2])) == 2, "random-structure robots are their own units"
    assert units[2] == units[3] != units[4], "E+L robots share their seed's unit"
    assert units[5] != units[6], "E+R has one seed only: robots are units"
    assert resampling_units(table[table["method"] != "E+L"]) is None


# ---------------------------------------------------------------- summary


@pytest.fixture(scope="module")
def ablation() -> pd.DataFrame:
    """R+R and E+R alike, E+L planted 1.5 sd higher; three seeds each."""
    means = {"R+R": 0.0, "R+L": 0.5, "E+R": 0.0, "E+L": 1.5}
    return synthetic_robots(np.random.default_rng(7), means=means, seeds=(0, 1, 2),
                            n_robots=20, sd=1.0, population_size=5)


def test_summary_reports_every_statistic_with_a_ci(ablation: pd.DataFrame) -> None:
    summary = robot_level.summarize(ablation, Resampling.seeded(0, 300))
    assert list(summary["method"].unique()) == ["R+R", "R+L", "E+R", "E+L"]
    assert set(summary["statistic"]) == {"max", "top5_mean", "mean", "median", "iqm", "std"}
    assert (summary["n"] == 60).all() and (summary["n_seeds"] == 3).all()
    units = summary.groupby("method")["unit"].first()
    assert units.to_dict() == {"R+R": "robot", "R+L": "robot", "E+R": "run", "E+L": "run"}
    el = ablation.loc[ablation["method"] == "E+L", "fitness"]
    row = summary.set_index(["method", "statistic"]).loc["E+L"]
    assert row.loc["mean", "estimate"] == pytest.approx(el.mean())
    assert row.loc["std", "estimate"] == pytest.approx(el.std(ddof=1))
    assert row.loc["iqm", "estimate"] == pytest.approx(scipy.stats.trim_mean(el, 0.25))
    assert row.loc["top5_mean", "estimate"] == pytest.approx(el.nlargest(5).mean())
    inside = (summary["ci_low"] <= summary["estimate"] + 1e-12) & (
        summary["estimate"] <= summary["ci_high"] + 1e-12)
    assert inside.all(), summary[~inside]


def test_compare_with_paper_lists_the_reported_numbers(ablation: pd.DataFrame) -> None:
    summary = robot_level.summarize(ablation, Resampling.seeded(0, 200))
    table = robot_level.compare_with_paper(summary)
    assert len(table) == 8
    paper = table.set_index(["method", "statistic"])["paper"]
    assert paper[("E+L", "max")] == 2.47 and paper[("R+L", "std")] == 0.60
    assert paper[("R+R", "max")] == -0.47 and paper[("E+R", "max")] == -0.06
    assert table["ours"].notna().all()


# ---------------------------------------------------------------- tests and effect sizes


def test_holm_matches_a_hand_worked_example() -> None:
    # Sorted: 0.005*4 = 0.02, 0.01*3 = 0.03, 0.03*2 = 0.06, 0.04*1 = 0.04 -> running
    # maximum 0.02, 0.03, 0.06, 0.06; back in input order:
    adjusted = stats.holm([0.01, 0.04, 0.03, 0.005])
    assert adjusted == pytest.approx([0.03, 0.06, 0.06, 0.02])
    assert stats.holm([0.5, 0.9]) == pytest.approx([1.0, 1.0]), "capped at 1"
    with_nan = stats.holm([0.01, np.nan, 0.02])
    assert np.isnan(with_nan[1]) and with_nan[[0, 2]] == pytest.approx([0.02, 0.02])


def test_a12_extremes_and_a_hand_count() -> None:
    assert stats.vargha_delaney_a12([5, 6, 7], [1, 2, 3]) == 1.0
    assert stats.vargha_delaney_a12([1, 2, 3], [5, 6, 7]) == 0.0
    assert stats.vargha_delaney_a12([1, 2, 3], [1, 2, 3]) == 0.5
    # Pairs (1,1) tie, (1,3) lose, (2,1) win, (2,3) lose: (0.5 + 1) / 4.
    assert stats.vargha_delaney_a12([1, 2], [1, 3]) == pytest.approx(0.375)
    assert stats.a12_magnitude(0.5) == "negligible"
    assert stats.a12_magnitude(0.2) == "large"


def test_a12_equals_normalised_mann_whitney_u() -> None:
    rng = np.random.default_rng(3)
    x, y = rng.normal(size=17).round(1), rng.normal(0.3, size=11).round(1)
    u = scipy.stats.mannwhitneyu(x, y).statistic
    assert stats.vargha_delaney_a12(x, y) == pytest.approx(u / (len(x) * len(y)))


def test_planted_difference_is_significant(ablation: pd.DataFrame) -> None:
    assert robot_level.kruskal_wallis(ablation).pvalue < 1e-6
    pairs = robot_level.pairwise_mann_whitney(ablation).set_index(["a", "b"])
    for other in ("R+R", "R+L", "E+R"):
        assert pairs.loc[(other, "E+L"), "reject"], f"E+L was planted above {other}"
    assert pairs.loc[("R+R", "E+L"), "a12"] < 0.25, "E+L beats R+R most of the time"
    assert (pairs["p_holm"] >= pairs["p"]).all()


def test_null_differences_are_rarely_significant() -> None:
    """Holm keeps the family-wise error of three null comparisons near 5 %."""
    rng = np.random.default_rng(11)
    methods = np.repeat(["R+R", "E+R", "E+L"], 30)
    tables = [pd.DataFrame(dict(method=methods, run=methods, fitness=rng.normal(size=90)))
              for _ in range(200)]
    # statsmodels' Holm runs a full gc.collect() per call: with the test process's objects
    # frozen out of the collector's reach, 200 calls take a second instead of a minute.
    gc.freeze()
    try:
        any_rejected = [robot_level.pairwise_mann_whitney(t)["reject"].any() for t in tables]
    finally:
        gc.unfreeze()
    kruskal_rejected = [robot_level.kruskal_wallis(t).pvalue <= 0.05 for t in tables]
    assert np.mean(any_rejected) < 0.1 and np.mean(kruskal_rejected) < 0.1


def test_per_run_tests_compare_one_value_per_run(ablation: pd.DataFrame) -> None:
    pairs = robot_level.pairwise_mann_whitney(ablation, per_run="mean")
    assert (pairs["n_a"] == 3).all() and (pairs["n_b"] == 3).all()


def test_interaction_contrast_recovers_planted_means() -> None:
    rng = np.random.default_rng(5)
    means = {"R+R": 0.0, "R+L": 1.0, "E+R": 0.0, "E+L": 3.0}  # interaction = 2
    robots = synthetic_robots(rng, means=means, seeds=(0, 1, 2, 3), n_robots=25, sd=0.3)
    table = robot_level.interaction_contrast(robots, Resampling(rng, n_resamples=500))
    table = table.set_index("contrast")
    row = table.loc["interaction (E+L − R+L) − (E+R − R+R)"]
    group_means = robots.groupby("method")["fitness"].mean()
    expected = (group_means["E+L"] - group_means["R+L"]) - (group_means["E+R"]
                                                            - group_means["R+R"])
    assert row["estimate"] == pytest.approx(expected)
    assert row["ci_low"] < 2.0 < row["ci_high"] and row["ci_low"] > 0
    no_learning = table.loc["evolution without learning (E+R − R+R)"]
    assert no_learning["ci_low"] < 0 < no_learning["ci_high"]


def test_contrast_names_a_missing_method() -> None:
    robots = synthetic_robots(np.random.default_rng(0), means={"R+R": 0.0}, n_robots=5)
    with pytest.raises(ValueError, match="no rows for method"):
        robot_level.interaction_contrast(robots, Resampling.seeded(0))


# ---------------------------------------------------------------- population replay


def test_population_trace_replays_the_steady_state() -> None:
    robots = pd.DataFrame(dict(
        run="r", birth=range(5), name=[f"robot-{i}" for i in range(5)],
        fitness=[1.0, 3.0, 0.5, 2.0, 0.0], accepted=[True, True, False, True, False],
    ))
    trace = population_trace(robots, population_size=2)
    assert np.isnan(trace["threshold"][:2]).all()
    assert trace["threshold"][2:].tolist() == [1.0, 1.0, 2.0]
    assert trace["pop_max"].tolist() == [1.0, 3.0, 3.0, 3.0, 3.0]
    assert trace["pop_mean"].tolist() == [1.0, 2.0, 2.0, 2.5, 2.5]


def test_best_so_far_accumulates_budget_and_fitness() -> None:
    robots = pd.DataFrame(dict(run="r", method="E+L", seed=0, birth=[1, 0, 2],
                               budget=[20, 10, 30], fitness=[0.0, 1.0, 2.0]))
    trace = best_so_far(robots)
    assert trace["env_steps"].tolist() == [10, 30, 60]
    assert trace["best"].tolist() == [1.0, 1.0, 2.0]


def test_missing_column_is_named() -> None:
    with pytest.raises(ValueError, match="fitness"):
        require_columns(pd.DataFrame(dict(run=[])), ["run", "fitness"], "robots table")
