"""Run-level statistics on synthetic runs with a planted run effect, and the power analysis.

Every synthetic study draws runs whose robots share a per-run offset (``seed_sd``): the
run effect that makes robot-level tests overconfident. The rejection rates are checked
against the binomial spread of a test at its nominal level over seeded repetitions.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import scipy.stats
from statsmodels.stats.power import TTestIndPower

from analysis import stats
from analysis.ablation import nested, power, robot_level
from analysis.ablation.nested_report import write_nested_tables
from analysis.ablation.report import ablation_markdown, ablation_tables, main
from analysis.load import Runs, load_histories
from analysis.stats import Resampling
from analysis.synthetic import synthetic_robots
from evo.run.layout import RunLayout
from evo.run.records import RunSummary, write_run_summary

ALPHA = 0.05
PAIR = "E+L vs R+L"


def null_band(reps: int, alpha: float = ALPHA, tail: float = 0.001) -> tuple[float, float]:
    """Rejection rates a test at level ``alpha`` stays within over ``reps`` studies,
    but for a two-sided ``tail`` chance."""
    low = scipy.stats.binom.ppf(tail / 2, reps, alpha) / reps
    high = scipy.stats.binom.isf(tail / 2, reps, alpha) / reps
    return float(low), float(high)


def study(rng: np.random.Generator, difference: float, *, seeds: int = 5, n_robots: int = 8,
          seed_sd: float = 1.0) -> pd.DataFrame:
    """E+L and R+L runs, robots ~ N(mean + run offset, 1): the columns the tests read."""
    methods = np.repeat(["R+L", "E+L"], seeds)
    offsets = np.where(methods == "E+L", difference, 0.0) + seed_sd * rng.normal(size=len(methods))
    return pd.DataFrame(dict(
        method=np.repeat(methods, n_robots),
        run=np.repeat([f"{m}-seed{i % seeds}" for i, m in enumerate(methods)], n_robots),
        fitness=np.repeat(offsets, n_robots) + rng.normal(size=len(methods) * n_robots),
    ))


def run_level_p(robots: pd.DataFrame) -> float:
    """Welch's test of E+L against R+L on run means (what :func:`nested.run_level_tests`
    runs per pair), without the tables around it, which these many studies do not need."""
    means = robots.groupby(["method", "run"])["fitness"].mean()
    return stats.welch_contrast([means["E+L"], means["R+L"]], [1.0, -1.0]).p


def robot_level_p(robots: pd.DataFrame) -> float:
    pairs = robot_level.pairwise_mann_whitney(robots).set_index(["a", "b"])
    return float(pairs.loc[("R+L", "E+L"), "p"])


# ---------------------------------------------------------------- the tests' arithmetic


def test_welch_contrast_of_two_groups_is_scipys_welch_test() -> None:
    rng = np.random.default_rng(0)
    a, b = rng.normal(1.0, 2.0, size=5), rng.normal(0.0, 0.5, size=7)
    ours = stats.welch_contrast([a, b], [1.0, -1.0])
    theirs = scipy.stats.ttest_ind(a, b, equal_var=False)
    assert ours.t == pytest.approx(theirs.statistic)
    assert ours.p == pytest.approx(theirs.pvalue)
    assert ours.df == pytest.approx(theirs.df)
    low, high = theirs.confidence_interval()
    assert (ours.ci_low, ours.ci_high) == pytest.approx((low, high))
    assert np.isnan(stats.welch_contrast([a, [1.0]], [1.0, -1.0]).p), "one value: no test"


def test_run_summaries_are_each_runs_mean_best_and_final_population() -> None:
    robots = pd.DataFrame(dict(
        run="E+L-seed3", method="E+L", seed=3, birth=range(4), name=list("abcd"),
        fitness=[0.0, 2.0, 5.0, -1.0], accepted=[True, True, True, False]))
    row = nested.run_summaries(robots, population_size=2).iloc[0]
    # Population {0, 2}; 5 replaces 0 -> {5, 2}; -1 is rejected.
    assert (row["robots"], row["mean"], row["best"]) == (4, 1.5, 5.0)
    assert row["final_population_mean"] == pytest.approx(3.5)


# ---------------------------------------------------------------- behaviour on synthetic runs


def test_run_level_tests_detect_a_planted_difference_despite_the_run_effect() -> None:
    robots = synthetic_robots(np.random.default_rng(1), means={"R+L": 0.0, "E+L": 2.0},
                              seeds=range(6), n_robots=10, seed_sd=0.5, population_size=4)
    runs = nested.run_summaries(robots, 4)
    row = nested.run_level_tests(runs).set_index(["summary", "question"]).loc[("mean", PAIR)]
    assert row["reject"] and row["ci_low"] < 2.0 < row["ci_high"]
    mixed = nested.mixed_model_tests(robots).set_index("question").loc[PAIR]
    assert mixed["reject"] and mixed["df"] == 10, "12 runs less 2 methods"
    assert mixed["estimate"] == pytest.approx(row["estimate"])
    # Equal robots per run and a run variance above 0: the mixed model's t is the
    # pooled-variance t-test on run means.
    means = runs.set_index("method")["mean"]
    pooled = scipy.stats.ttest_ind(means["E+L"], means["R+L"])
    assert mixed["t"] == pytest.approx(pooled.statistic, rel=1e-2)
    assert mixed["sd_between"] == pytest.approx(0.5, abs=0.35)


def test_without_a_difference_run_level_tests_reject_at_their_level_robot_tests_do_not() -> None:
    """Studies of 5 runs per method of 20 robots, run effect as large as the robot noise."""
    rng = np.random.default_rng(2)
    studies = [study(rng, difference=0.0, n_robots=20) for _ in range(300)]
    run_level = np.mean([run_level_p(s) <= ALPHA for s in studies])
    low, high = null_band(len(studies))
    assert low <= run_level <= high, f"run-level rejection rate {run_level}"
    robot_level = np.mean([robot_level_p(s) <= ALPHA for s in studies[:60]])
    assert robot_level > 4 * high, f"robot-level test rejected only {robot_level}"


def test_mixed_model_rejects_at_its_level_without_a_difference() -> None:
    """The mixed model's Wald t on runs − methods df is calibrated with few runs."""
    rng = np.random.default_rng(3)
    reps = 60
    rejected = [
        nested.mixed_contrast(study(rng, 0.0, seeds=4, n_robots=5), {"E+L": 1.0, "R+L": -1.0})
        .contrast.p <= ALPHA
        for _ in range(reps)
    ]
    low, high = null_band(reps)
    assert low <= np.mean(rejected) <= high, f"mixed-model rejection rate {np.mean(rejected)}"


# ---------------------------------------------------------------- power


def test_closed_form_seeds_match_the_textbook_and_the_simulation() -> None:
    # d = 0.5 at alpha 0.05 needs 64 per group (Cohen 1988, Table 2.4.1).
    assert power.analytic_seeds(0.5, 1.0, 1.0, alpha=0.05) == 64
    n = power.analytic_seeds(1.0, 1.0, 1.0, alpha=0.05)
    expected = TTestIndPower().power(effect_size=1.0, nobs1=n, alpha=0.05)
    simulated = power.simulated_power(1.0, 1.0, 1.0, n, 0.05, np.random.default_rng(4))
    assert simulated == pytest.approx(expected, abs=0.03)


def test_power_asks_more_seeds_for_a_smaller_effect() -> None:
    rng = np.random.default_rng(5)
    seeds = [power.seeds_needed(delta, 0.04, 0.004, rng=rng) for delta in (0.4, 0.2, 0.1)]
    assert seeds[0] < seeds[1] < seeds[2], seeds
    robots = synthetic_robots(np.random.default_rng(6), means={"R+L": 0.0, "E+L": 1.0},
                              seeds=(0, 1, 2), n_robots=10, sd=0.3, seed_sd=0.2)
    table = power.power_table(robots, scales=(2.0, 1.0, 0.5), robots_per_run=(10,),
                              rng=rng).set_index("delta")
    assert table["seeds"].is_monotonic_increasing and table.index.is_monotonic_decreasing
    assert (table["seeds"] >= table["seeds_closed_form"]).all()
    assert table["alpha_planned"].to_numpy() == pytest.approx(ALPHA / 3)


def test_holm_level_asks_more_seeds_than_a_single_test() -> None:
    single = power.seeds_needed(0.3, 0.1, 0.1, n_tests=1)
    assert power.seeds_needed(0.3, 0.1, 0.1, n_tests=3) > single


# ---------------------------------------------------------------- in the report


def write_copies(robots: pd.DataFrame, folder: Path) -> None:
    """Each run as a committed copy: ``<method>_seed<S>/history.csv`` and summary.json."""
    for (method, seed), rows in robots.groupby(["method", "seed"]):
        run_dir = folder / f"{method}_seed{seed}"
        run_dir.mkdir(parents=True)
        rows.assign(method=method, env_steps=rows["budget"])[
            ["birth", "name", "method", "parents", "budget", "fitness", "accepted",
             "env_steps"]].to_csv(run_dir / "history.csv", index=False)
        best = rows.loc[rows["fitness"].idxmax()]
        steps = int(rows["budget"].sum())
        write_run_summary(RunLayout(run_dir).summary, RunSummary(
            method=str(method), robots_evaluated=len(rows), robot_budget=len(rows), failed=0,
            best_robot=str(best["name"]), best_fitness=float(best["fitness"]),
            best_initial_fitness=None, accept_rate=None, env_steps=steps, wall_seconds=1.0,
            steps_per_second=float(steps), complete=True))


def test_history_copies_give_the_report_its_run_level_sections(tmp_path: Path) -> None:
    means = {"R+R": -0.9, "R+L": -0.5, "E+R": -0.8, "E+L": 0.5}
    robots = synthetic_robots(np.random.default_rng(7), means=means, seeds=(0, 1),
                              n_robots=8, sd=0.1, seed_sd=0.02, population_size=4)
    write_copies(robots, tmp_path / "runs")
    runs = load_histories(tmp_path / "runs", first=6)
    assert sorted(runs.runs["seed"]) == [0, 0, 0, 0, 1, 1, 1, 1]
    assert (runs.robots.groupby("run").size() == 6).all() and runs.curves.empty
    tables = ablation_tables(runs.robots, Resampling.seeded(0, 100), population_size=4)
    assert tables.nested is not None
    text = ablation_markdown(runs, tables, {}, tmp_path)
    assert "## Runs as the unit" in text and "### Power: GA seeds needed" in text
    assert "| E+L vs R+L | Welch t on run means | 2/2 |" in text
    assert "E+L > R+L" in text, "a planted difference of 1 with 2 runs each is decided"
    written = write_nested_tables(tables.nested, tmp_path)
    assert len(pd.read_csv(written[0])) == 8, "one row per run"
    tests = pd.read_csv(written[1])
    assert set(tests["test"]) == {"welch_run_level", "mixed_model"}
    assert pd.read_csv(written[2])["seeds"].ge(2).all()


def test_history_copy_without_a_seed_is_named(tmp_path: Path, capsys: pytest.CaptureFixture[str]
                                              ) -> None:
    robots = synthetic_robots(np.random.default_rng(8), means={"E+L": 0.0}, n_robots=4)
    write_copies(robots, tmp_path)
    (tmp_path / "E+L_seed0").rename(tmp_path / "best_run")
    assert main([str(tmp_path / "best_run"), "--history-only", "--out",
                 str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "best_run" in err and "seed<S>" in err and len(err.strip().splitlines()) == 1


def test_power_cli_prints_the_seeds_for_the_observed_difference(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    robots = synthetic_robots(np.random.default_rng(10), means={"R+L": 0.0, "E+L": 0.5},
                              seeds=(0, 1, 2), n_robots=6, sd=0.3, seed_sd=0.2)
    write_copies(robots, tmp_path / "runs")
    assert power.main([str(tmp_path / "runs"), "--history-only"]) == 0
    headline, *table = capsys.readouterr().out.splitlines()
    seeds = int(headline.split(": ")[1].split()[0])
    assert headline.startswith("E+L − R+L = ") and seeds >= 2
    assert len(table) == 2 + 4, "header, rule, 2 differences × 2 run lengths"
    assert power.main([str(tmp_path / "runs"), "--history-only", "--pair", "E+L", "E+R"]) == 2
    assert "E+R" in capsys.readouterr().err


def test_one_seed_per_method_leaves_the_run_level_sections_out() -> None:
    robots = synthetic_robots(np.random.default_rng(9), n_robots=6, population_size=3)
    tables = ablation_tables(robots, Resampling.seeded(0, 100))
    assert tables.nested is None
    assert any("two or more GA seeds" in note for note in tables.notes)


# ---------------------------------------------------------------- the fifth arm, E+L+I


def test_the_fifth_arm_gets_its_own_question_and_leaves_the_papers_family_alone(
        tmp_path: Path) -> None:
    means = {"R+R": -0.9, "R+L": -0.5, "E+R": -0.8, "E+L": 0.5}
    four = synthetic_robots(np.random.default_rng(11), means=means, seeds=(0, 1, 2),
                            n_robots=8, sd=0.3, seed_sd=0.1, population_size=4)
    fifth = synthetic_robots(np.random.default_rng(12), means={"E+L+I": 1.5}, seeds=(0, 1, 2),
                             n_robots=8, sd=0.3, seed_sd=0.1, population_size=4)
    without, with_it = (ablation_tables(robots, Resampling.seeded(0, 100), population_size=4)
                        for robots in (four, pd.concat([four, fifth], ignore_index=True)))
    assert without.nested is not None and with_it.nested is not None
    question = "E+L+I vs E+L"
    for test in ("run_tests", "mixed"):
        before, after = getattr(without.nested, test), getattr(with_it.nested, test)
        assert question not in set(before["question"])
        pd.testing.assert_frame_equal(after[after["question"] != question].reset_index(drop=True),
                                      before, obj=f"{test}: the paper's questions")
        extra = after[after["question"] == question]
        assert len(extra) == (3 if test == "run_tests" else 1), "one per run summary"
        assert (extra["p_holm"] == extra["p"]).all(), "its own test, outside the Holm family"
        assert extra["reject"].all() and (extra["estimate"] > 0.5).all(), "1.0 planted"
    # The robot-level tests, the interaction and the paper's intervals are as without it.
    pd.testing.assert_frame_equal(with_it.pairwise, without.pairwise)
    pd.testing.assert_frame_equal(with_it.interaction, without.interaction)
    pd.testing.assert_frame_equal(
        with_it.summary[with_it.summary["method"] != "E+L+I"], without.summary)
    assert list(with_it.main["method"]) == ["R+R", "R+L", "E+R", "E+L", "E+L+I"]
    assert with_it.extra_pairwise[["a", "b"]].values.tolist() == [["E+L+I", "E+L"]]
    assert without.extra_pairwise.empty
    text = ablation_markdown(load_histories_of(four, tmp_path / "four"), without, {}, tmp_path)
    assert "E+L+I" not in text
    text = ablation_markdown(load_histories_of(pd.concat([four, fifth]), tmp_path / "five"),
                             with_it, {}, tmp_path)
    assert text.startswith("# Ablation: R+R, R+L, E+R, E+L, E+L+I\n")
    assert f"| {question} | Welch t on run means | 3/3 |" in text and "E+L+I > E+L" in text
    assert "includes what its robots inherited" in text


def load_histories_of(robots: pd.DataFrame, folder: Path) -> Runs:
    """``robots`` written as committed copies and read back (the report's ``runs``)."""
    write_copies(robots, folder)
    return load_histories(folder)


def test_power_plans_the_fifth_arms_question_as_a_test_of_its_own(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    robots = synthetic_robots(np.random.default_rng(13), means={"E+L+I": 0.5, "E+L": 0.0},
                              seeds=(0, 1, 2), n_robots=6, sd=0.3, seed_sd=0.2)
    write_copies(robots, tmp_path / "runs")
    assert power.main([str(tmp_path / "runs"), "--history-only", "--pair", "E+L+I", "E+L"]) == 0
    headline = capsys.readouterr().out.splitlines()[0]
    assert headline.startswith("E+L+I − E+L = ") and "alpha = 0.05, a test of its own" in headline
