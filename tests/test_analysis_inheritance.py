"""``analysis.inheritance`` on small run folders with known numbers (no training).

Two GA seeds x two methods, population 2. The runs without train every robot for 100
env steps; the runs with inheritance train an inheriting offspring for 50. Seed 0's
run with inheritance has two rows that arrived out of birth order. The runs of seed 0
say their method and seed in ``config.yaml``; those of seed 1 have none and are read
from their folder names (``parent_seed1``, ``off_seed1``).

E is seed 1's run with inheritance's total, 350 env steps. At E:

* seed 0: with (cum. 100, 200, 250, 300 | 400): best 4.5, mean (3.5 + 4.5) / 2 = 4.0;
  without (100, 200, 300 | 400, 500): best 3, mean (3 + 2) / 2 = 2.5;
* seed 1: with (all five rows): best 3, mean 2; without (100, 200, 300 | ...): best 5,
  mean 3.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import scipy.stats

from analysis.equal_cost.inheritance import main
from evo.run.records import HistoryRow, RunSummary, write_history, write_run_summary

Spec = list[tuple[float, int, str, str]]
"""A run's robots in birth order: (fitness, env steps, inherited_from, operator)."""

OPERATORS = {"r": "random", "x": "crossover", "f": "random-fallback"}


def parse_runs(table: str) -> dict[str, Spec]:
    """A run per line: its name, then per robot ``fitness/env steps/inherited_from/operator``
    (``-``: inherited from none; an operator by its letter in :data:`OPERATORS`)."""
    runs = {}
    for line in table.strip().splitlines():
        name, *robots = line.split()
        runs[name] = [(float(f), int(steps), "" if parent == "-" else parent, OPERATORS[op])
                      for f, steps, parent, op in (robot.split("/") for robot in robots)]
    return runs


# A robot enters a population of two when it beats the worst member.
RUNS = parse_runs("""
with_0     1.0/100/-/r  2.0/100/-/r  3.5/50/a/x   4.5/50/a/x   0.5/100/-/f
without_0  1.0/100/-/r  2.0/100/-/r  3.0/100/-/x  0.5/100/-/x  4.0/100/-/x
with_1     1.0/100/-/r  1.0/100/-/r  0.0/50/a/x   3.0/50/a/x   0.2/50/b/x
without_1  1.0/100/-/r  1.0/100/-/r  5.0/100/-/x  0.0/100/-/x  2.0/100/-/x
""")


def history(spec: Spec, births: list[int]) -> list[HistoryRow]:
    """History rows of a steady-state GA with a population of two, in ``spec``'s order."""
    population: list[float] = []
    rows = []
    for birth, (fitness, steps, inherited, operator) in zip(births, spec, strict=True):
        accepted = len(population) < 2 or fitness > min(population)
        if accepted and len(population) == 2:
            population.remove(min(population))
        if accepted:
            population.append(fitness)
        parents = () if operator.startswith("random") else ("a", "b")
        rows.append(HistoryRow(
            birth=birth, name=f"robot-{birth:08x}", method="E+L", parents=parents,
            operator=operator, budget=steps, seed=birth, fitness=fitness, accepted=accepted,
            replaced="", env_steps=steps, episodes=4, wall_seconds=1.0, error="",
            population_best=max(population), population_mean=float(np.mean(population)),
            status="trained", predicted=math.nan, inherited_from=inherited))
    return rows


def make_run(folder: Path, spec: Spec, *,
             config: str | None = None, births: list[int] | None = None) -> Path:
    folder.mkdir(parents=True)
    rows = history(spec, births or list(range(len(spec))))
    write_history(folder / "history.csv", rows)
    write_run_summary(folder / "summary.json",
                      RunSummary.of(rows, method="E+L", robot_budget=len(rows), wall_seconds=1.0))
    if config is not None:
        (folder / "config.yaml").write_text(config)
    return folder


@pytest.fixture
def runs(tmp_path: Path) -> Path:
    root = tmp_path / "inheritance"
    make_run(root / "a_seed0", RUNS["with_0"], births=[0, 1, 3, 2, 4],
             config="seed: 0\nga:\n  inheritance: parent\n  population_size: 2\n")
    make_run(root / "b_seed0", RUNS["without_0"],
             config="seed: 0\nga:\n  inheritance: off\n  population_size: 2\n")
    make_run(root / "parent_seed1", RUNS["with_1"])
    make_run(root / "off_seed1", RUNS["without_1"])
    return root


@pytest.fixture
def report(runs: Path, tmp_path: Path) -> Path:
    out = tmp_path / "out"
    assert main([str(runs), "--out", str(out), "--resamples", "200"]) == 0
    return out


def test_every_file_is_written(report: Path) -> None:
    for name in ("report.md", "runs.csv", "equal_cost.csv", "differences.csv",
                 "steps_to_target.csv", "acceptance.csv", "acceptance_tests.csv"):
        assert (report / name).stat().st_size > 0, name
    assert (report / "best_so_far.png").read_bytes()[:4] == b"\x89PNG"
    text = (report / "report.md").read_text()
    assert "python -m analysis.inheritance" in text and "--resamples 200" in text
    assert "E = 350 env steps" in text and "wide" in text


def test_runs_table_reads_method_seed_cost_and_final_population(report: Path) -> None:
    table = pd.read_csv(report / "runs.csv").set_index("run")
    assert table.loc["a_seed0", ["method", "seed"]].tolist() == ["with", 0], "from config"
    assert table.loc["off_seed1", ["method", "seed"]].tolist() == ["without", 1], "from name"
    assert table["env_steps"].to_dict() == {"a_seed0": 400, "b_seed0": 500,
                                            "parent_seed1": 350, "off_seed1": 500}
    assert table["best"].to_dict() == {"a_seed0": 4.5, "b_seed0": 4.0,
                                       "parent_seed1": 3.0, "off_seed1": 5.0}
    assert table["pop_mean"].to_dict() == {"a_seed0": 4.0, "b_seed0": 3.5,
                                           "parent_seed1": 2.0, "off_seed1": 3.5}
    assert table.loc["parent_seed1", "accept_rate_inherited"] == pytest.approx(1 / 3)
    assert table.loc["a_seed0", "accept_rate_scratch"] == 0.0
    assert table.loc["a_seed0", "out_of_birth_order"] == 2
    assert table["complete"].all()


def test_every_run_is_read_at_the_smallest_total_env_steps(report: Path) -> None:
    table = pd.read_csv(report / "equal_cost.csv").set_index("seed")
    assert (table["E"] == 350).all()
    assert table["best_with"].tolist() == [4.5, 3.0]
    assert table["best_without"].tolist() == [3.0, 5.0]
    assert table["pop_mean_with"].tolist() == [4.0, 2.0]
    assert table["pop_mean_without"].tolist() == [2.5, 3.0]
    assert table["robots_with"].tolist() == [4, 5]
    assert table["best_diff"].tolist() == [1.5, -2.0]
    assert table["best_without_end"].tolist() == [4.0, 5.0]
    assert table["pop_mean_without_end"].tolist() == [3.5, 3.5]

    differences = pd.read_csv(report / "differences.csv").set_index("column")
    best = differences.loc["best_diff"]
    low, high = scipy.stats.t.interval(0.95, 1, loc=-0.25, scale=1.75)
    assert (best["seeds"], best["mean"]) == (2, -0.25)
    assert (best["t_low"], best["t_high"]) == pytest.approx((low, high))
    assert -2.0 <= best["boot_low"] <= best["boot_high"] <= 1.5
    assert differences.loc["pop_mean_diff", "mean"] == pytest.approx(0.25)


def test_env_steps_to_the_final_best_of_the_run_without(report: Path) -> None:
    """Seed 0: the run with inheritance passes 4 at its fourth row in arrival order (300
    env steps; in birth order it would be 250); seed 1's never reaches 5."""
    table = pd.read_csv(report / "steps_to_target.csv").set_index("seed")
    assert table.loc[0, "target"] == 4.0
    assert table.loc[0, "with_steps_to_target"] == 300
    assert table.loc[0, "with_ratio"] == pytest.approx(300 / 500)
    assert table.loc[0, "without_steps_to_target"] == 500
    assert table.loc[0, "without_ratio"] == 1.0
    assert not table.loc[1, "reached"] and np.isnan(table.loc[1, "with_steps_to_target"])
    assert table.loc[1, "without_steps_to_target"] == 300
    assert table.loc[1, "without_ratio"] == pytest.approx(0.6)


def test_acceptance_of_inherited_and_from_scratch_offspring(report: Path) -> None:
    table = pd.read_csv(report / "acceptance.csv").set_index(["method", "kind"])
    assert table.loc[("with", "inherited"), ["offspring", "accepted"]].tolist() == [5, 3]
    assert table.loc[("with", "from scratch"), ["offspring", "accepted"]].tolist() == [1, 0]
    assert table.loc[("without", "from scratch"), ["offspring", "accepted"]].tolist() == [6, 4]
    assert ("without", "inherited") not in table.index
    tests = pd.read_csv(report / "acceptance_tests.csv")
    pooled = scipy.stats.fisher_exact([[3, 2], [4, 3]])
    without = scipy.stats.fisher_exact([[3, 2], [4, 2]])
    assert tests["other"].tolist() == [7, 6]
    assert tests["fisher_p"].tolist() == pytest.approx([pooled.pvalue, without.pvalue])
    assert tests["odds_ratio"].tolist() == pytest.approx([pooled.statistic, without.statistic])


def test_a_run_of_unknown_method_or_one_method_alone_is_refused(
        runs: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    make_run(runs / "other_seed2", RUNS["with_1"])
    assert main([str(runs), "--out", str(tmp_path / "o")]) == 2
    assert "other_seed2" in capsys.readouterr().err
    assert main([str(runs / "off_seed1"), "--out", str(tmp_path / "o")]) == 2
    assert "no run with inheritance" in capsys.readouterr().err
