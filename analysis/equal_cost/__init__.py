"""Equal cost: evolution runs of two arms compared at the env steps they spent, paired by
GA seed.

A change to the GA that makes a run cheaper (early rejection stops hopeless offspring;
policy inheritance trains an inheriting offspring for a share of its budget) is fair to
judge only at equal cost: what each run had found by the time it had spent E env steps.
The runs of the two arms ("without" the change and "with" it) that share a GA seed
share their initial population, so they pair. The comparison, written once here:

* a run's **cost trace** (:func:`analysis.population.cost_trace`): per evaluation in the
  order the GA applied it, the cumulative env steps, the best fitness so far and the
  population's mean; the uses here add ``arm`` and ``seed``;
* :func:`at_env_steps`: a run read at a cost;
* :func:`equal_cost_table`: per seed, both arms' runs read at one cost E;
* :func:`plot_equal_cost`: every run's best so far and population mean against env
  steps (:func:`analysis.plots.plot_cost_traces`).

Its two uses, each with its computation, writer and command line:

* :mod:`analysis.equal_cost.early_rejection`: runs with the early-rejection rule against
  runs without it, ``python -m analysis.equal_cost --without RUN... --with RUN... --out
  DIR`` (or ``python -m analysis equal_cost ...``);
* :mod:`analysis.equal_cost.inheritance`: runs with policy inheritance against runs
  without it, ``python -m analysis.inheritance RUNS... --out DIR`` (or
  ``python -m analysis inheritance ...``).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np
import pandas as pd
from matplotlib.figure import Figure

from analysis import plots

ARMS = ("without", "with")
"""The two arms: runs without the change, then runs with it."""
ARM_COLORS = {"without": "tab:blue", "with": "tab:red"}
PANELS = (("best", "best fitness so far"), ("pop_mean", "population mean fitness"))
"""The figure's panels: the trace's column and its label."""
AT_COST = ("robots", "env_steps", "best", "pop_mean")
"""What :func:`equal_cost_table` gives of each arm's run at the cost."""


def at_env_steps(trace: pd.DataFrame, run: str, env_steps: float) -> tuple[pd.Series, int]:
    """A run's trace row after the last evaluation that ended within ``env_steps`` (its
    first if none did), and how many evaluations it had made by then."""
    rows = trace[trace["run"] == run]
    within = rows[rows["env_steps"] <= env_steps]
    return (within.iloc[-1], len(within)) if len(within) else (rows.iloc[0], 1)


def _first_reaching(trace: pd.DataFrame, run: str, target: float) -> float:
    """Cumulative env steps at the first row of ``run`` whose best reaches ``target``."""
    mine = trace[trace["run"] == run]
    reached = mine[mine["best"] >= target]
    return float(reached["env_steps"].iloc[0]) if len(reached) else np.nan


def steps_to_target(trace: pd.DataFrame) -> pd.DataFrame:
    """Per seed with a run of each arm: the env steps each needed to reach the final
    best fitness of the run without the change (NaN if never), and as a share of what
    the run without spent in all."""
    ends = trace.groupby("run").tail(1).set_index(["seed", "arm"])
    rows = []
    for seed in sorted(ends.index.get_level_values("seed").unique()):
        if not all((seed, m) in ends.index for m in ARMS):
            continue
        w, wo = ends.loc[(seed, "with")], ends.loc[(seed, "without")]
        target, total = float(wo["best"]), float(wo["env_steps"])
        with_steps = _first_reaching(trace, str(w["run"]), target)
        without_steps = _first_reaching(trace, str(wo["run"]), target)
        rows.append(dict(seed=int(seed), target=target, without_total=int(total),
                         with_total=int(w["env_steps"]), reached=not np.isnan(with_steps),
                         with_steps_to_target=with_steps, with_ratio=with_steps / total,
                         without_steps_to_target=without_steps,
                         without_ratio=without_steps / total))
    return pd.DataFrame(rows)


def equal_cost_table(trace: pd.DataFrame, cost: float | Mapping[int, float]) -> pd.DataFrame:
    """Per GA seed with a run of each arm: both runs read at the cost E.

    Args:
        trace: The cost traces of the runs of both arms (``run``, unique across the
            arms, ``arm``, ``seed``, ``env_steps``, ``best``, ``pop_mean``).
        cost: E: one for every seed, or per seed (a seed without one is left out).

    Returns:
        ``seed``, ``E``, and per arm (with, then without) ``robots_<arm>`` (evaluations
        by then), ``env_steps_<arm>`` (spent by then), ``best_<arm>`` and
        ``pop_mean_<arm>``; one row per seed, seeds ascending (the first run of an arm
        where a seed has two).
    """
    rows = []
    for seed, runs in trace.drop_duplicates("run").groupby("seed", sort=True):
        first = runs.drop_duplicates("arm")
        run_of = dict(zip(first["arm"], first["run"], strict=True))
        at = cost.get(int(seed)) if isinstance(cost, Mapping) else cost
        if at is None or not set(ARMS) <= run_of.keys():
            continue
        row: dict[str, object] = {"seed": int(seed), "E": at}
        for arm in ARMS[::-1]:
            there, robots = at_env_steps(trace, run_of[arm], at)
            row |= {f"robots_{arm}": robots, f"env_steps_{arm}": int(there["env_steps"]),
                    f"best_{arm}": float(there["best"]),
                    f"pop_mean_{arm}": float(there["pop_mean"])}
        rows.append(row)
    columns = ["seed", "E", *(f"{what}_{arm}" for arm in ARMS[::-1] for what in AT_COST)]
    return pd.DataFrame(rows, columns=columns)


def plot_equal_cost(trace: pd.DataFrame, *, legend: str, xlabel: str = "env steps (cumulative)",
                    cost: float | None = None, path: str | Path | None = None) -> Figure:
    """Best fitness so far and population mean against env steps, one line per run
    coloured by its arm (``legend``: its label, ``"{} early rejection"``), and E marked
    where ``cost`` is given."""
    return plots.plot_cost_traces(trace, by="arm", colors=ARM_COLORS, legend=legend,
                                  panels=PANELS, xlabel=xlabel, mark=cost, path=path)
