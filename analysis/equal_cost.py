"""Early rejection at equal cost: evolution runs with the rule against runs without it.

    python -m analysis.equal_cost --without runs/paper_clean --with runs/paper_clean_early \\
        --out docs/results/early_rejection

Each side is a set of run directories (or folders holding them), one per GA seed; runs
of the two sides with the same seed are paired (they share their initial population).
It writes ``OUT/equal_cost.md`` with ``equal_cost.png`` and ``equal_cost_runs.csv``:

* per run: robots, stopped-early offspring, total env steps, env steps saved (what the
  stopped offspring's schedule had left), best fitness, and the final population's mean
  and minimum;
* per side, across seeds: the mean of each figure with a t-based 95 % CI, and the
  paired difference (with − without) with its CI and a paired t-test;
* the same figures of the run without the rule at the env steps the run with it used
  in all (equal cost), against the run with the rule at its end;
* the final populations of the two sides pooled (Mann–Whitney U and A12; the members of
  one population are not independent, so read it beside the per-seed test);
* best fitness so far and the population mean against cumulative env steps.

Fitness here is a fully trained robot's (an offspring stopped early never enters the
population, so its fitness so far is never a population member or a best); each
figure comes from replaying the steady state (:mod:`analysis.population`).
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd
import scipy.stats
from matplotlib.figure import Figure
from numpy.typing import NDArray

from analysis import plots, stats
from analysis.cli import report_folder, run_report
from analysis.load import Runs, load_runs
from analysis.markdown import figure_link, fmt_ci, markdown_table
from analysis.population import final_population, population_trace

REPORT = "equal_cost.md"
SIDES = ("without", "with")
"""The two sides: runs without the rule, then runs with it."""
SIDE_COLORS = {"without": "tab:blue", "with": "tab:red"}
FIGURES = ("best", "pop_mean", "pop_min", "env_steps_M")
"""Per-run figures compared across the two sides."""
STOPPED = "stopped-early"


def cost_trace(runs: Runs) -> pd.DataFrame:
    """Per robot of every run, in birth order: the cumulative env steps and the population.

    Returns:
        :func:`analysis.population.population_trace` (``pop_max`` is the best fully
        trained fitness so far) with ``seed``, ``status`` and ``env_steps`` (cumulative
        env steps up to and including the robot) added.
    """
    robots = runs.robots.sort_values(["run", "birth"])
    traces = [population_trace(rows, runs.population_sizes[str(run)])
              for run, rows in robots.groupby("run", sort=True)]
    trace = pd.concat(traces, ignore_index=True)
    merged = trace.merge(robots[["run", "birth", "seed", "status", "budget"]],
                         on=["run", "birth"], validate="one_to_one")
    merged["env_steps"] = merged.groupby("run")["budget"].cumsum()
    return merged.drop(columns="budget")


def run_table(runs: Runs, side: str, trace: pd.DataFrame) -> pd.DataFrame:
    """One row per run: its seed, status and the figures of :data:`FIGURES`.

    Args:
        runs: The runs of one side.
        side: ``"without"`` or ``"with"``.
        trace: :func:`cost_trace` of ``runs`` (its last row per run is the final
            population).
    """
    robots = runs.robots
    stopped = robots["status"] == STOPPED
    saved = (robots["scheduled_budget"] - robots["budget"]).clip(lower=0).where(stopped, 0)
    rows = []
    for run in runs.runs.itertuples(index=False):
        last = trace[trace["run"] == run.run].iloc[-1]
        mine = robots["run"] == run.run
        rows.append(dict(
            side=side, seed=int(run.seed), run=run.run, status=run.status,
            robots=int(mine.sum()), stopped_early=int((stopped & mine).sum()),
            env_steps=int(last["env_steps"]), env_steps_M=last["env_steps"] / 1e6,
            saved=int(saved[mine].sum()),
            best=float(last["pop_max"]), pop_mean=float(last["pop_mean"]),
            pop_min=float(last["pop_min"]),
        ))
    return pd.DataFrame(rows)


def at_env_steps(trace: pd.DataFrame, run: str, env_steps: float) -> tuple[pd.Series, int]:
    """A run's population after the last robot that ended within ``env_steps`` (its
    first robot if none did), and how many robots it had evaluated by then."""
    rows = trace[trace["run"] == run]
    within = rows[rows["env_steps"] <= env_steps]
    return (within.iloc[-1], len(within)) if len(within) else (rows.iloc[0], 1)


def equal_cost_table(trace: pd.DataFrame, per_run: pd.DataFrame) -> pd.DataFrame:
    """Per seed of both sides: the run without the rule (``trace``, its
    :func:`cost_trace`) when it had spent what the run with the rule spent in all,
    beside that run at its end."""
    rows = []
    for mine in per_run[per_run["side"] == "with"].itertuples(index=False):
        match = per_run[(per_run["side"] == "without") & (per_run["seed"] == mine.seed)]
        if match.empty:
            continue
        there, evaluated = at_env_steps(trace, match.iloc[0]["run"], mine.env_steps)
        rows.append(dict(seed=mine.seed, env_steps=mine.env_steps,
                         robots_with=mine.robots, robots_without=evaluated,
                         best_without=float(there["pop_max"]), best_with=mine.best,
                         pop_mean_without=float(there["pop_mean"]),
                         pop_mean_with=mine.pop_mean))
    return pd.DataFrame(rows)


def parting_table(without: Runs, with_: Runs) -> pd.DataFrame:
    """Per seed on both sides: how many first births the two runs share (the same robot
    at the same birth) and the first birth the rule stopped.

    In a serial run the two are the same run until the rule first stops an offspring.
    With several workers the GA is asynchronous, results come back in an order that
    differs from run to run, and the two can part before any stop: what follows is
    then GA-run variance as much as the rule's doing.
    """
    rows = []
    for seed, mine in with_.robots.groupby("seed"):
        theirs = without.robots[without.robots["seed"] == seed]
        if theirs.empty:
            continue
        a = mine.sort_values("birth")["name"].to_numpy()
        b = theirs.sort_values("birth")["name"].to_numpy()
        n = min(len(a), len(b))
        differ = np.flatnonzero(a[:n] != b[:n])
        stops = mine.loc[mine["status"] == STOPPED, "birth"]
        rows.append(dict(seed=int(seed), same_first_births=int(differ[0]) if len(differ) else n,
                         first_stop=int(stops.min()) if len(stops) else np.nan))
    return pd.DataFrame(rows)


def _mean_ci(x: NDArray[np.float64]) -> tuple[float, float, float]:
    """Mean and t-based 95 % CI (NaN interval below two values)."""
    if len(x) < 2 or np.ptp(x) == 0:
        mean = float(np.mean(x)) if len(x) else np.nan
        return mean, np.nan, np.nan
    ci = scipy.stats.ttest_1samp(x, 0.0).confidence_interval(0.95)
    return float(np.mean(x)), float(ci.low), float(ci.high)


def _paired(with_: NDArray[np.float64], without: NDArray[np.float64]
            ) -> tuple[float, float, float, float]:
    """Mean of the paired differences with its t CI, and the paired t-test's p."""
    mean, low, high = _mean_ci(with_ - without)
    if np.isnan(low):
        return mean, low, high, np.nan
    return mean, low, high, float(scipy.stats.ttest_rel(with_, without).pvalue)


def comparison_table(per_run: pd.DataFrame, figures: Sequence[str] = FIGURES) -> pd.DataFrame:
    """Per figure: each side's mean [CI] across seeds and the paired difference."""
    paired = per_run.pivot(index="seed", columns="side", values=list(figures)).dropna()
    rows = []
    for figure in figures:
        cells: dict[str, object] = {"figure": figure}
        for side in SIDES:
            cells[side] = fmt_ci(*_mean_ci(
                per_run.loc[per_run["side"] == side, figure].to_numpy(float)))
        if figure in paired and set(SIDES) <= set(paired[figure].columns):
            mean, low, high, p = _paired(paired[figure]["with"].to_numpy(float),
                                         paired[figure]["without"].to_numpy(float))
            cells["with - without"] = fmt_ci(mean, low, high)
            cells["paired t p"] = p
            cells["seeds"] = len(paired)
        rows.append(cells)
    return pd.DataFrame(rows)


def complete_runs(runs: Runs) -> Runs:
    """``runs`` without the runs that have not finished (their figures would still change)."""
    done = runs.runs[runs.runs["status"] == "complete"]
    keep = runs.robots["run"].isin(done["run"])
    return dataclasses.replace(runs, robots=runs.robots[keep], runs=done)


def population_test(without: Runs, with_: Runs) -> dict[str, float]:
    """Mann–Whitney U and A12 (with over without) on the pooled final populations."""
    x = np.concatenate([final_population(rows, with_.population_sizes[str(run)])["fitness"]
                        for run, rows in with_.robots.groupby("run")])
    y = np.concatenate([final_population(rows, without.population_sizes[str(run)])["fitness"]
                        for run, rows in without.robots.groupby("run")])
    test = scipy.stats.mannwhitneyu(x, y, alternative="two-sided")
    return dict(n_with=len(x), n_without=len(y), u=float(test.statistic),
                p=float(test.pvalue), a12=stats.vargha_delaney_a12(x, y))


def plot_equal_cost(traces: dict[str, pd.DataFrame], *, path: str | Path | None = None
                    ) -> Figure:
    """Best fitness so far and population mean against env steps, one line per run."""
    fig, axes = plots.new_figure(2, sharey=False)
    for side, trace in traces.items():
        for i, (_, rows) in enumerate(trace.groupby("run")):
            label = f"{side} early rejection" if i == 0 else None
            for ax, column in zip(axes, ("pop_max", "pop_mean"), strict=True):
                ax.step(rows["env_steps"], rows[column], where="post",
                        color=SIDE_COLORS[side], label=label)
    axes[0].set(xlabel="env steps (cumulative)", ylabel="best fitness so far")
    axes[1].set(xlabel="env steps (cumulative)", ylabel="population mean fitness")
    axes[0].legend(loc="lower right")
    return plots.finish(fig, path)


def write_equal_cost(without_paths: Sequence[Path], with_paths: Sequence[Path],
                     out: str | Path) -> Path:
    """Load both sides, write ``out/equal_cost.md`` with its figure and CSV, return it."""
    out = report_folder(out)
    sides = {"without": load_runs(without_paths), "with": load_runs(with_paths)}
    traces = {side: cost_trace(runs) for side, runs in sides.items()}
    per_run = pd.concat([run_table(runs, side, traces[side]) for side, runs in sides.items()],
                        ignore_index=True).sort_values(["seed", "side"], ignore_index=True)
    per_run.to_csv(out / "equal_cost_runs.csv", index=False)
    figure = out / "equal_cost.png"
    plot_equal_cost(traces, path=figure)
    report = out / REPORT
    report.write_text(_markdown(sides, traces["without"], per_run, figure, out),
                      encoding="utf-8")
    return report


def _markdown(sides: dict[str, Runs], trace_without: pd.DataFrame, per_run: pd.DataFrame,
              figure: Path, out: Path) -> str:
    parts = [
        "# Early rejection at equal cost\n",
        "Runs without the rule against runs with it (`analysis.equal_cost`). Fitness is a "
        "fully trained robot's: an offspring stopped early never enters the population. "
        "`saved` is the env steps the stopped offspring's schedule had left. Only "
        "complete runs enter the comparisons.\n",
        "## Runs\n", markdown_table(per_run),
        *_comparison_markdown({side: complete_runs(runs) for side, runs in sides.items()},
                              trace_without, per_run[per_run["status"] == "complete"]),
        figure_link(figure, out, "best fitness so far and population mean against env steps"),
    ]
    notes = [n for runs in sides.values() for n in runs.notes]
    if notes:
        parts += ["## Notes on the input\n", *(f"- {n}\n" for n in notes)]
    return "\n".join(parts)


def _comparison_markdown(sides: dict[str, Runs], trace_without: pd.DataFrame,
                         done: pd.DataFrame) -> list[str]:
    """The comparison sections over complete runs, or why there are none yet."""
    if any(done["side"].eq(side).sum() == 0 for side in SIDES):
        return ["_No complete run on both sides yet: no comparison._\n"]
    test = population_test(sides["without"], sides["with"])
    without_steps = done.loc[done["side"] == "without", "env_steps"].mean()
    with_steps = done.loc[done["side"] == "with", "env_steps"].mean()
    return [
        "## Across seeds (mean [t 95 % CI]; difference paired by seed)\n",
        markdown_table(comparison_table(done)),
        f"Whole schedule (mean over complete runs): {without_steps:,.0f} env steps without "
        f"the rule, {with_steps:,.0f} with it ({without_steps / with_steps:.2f}x fewer).\n",
        "## At equal cost\n",
        "The run without the rule when it had spent what the run with it spent in all "
        "(and the robots it had evaluated by then), beside the run with the rule at its "
        "end.\n",
        markdown_table(equal_cost_table(trace_without, done)),
        "## Where the paired runs part\n",
        "`same_first_births`: births at which both runs evaluated the same robot before "
        "they first differ; `first_stop`: the first birth the rule stopped. Where the runs "
        "part before the first stop (asynchronous evaluation with several workers), the "
        "per-seed difference is GA-run variance as much as the rule's doing; with "
        "`executor=serial` they part only at the first stop.\n",
        markdown_table(parting_table(sides["without"], sides["with"])),
        "## Final populations pooled\n",
        f"Mann–Whitney U = {test['u']:.1f}, p = {test['p']:.3g}, A12 (with over without) "
        f"= {test['a12']:.2f} ({stats.a12_magnitude(test['a12'])}), "
        f"{test['n_with']} and {test['n_without']} members. The members of one population "
        "are not independent draws, so this test overstates its power; the paired "
        "per-seed test above is the conservative one.\n",
    ]


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m analysis.equal_cost --without RUN... --with RUN... --out DIR``."""
    cli = argparse.ArgumentParser(
        prog="python -m analysis.equal_cost",
        description="Evolution with early rejection against without it, at equal cost.")
    cli.add_argument("--without", nargs="+", type=Path, required=True,
                     help="run directories without the rule (or folders holding them)")
    cli.add_argument("--with", dest="with_", nargs="+", type=Path, required=True,
                     help="run directories with the rule (or folders holding them)")
    cli.add_argument("--out", type=Path, required=True, help="report folder (created)")
    args = cli.parse_args(argv)
    return run_report(lambda: write_equal_cost(args.without, args.with_, args.out))


if __name__ == "__main__":
    sys.exit(main())
