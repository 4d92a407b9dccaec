"""Synthetic robots and curves tables with a known answer, for tests and dry runs.

The tables follow :mod:`analysis.tables`. Fitness is drawn per method (and optionally
per GA seed, to make runs differ); acceptance replays the steady-state rule (an
offspring enters when it beats the population minimum). Curves follow
``y(τ) = final − (final − start)·exp(−rate·τ)`` plus Gaussian noise on an evenly spaced
grid of ``τ = env_steps / budget``, the same grid for every robot, so that a cut at a
budget fraction sees the same τ for all of them.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
import pandas as pd
from numpy.typing import ArrayLike

from analysis.early_slope import curve_fitness
from analysis.tables import METHODS, is_evolved


def synthetic_robots(
    rng: np.random.Generator,
    *,
    means: Mapping[str, float] | None = None,
    seeds: Sequence[int] = (0,),
    n_robots: int = 40,
    sd: float = 1.0,
    seed_sd: float = 0.0,
    population_size: int = 10,
    budgets: tuple[int, int] = (50_000, 250_000),
) -> pd.DataFrame:
    """A robots table: ``n_robots`` per method and seed, fitness ~ N(mean + seed effect, sd).

    Args:
        rng: Randomness.
        means: Method → mean fitness; defaults to all of :data:`METHODS` at 0.
        seeds: GA seeds; one run per method and seed.
        n_robots: Robots per run.
        sd: Robot-to-robot standard deviation.
        seed_sd: Standard deviation of a per-run offset (within-run correlation).
        population_size: Initial population, for ``accepted`` and ``parents``.
        budgets: First and last robot's budget, linear in birth order.

    Returns:
        Robots table in run and birth order.
    """
    means = dict.fromkeys(METHODS, 0.0) if means is None else dict(means)
    budget = np.linspace(*budgets, n_robots).round().astype(int)
    runs = []
    for method, mean in means.items():
        for seed in seeds:
            fitness = mean + seed_sd * rng.normal() + sd * rng.normal(size=n_robots)
            runs.append(_run_table(rng, method, seed, fitness, budget, population_size))
    return pd.concat(runs, ignore_index=True)


def _run_table(rng: np.random.Generator, method: str, seed: int, fitness: ArrayLike,
               budget: ArrayLike, population_size: int) -> pd.DataFrame:
    fitness = np.asarray(fitness, dtype=float)
    names = [f"robot-{int(v):08x}" for v in rng.integers(0, 16**8, size=len(fitness))]
    accepted, populations = steady_state(fitness, population_size)
    parents = [
        ";".join(names[p] for p in rng.choice(pop, size=2, replace=False))
        if pop and is_evolved(method) else ""
        for pop in populations
    ]
    return pd.DataFrame(dict(
        run=f"{method}-seed{seed}", method=method, seed=seed, birth=np.arange(len(names)),
        name=names, budget=budget, fitness=fitness, accepted=accepted, parents=parents,
    ))


def steady_state(
    fitness: ArrayLike, population_size: int
) -> tuple[list[bool], list[list[int]]]:
    """Replay the steady-state replacement rule on fitnesses in birth order.

    Args:
        fitness: Fitness per robot in birth order.
        population_size: Initial population size (all of them are accepted).

    Returns:
        ``accepted`` per robot, and the population (birth indices) each robot met;
        empty for the initial population.
    """
    values = np.asarray(fitness, dtype=float)
    accepted: list[bool] = []
    populations: list[list[int]] = []
    population: list[int] = []
    for i, f in enumerate(values):
        if i < population_size:
            populations.append([])
            accepted.append(True)
            population.append(i)
            continue
        populations.append(list(population))
        worst = min(population, key=lambda j: values[j])
        accepted.append(bool(f > values[worst]))
        if accepted[-1]:
            population[population.index(worst)] = i
    return accepted, populations


def synthetic_curves(
    robots: pd.DataFrame,
    rng: np.random.Generator,
    *,
    start: ArrayLike = 0.0,
    final: ArrayLike = 1.0,
    rate: ArrayLike = 3.0,
    noise: float = 0.0,
    n_batches: int = 40,
    episodes: int = 4,
) -> pd.DataFrame:
    """A curves table for ``robots``: saturating curves with per-robot parameters.

    Args:
        robots: Robots table (``run``, ``name``, ``budget``).
        rng: Randomness of the noise.
        start: Return at τ = 0, per robot (aligned with ``robots``) or one for all.
        final: Asymptote, per robot or one for all.
        rate: Rate ``c`` of ``exp(−c·τ)``, per robot or one for all.
        noise: Standard deviation of the batch mean return's noise.
        n_batches: Batches per robot, evenly spaced up to the budget.
        episodes: Episodes completed per batch.

    Returns:
        Curves table.
    """
    n = len(robots)
    start, final, rate = (np.broadcast_to(np.asarray(v, dtype=float), (n,))
                          for v in (start, final, rate))
    tau = np.arange(1, n_batches + 1) / n_batches
    y = final[:, None] - (final - start)[:, None] * np.exp(-rate[:, None] * tau[None, :])
    y = y + noise * rng.normal(size=y.shape)
    steps = (robots["budget"].to_numpy(dtype=float)[:, None] * tau[None, :]).round()
    return pd.DataFrame(dict(
        run=np.repeat(robots["run"].to_numpy(), n_batches),
        name=np.repeat(robots["name"].to_numpy(), n_batches),
        env_steps=steps.ravel().astype(int),
        **{"train/mean_return": y.ravel(), "train/episodes": episodes,
           "train/success_rate": np.nan},
    ))


def with_curve_fitness(
    robots: pd.DataFrame, curves: pd.DataFrame, population_size: int = 10
) -> pd.DataFrame:
    """``robots`` with ``fitness`` recomputed from ``curves`` (paper Eq. 8), ``accepted`` too.

    Args:
        robots: Robots table in run and birth order.
        curves: Curves table of those robots.
        population_size: Initial population size for the acceptance replay.

    Returns:
        A copy of ``robots`` with the new ``fitness`` and ``accepted``.
    """
    index = pd.MultiIndex.from_frame(robots[["run", "name"]])
    table = robots.assign(fitness=curve_fitness(curves).reindex(index).to_numpy())
    table["accepted"] = table.groupby("run", sort=False)["fitness"].transform(
        lambda f: steady_state(f, population_size)[0]
    ).astype(bool)
    return table
