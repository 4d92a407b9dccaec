"""The paper's figures build from synthetic tables with the expected axes, lines and points."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from analysis import plots
from analysis.synthetic import synthetic_curves, synthetic_robots


@pytest.fixture(scope="module")
def tables() -> tuple[pd.DataFrame, pd.DataFrame]:
    rng = np.random.default_rng(0)
    means = {"R+R": -0.8, "R+L": -0.5, "E+R": -0.7, "E+L": 0.5}
    robots = synthetic_robots(rng, means=means, seeds=(0, 1), n_robots=15, population_size=5)
    curves = synthetic_curves(robots, rng, final=robots["fitness"].to_numpy(), noise=0.1,
                              n_batches=10)
    return robots, curves


def test_against_baseline_draws_one_panel_per_method(
    tables: tuple[pd.DataFrame, pd.DataFrame], tmp_path: Path
) -> None:
    robots, _ = tables
    fig = plots.plot_against_baseline(robots, path=tmp_path / "fig13-15.png")
    assert [ax.get_title() for ax in fig.axes] == ["E+R vs R+R", "R+L vs R+R", "E+L vs R+R"]
    for ax in fig.axes:
        assert [len(c.get_offsets()) for c in ax.collections] == [30, 30], "2 seeds x 15"
    assert (tmp_path / "fig13-15.png").read_bytes()[:4] == b"\x89PNG"


def test_evolution_shows_every_robot_and_two_population_lines(
    tables: tuple[pd.DataFrame, pd.DataFrame],
) -> None:
    robots, _ = tables
    fig = plots.plot_evolution(robots, "E+L-seed0", population_size=5)
    (ax,) = fig.axes
    assert [line.get_label() for line in ax.lines] == ["population best", "population mean"]
    assert sum(len(c.get_offsets()) for c in ax.collections) == 15
    best = ax.lines[0].get_ydata()
    assert np.all(np.diff(best) >= 0), "the population best never falls"
    with pytest.raises(ValueError, match="pass run="):
        plots.plot_evolution(robots)


def test_learning_curves_draw_one_line_per_robot(
    tables: tuple[pd.DataFrame, pd.DataFrame],
) -> None:
    robots, curves = tables
    names = robots.loc[robots["run"] == "E+L-seed0", "name"].head(4).tolist()
    fig = plots.plot_learning_curves(curves, names, "E+L-seed0", window=3)
    (ax,) = fig.axes
    assert len(ax.lines) == 4 and all(len(line.get_xdata()) == 10 for line in ax.lines)


def test_best_so_far_draws_one_rising_line_per_run(
    tables: tuple[pd.DataFrame, pd.DataFrame], tmp_path: Path
) -> None:
    robots, _ = tables
    fig = plots.plot_best_so_far(robots, path=tmp_path / "best.png")
    (ax,) = fig.axes
    assert len(ax.lines) == robots["run"].nunique() == 8
    assert all(np.all(np.diff(line.get_ydata()) >= 0) for line in ax.lines)
    assert (tmp_path / "best.png").stat().st_size > 0
