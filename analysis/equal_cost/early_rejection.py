"""Early rejection at equal cost: evolution runs with the rule against runs without it
(a use of the comparison of :mod:`analysis.equal_cost`).

    python -m analysis.equal_cost --without runs/paper_clean --with runs/paper_clean_early \\
        --out docs/results/early_rejection [--first N]

Each side is a set of run directories (or folders holding them), one per GA seed; runs
of the two sides with the same seed are paired (they share their initial population);
``--first N`` compares each run's first N robots only, so that runs of different lengths
compare over the same births.
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
figure comes from replaying the steady state (:mod:`analysis.population`), in birth
order. :func:`early_rejection_tables` computes every table, :func:`write_equal_cost`
writes them, :func:`main` is the command line.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
import scipy.stats

from analysis.cli import report_folder, run_report
from analysis.equal_cost import ARMS as SIDES
from analysis.equal_cost import equal_cost_table, plot_equal_cost, steps_to_target
from analysis.load import Runs, load_runs
from analysis.markdown import figure_link, fmt_ci, fmt_number, markdown_table
from analysis.population import cost_trace, final_population, population_trace
from analysis.stats import Contrast, a12_magnitude, mean_interval, vargha_delaney_a12, wilson

REPORT = "equal_cost.md"
FIGURES = ("best", "pop_mean", "pop_min", "env_steps_M")
"""Per-run figures compared across the two sides."""
STOPPED = "stopped-early"
EQUAL_COST = ("seed", "E", "robots_with", "robots_without", "best_without", "best_with",
              "pop_mean_without", "pop_mean_with")
"""The columns of :func:`analysis.equal_cost.equal_cost_table` the report shows."""


def side_trace(runs: Runs, side: str) -> pd.DataFrame:
    """Per robot of every run of one side, in birth order: its cost trace.

    Returns:
        :func:`analysis.population.population_trace` (``best`` is ``pop_max``, the best
        fully trained fitness so far) with ``arm`` (``side``), ``seed``, ``status`` and
        ``env_steps`` (cumulative env steps up to and including the robot) added; ``run``
        is ``<side>/<run>``, as the two sides' run directories may share a name.
    """
    robots = runs.robots.sort_values(["run", "birth"])
    traces = [population_trace(rows, runs.population_sizes[str(run)])
              for run, rows in robots.groupby("run", sort=True)]
    trace = pd.concat(traces, ignore_index=True)
    merged = trace.merge(robots[["run", "birth", "seed", "status", "budget"]],
                         on=["run", "birth"], validate="one_to_one")
    merged["run"] = side + "/" + merged["run"].astype(str)
    merged.insert(1, "arm", side)
    return cost_trace(merged, steps="budget", best="pop_max").drop(columns="budget")


def run_table(runs: Runs, side: str, trace: pd.DataFrame) -> pd.DataFrame:
    """One row per run: its seed, status and the figures of :data:`FIGURES`.

    Args:
        runs: The runs of one side.
        side: ``"without"`` or ``"with"``.
        trace: :func:`side_trace` of ``runs`` (its last row per run is the final
            population).
    """
    robots = runs.robots
    stopped = robots["status"] == STOPPED
    saved = (robots["scheduled_budget"] - robots["budget"]).clip(lower=0).where(stopped, 0)
    rows = []
    for run in runs.runs.itertuples(index=False):
        last = trace[trace["run"] == f"{side}/{run.run}"].iloc[-1]
        mine = robots["run"] == run.run
        rows.append(dict(
            side=side, seed=int(run.seed), run=run.run, status=run.status,
            robots=int(mine.sum()), stopped_early=int((stopped & mine).sum()),
            env_steps=int(last["env_steps"]), env_steps_M=last["env_steps"] / 1e6,
            saved=int(saved[mine].sum()),
            best=float(last["best"]), pop_mean=float(last["pop_mean"]),
            pop_min=float(last["pop_min"]),
        ))
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
    for seed, mine, theirs in _paired(without, with_):
        stops = mine.loc[mine["status"] == STOPPED, "birth"]
        rows.append(dict(seed=int(seed), same_first_births=_same_first_births(mine, theirs),
                         first_stop=int(stops.min()) if len(stops) else np.nan))
    return pd.DataFrame(rows)


def _paired(without: Runs, with_: Runs) -> Iterator[tuple[int, pd.DataFrame, pd.DataFrame]]:
    """Per seed with a run on both sides: the seed, the robots with the rule and those
    without it, each in birth order."""
    for seed, mine in with_.robots.groupby("seed"):
        theirs = without.robots[without.robots["seed"] == seed]
        if not theirs.empty:
            yield int(seed), mine.sort_values("birth"), theirs.sort_values("birth")


def _same_first_births(mine: pd.DataFrame, theirs: pd.DataFrame) -> int:
    """How many first births (in birth order) two runs share the same robot at."""
    a, b = mine["name"].to_numpy(), theirs["name"].to_numpy()
    n = min(len(a), len(b))
    differ = np.flatnonzero(a[:n] != b[:n])
    return int(differ[0]) if len(differ) else n


def stopped_against_full(without: Runs, with_: Runs) -> pd.DataFrame:
    """Per seed: the offspring the rule stopped, judged by the paired run's full training.

    A serial run with the rule is the run without it for as long as the rule stops only
    offspring full training rejects (a rejected offspring leaves the population as it
    was): until then the run without the rule trained the same robot at the same birth
    in full, and its ``accepted`` says whether the stop was wrong. The first wrong stop
    changes the population, so births after it are not compared; nor are births after
    the two runs first evaluated different robots. ``births``: the offspring births
    compared; ``accepted``: those full training accepted; ``wrongly_stopped``: stopped
    with the rule, accepted without it.
    """
    rows = []
    for seed, mine, theirs in _paired(without, with_):
        shared = _same_first_births(mine, theirs)
        full_training = theirs["accepted"].to_numpy(bool)
        compared, wrong, accepted, stopped = 0, 0, 0, 0
        for at, row in enumerate(mine.iloc[:shared].itertuples()):
            if row.operator == "random":  # the initial population: nothing to stop
                continue
            full = bool(full_training[at])
            compared, accepted = compared + 1, accepted + full
            if row.status == STOPPED:
                stopped += 1
                wrong += full
                if full:
                    break
        rows.append(dict(seed=seed, births=compared, accepted=accepted,
                         stopped=stopped, wrongly_stopped=wrong))
    return pd.DataFrame(rows, columns=["seed", "births", "accepted", "stopped",
                                       "wrongly_stopped"])


def _cell(interval: Contrast) -> str:
    """``mean [CI]``; the mean alone where the values do not vary or are too few."""
    if interval.se > 0:
        return fmt_ci(interval.estimate, interval.ci_low, interval.ci_high)
    return fmt_number(interval.estimate)


def comparison_table(per_run: pd.DataFrame, figures: Sequence[str] = FIGURES) -> pd.DataFrame:
    """Per figure: each side's mean [t CI] across seeds and the paired difference with
    the paired t-test's p (:func:`analysis.stats.mean_interval`)."""
    paired = per_run.pivot(index="seed", columns="side", values=list(figures)).dropna()
    rows = []
    for figure in figures:
        cells: dict[str, object] = {"figure": figure}
        for side in SIDES:
            cells[side] = _cell(mean_interval(
                per_run.loc[per_run["side"] == side, figure].to_numpy(float)))
        if figure in paired and set(SIDES) <= set(paired[figure].columns):
            difference = mean_interval(paired[figure]["with"].to_numpy(float)
                                       - paired[figure]["without"].to_numpy(float))
            cells["with - without"] = _cell(difference)
            cells["paired t p"] = difference.p
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
                p=float(test.pvalue), a12=vargha_delaney_a12(x, y))


@dataclass(frozen=True)
class Comparison:
    """The comparison sections over complete runs (see :class:`EarlyRejectionTables`)."""

    across_seeds: pd.DataFrame
    equal_cost: pd.DataFrame
    parting: pd.DataFrame
    population: dict[str, float]
    env_steps: dict[str, float]
    """Per side, the mean env steps of its complete runs."""
    targets: pd.DataFrame
    """Per seed, the env steps each run needed to reach the final best fitness of the
    run without the rule (:func:`analysis.equal_cost.steps_to_target`)."""
    stops: pd.DataFrame
    """Per seed, the stopped offspring judged by the paired full training
    (:func:`stopped_against_full`)."""


@dataclass(frozen=True)
class EarlyRejectionTables:
    """Every table of the report.

    Attributes:
        sides: The runs of each side, as loaded.
        trace: :func:`side_trace` of both sides, the run without the rule first.
        runs: One row per run (:func:`run_table`), by seed and side.
        comparison: Over complete runs: :func:`comparison_table`, the two sides at
            equal cost (:func:`analysis.equal_cost.equal_cost_table`), where the paired
            runs part (:func:`parting_table`) and the final populations pooled
            (:func:`population_test`); None without a complete run on both sides.
    """

    sides: dict[str, Runs]
    trace: pd.DataFrame
    runs: pd.DataFrame
    comparison: Comparison | None


def early_rejection_tables(sides: dict[str, Runs]) -> EarlyRejectionTables:
    """The report's tables from the runs of both sides (``"without"``, ``"with"``)."""
    trace = pd.concat([side_trace(runs, side) for side, runs in sides.items()],
                      ignore_index=True)
    per_run = pd.concat([run_table(runs, side, trace[trace["arm"] == side])
                         for side, runs in sides.items()],
                        ignore_index=True).sort_values(["seed", "side"], ignore_index=True)
    done = per_run[per_run["status"] == "complete"]
    if any(done["side"].eq(side).sum() == 0 for side in SIDES):
        return EarlyRejectionTables(sides, trace, per_run, None)
    complete = {side: complete_runs(runs) for side, runs in sides.items()}
    kept = trace["run"].isin(done["side"] + "/" + done["run"].astype(str))
    with_ = done[done["side"] == "with"].drop_duplicates("seed")  # as equal_cost_table
    table = equal_cost_table(trace[kept], dict(zip(with_["seed"], with_["env_steps"],
                                                   strict=True)))
    comparison = Comparison(
        comparison_table(done), table[list(EQUAL_COST)].rename(columns={"E": "env_steps"}),
        parting_table(complete["without"], complete["with"]),
        population_test(complete["without"], complete["with"]),
        {side: done.loc[done["side"] == side, "env_steps"].mean() for side in SIDES},
        steps_to_target(trace[kept]),
        stopped_against_full(complete["without"], complete["with"]))
    return EarlyRejectionTables(sides, trace, per_run, comparison)


def write_equal_cost(without_paths: Sequence[Path], with_paths: Sequence[Path],
                     out: str | Path, first: int | None = None) -> Path:
    """Load both sides, write ``out/equal_cost.md`` with its figure and CSV, return it.
    ``first`` keeps each run's first ``first`` robots (:func:`analysis.load.load_runs`),
    so that longer runs without the rule compare over the robots the runs with it had."""
    out = report_folder(out)
    tables = early_rejection_tables({"without": load_runs(without_paths, first),
                                     "with": load_runs(with_paths, first)})
    tables.runs.to_csv(out / "equal_cost_runs.csv", index=False)
    figure = out / "equal_cost.png"
    plot_equal_cost(tables.trace, legend="{} early rejection", path=figure)
    report = out / REPORT
    report.write_text(_markdown(tables, figure, out), encoding="utf-8")
    return report


def _markdown(tables: EarlyRejectionTables, figure: Path, out: Path) -> str:
    parts = [
        "# Early rejection at equal cost\n",
        "Runs without the rule against runs with it (`analysis.equal_cost`). Fitness is a "
        "fully trained robot's: an offspring stopped early never enters the population. "
        "`saved` is the env steps the stopped offspring's schedule had left. Only "
        "complete runs enter the comparisons.\n",
        "## Runs\n", markdown_table(tables.runs),
        *(_comparison_markdown(tables.comparison) if tables.comparison is not None else
          ["_No complete run on both sides yet: no comparison._\n"]),
        figure_link(figure, out, "best fitness so far and population mean against env steps"),
    ]
    notes = [n for runs in tables.sides.values() for n in runs.notes]
    if notes:
        parts += ["## Notes on the input\n", *(f"- {n}\n" for n in notes)]
    return "\n".join(parts)


def _comparison_markdown(c: Comparison) -> list[str]:
    """The comparison sections over complete runs."""
    test, without_steps, with_steps = c.population, c.env_steps["without"], c.env_steps["with"]
    return [
        "## Across seeds (mean [t 95 % CI]; difference paired by seed)\n",
        markdown_table(c.across_seeds),
        f"Whole schedule (mean over complete runs): {without_steps:,.0f} env steps without "
        f"the rule, {with_steps:,.0f} with it ({without_steps / with_steps:.2f}x fewer).\n",
        "## At equal cost\n",
        "The run without the rule when it had spent what the run with it spent in all "
        "(and the robots it had evaluated by then), beside the run with the rule at its "
        "end.\n",
        markdown_table(c.equal_cost),
        "## Env steps to the final best of the run without the rule\n",
        "`target`: the run without the rule's final best fitness; `*_steps_to_target`: the "
        "cumulative env steps at which each run's best so far first reached it; "
        "`*_ratio`: those as a share of what the run without spent in all "
        "(`without_total`); empty where the run with the rule never reached it."
        + (f" Median `with_ratio` over the seeds that reached it: "
           f"{fmt_number(c.targets['with_ratio'].median(), 2)}."
           if c.targets["reached"].any() else "") + "\n",
        markdown_table(c.targets),
        "## Where the paired runs part\n",
        "`same_first_births`: births at which both runs evaluated the same robot before "
        "they first differ; `first_stop`: the first birth the rule stopped. Where the runs "
        "part before the first stop (asynchronous evaluation with several workers), the "
        "per-seed difference is GA-run variance as much as the rule's doing; with "
        "`executor=serial` they part only at the first stop.\n",
        markdown_table(c.parting),
        "## The stopped offspring against full training\n",
        "For as long as the rule stops only offspring that full training rejects, a "
        "serial run with it is the run without it, which trained each of those offspring "
        "in full: its `accepted` judges the stop. `births`: offspring births compared (up "
        "to the first wrong stop, or to where the runs first evaluated different robots); "
        "`accepted`: those full training accepted; `wrongly_stopped`: stopped with the "
        "rule, accepted without it.\n",
        markdown_table(c.stops),
        _false_rejections(c.stops),
        "## Final populations pooled\n",
        f"Mann–Whitney U = {test['u']:.1f}, p = {test['p']:.3g}, A12 (with over without) "
        f"= {test['a12']:.2f} ({a12_magnitude(test['a12'])}), "
        f"{test['n_with']} and {test['n_without']} members. The members of one population "
        "are not independent draws, so this test overstates its power; the paired "
        "per-seed test above is the conservative one.\n",
    ]


def _false_rejections(stops: pd.DataFrame) -> str:
    """The pooled wrongly stopped share of the accepted offspring, with its interval."""
    wrong, accepted = int(stops["wrongly_stopped"].sum()), int(stops["accepted"].sum())
    if not accepted:
        return "No compared offspring was accepted by full training.\n"
    rate, low, high = wilson(wrong, accepted)
    return (f"Pooled: {wrong} of {accepted} offspring that full training accepted were "
            f"stopped, {100 * rate:.1f} % [Wilson 95 %: {100 * low:.1f}, "
            f"{100 * high:.1f}]; {int(stops['stopped'].sum())} stops compared.\n")


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
    cli.add_argument("--first", type=int, default=None, metavar="N",
                     help="keep each run's first N robots (births below N), to compare "
                          "longer runs over the robots the shorter ones had")
    args = cli.parse_args(argv)
    return run_report(lambda: write_equal_cost(args.without, args.with_, args.out,
                                               args.first))


if __name__ == "__main__":
    sys.exit(main())
