"""The GA population over a run, replayed from a robots table, and cost traces: the best
fitness so far against the env steps spent.

A steady-state GA keeps no per-generation snapshot in the robots table, but the table
holds enough to replay it: the first ``population_size`` robots of a run form the
initial population; each later robot, in birth order, faced the population's minimum
and, where ``accepted``, replaced that minimum. With asynchronous evaluation the birth
order is the order in which results came back, which is the order the GA applied them.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from analysis.tables import require_columns


def population_trace(robots: pd.DataFrame, population_size: int = 20) -> pd.DataFrame:
    """For every robot, the population minimum it had to beat and the population after it.

    Args:
        robots: Robots table (``run``, ``birth``, ``name``, ``fitness``, ``accepted``).
        population_size: Size of the initial population (SPEC default 20).

    Returns:
        One row per robot, sorted by run and birth: ``run``, ``birth``, ``name``,
        ``threshold`` (population minimum before its evaluation; NaN for the initial
        population), and ``pop_min``, ``pop_mean``, ``pop_max`` after it was applied.
    """
    require_columns(robots, ("run", "birth", "name", "fitness", "accepted"), "robots table")
    parts = [
        _replay(run_rows.sort_values("birth"), population_size)[0]
        for _, run_rows in robots.groupby("run", sort=True)
    ]
    return pd.concat(parts, ignore_index=True)


def final_population(robots: pd.DataFrame, population_size: int = 20) -> pd.DataFrame:
    """The fitness of every member of each run's population after its last robot.

    Args:
        robots: Robots table (``run``, ``birth``, ``name``, ``fitness``, ``accepted``).
        population_size: Size of the initial population (SPEC default 20).

    Returns:
        ``run`` and ``fitness``, one row per member (``population_size`` per run that
        has that many robots), runs sorted.
    """
    require_columns(robots, ("run", "birth", "name", "fitness", "accepted"), "robots table")
    parts = [
        pd.DataFrame(dict(run=run, fitness=_replay(rows.sort_values("birth"),
                                                   population_size)[1]))
        for run, rows in robots.groupby("run", sort=True)
    ]
    return pd.concat(parts, ignore_index=True)


def _replay(rows: pd.DataFrame, population_size: int) -> tuple[pd.DataFrame, list[float]]:
    """The trace of one run's rows in birth order, and its population at the end."""
    population: list[float] = []
    threshold, pop_min, pop_mean, pop_max = [], [], [], []
    for i, (fitness, accepted) in enumerate(zip(rows["fitness"], rows["accepted"],
                                               strict=True)):
        if i < population_size:
            threshold.append(np.nan)
            population.append(float(fitness))
        else:
            worst = int(np.argmin(population))
            threshold.append(population[worst])
            if accepted:
                population[worst] = float(fitness)
        pop_min.append(min(population))
        pop_mean.append(float(np.mean(population)))
        pop_max.append(max(population))
    return pd.DataFrame(dict(
        run=rows["run"].to_numpy(), birth=rows["birth"].to_numpy(), name=rows["name"].to_numpy(),
        threshold=threshold, pop_min=pop_min, pop_mean=pop_mean, pop_max=pop_max,
    )), population


def cost_trace(rows: pd.DataFrame, *, steps: str, best: str) -> pd.DataFrame:
    """Every run's cumulative env steps and best fitness so far, row by row.

    The one trace behind every best-so-far figure and every reading at equal cost
    (:mod:`analysis.equal_cost`): what a run had found by the time it had spent so many
    env steps.

    Args:
        rows: One row per evaluation with ``run``; each run's rows in the order the GA
            applied them (birth order, or history.csv's row order).
        steps: The column of the env steps each evaluation cost.
        best: The column of a fitness: the robot's own, or its population's best after
            it.

    Returns:
        ``rows`` with ``env_steps``, the env steps its run had spent up to and including
        the row, and ``best``, the largest ``best`` of its run so far (NaN skipped).
    """
    trace = rows.copy()
    by_run = trace.groupby("run", sort=False)
    trace["env_steps"] = by_run[steps].cumsum()
    trace["best"] = by_run[best].transform(lambda v: np.fmax.accumulate(v.to_numpy(float)))
    return trace


def best_so_far(robots: pd.DataFrame) -> pd.DataFrame:
    """Best fitness found so far against the env steps spent so far, per run.

    Args:
        robots: Robots table (``run``, ``method``, ``seed``, ``birth``, ``budget``,
            ``fitness``).

    Returns:
        ``run``, ``method``, ``seed``, ``birth``, ``env_steps`` (cumulative budget up to
        and including this robot) and ``best`` (running maximum of fitness): the
        :func:`cost_trace` of the robots in birth order.
    """
    require_columns(robots, ("run", "method", "seed", "birth", "budget", "fitness"),
                    "robots table")
    rows = robots.sort_values(["run", "birth"])[["run", "method", "seed", "birth", "budget",
                                                 "fitness"]]
    trace = cost_trace(rows, steps="budget", best="fitness")
    return trace[["run", "method", "seed", "birth", "env_steps", "best"]].reset_index(drop=True)
