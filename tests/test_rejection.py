"""analysis.rejection: the rule replayed on committed runs, the body measures, and the
bias test, which must flag a rule that stops bodies for their shape and clear one that
stops them for their fitness."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from analysis.rejection import bias, main, modules_changed
from evo.robot import load_robot, parse_robot

RUNS = Path(__file__).resolve().parents[1] / "docs" / "results" / "ablation" / "runs"


def offspring(stop_by: str, n: int = 400, seed: int = 0) -> pd.DataFrame:
    """Planted offspring: bodies and fitness drawn independently; stopped by how far the
    fitness lies below the minimum (``fitness``) or by module count (``modules``)."""
    rng = np.random.default_rng(seed)
    modules = rng.integers(3, 25, n)
    excess = rng.normal(0.3, 0.6, n)
    if stop_by == "fitness":
        stopped = excess + rng.normal(0, 0.2, n) < -0.3
    else:
        stopped = (modules > 14) & (rng.random(n) < 0.6)
    return pd.DataFrame(dict(stopped=stopped, fitness=excess - 0.5, threshold=-0.5,
                             modules=modules, motors=rng.integers(0, 5, n),
                             pivots=rng.integers(0, 5, n), changed=rng.integers(0, 12, n)))


def test_a_rule_that_stops_large_bodies_is_flagged() -> None:
    table = bias(offspring("modules")).set_index("measure")
    assert table.loc["modules", "p_holm"] < 0.01 and table.loc["modules", "coef"] > 0, table
    assert (table.drop(index="modules")["p_holm"] > 0.05).all(), table


def test_a_rule_that_stops_by_fitness_alone_is_cleared() -> None:
    planted = offspring("fitness")
    assert 0.1 < planted["stopped"].mean() < 0.5, "the planted rule stops some, not most"
    table = bias(planted)
    assert (table["p_holm"] > 0.05).all(), table


def test_modules_changed_counts_what_crossover_swapped() -> None:
    car = load_robot(Path("robots/four_wheeler.json"))
    assert modules_changed(car, car) == 0
    bare = parse_robot({"format": "evo.robot/1", "root": {"type": "brain", "children": [
        {"face": 1, "rotation": 180, "module": {"type": "motor", "children": [
            {"face": 2, "module": {"type": "wheel"}}, {"face": 3, "module": {"type": "wheel"}}]}}
    ]}})
    # the four-wheeler's front branch: pivot, motor and its two wheels
    assert modules_changed(car, bare) == modules_changed(bare, car) == 4


@pytest.mark.slow
def test_the_study_on_committed_runs_writes_its_table_figure_and_rows(tmp_path: Path) -> None:
    runs = [RUNS / "E+L+I_seed3", RUNS / "E+L+I_seed4"]
    assert main([*map(str, runs), "--first", "60", "--checkpoints", "0.4", "--margin", "0.5",
                 "--out", str(tmp_path)]) == 0
    rows = pd.read_csv(tmp_path / "offspring.csv")
    assert len(rows) == 80 and set(rows["run"]) == {"E+L+I_seed3", "E+L+I_seed4"}
    assert rows["stopped"].any() and not rows["stopped"].all()
    assert (rows[["modules", "motors", "pivots"]] >= 0).all().all()
    assert rows["changed"].notna().all(), "every offspring's parents are on file"
    text = (tmp_path / "bias.md").read_text()
    assert "| modules |" in text and "false_rejections" in text
    assert (tmp_path / "bias.png").stat().st_size > 10_000


def test_bad_rule_settings_are_named(capsys: pytest.CaptureFixture[str]) -> None:
    assert main([str(RUNS / "E+L+I_seed3"), "--predictor", "slope", "--out", "x"]) == 2
    assert "predictor must be one of" in capsys.readouterr().err
