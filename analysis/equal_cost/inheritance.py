"""Policy inheritance at equal cost: evolution runs with ``ga.inheritance`` against runs
without it, paired by GA seed (a use of the comparison of :mod:`analysis.equal_cost`).

    python -m analysis.inheritance runs/inheritance --out docs/results/inheritance

The input is run directories, or folders holding them (``conf/exp/inheritance_laptop.yaml``
makes ``runs/inheritance/{parent,off}_seed{0,1,2}/``). A run's method is ``with`` or
``without``: from its ``config.yaml`` ``ga.inheritance`` (``off`` is without, any other
mode with), else from its folder name's prefix (``parent_``/``with_`` or
``off_``/``without_``). Its GA seed and population size come from
:func:`analysis.load.run_setting` (the config, else a name ending in ``seed<S>``). Runs
of the two methods with the same seed pair: they share their initial robots and initial
trainings.

It writes under ``--out``:

* ``runs.csv``: per run, robots, total env steps, final best fitness, final population
  mean (history's ``population_mean`` after the last row), accept rates;
* ``equal_cost.csv``: per seed, both runs read at ``E``, the smallest final cumulative
  env steps of all runs (the runs with inheritance end first: an inheriting offspring
  trains for a share of its budget), and the run without at its own end;
  ``differences.csv``: the paired differences (with − without) across seeds, each with a
  t interval and a percentile bootstrap interval over seeds;
* ``steps_to_target.csv``: per seed, the env steps the run with inheritance needed to
  reach the final best fitness of the run without, and the run without to reach it;
* ``acceptance.csv`` and ``acceptance_tests.csv``: how often inherited and from-scratch
  offspring entered the population, with Fisher's exact test over the pooled seeds;
* ``best_so_far.png`` and ``report.md``.

**Order (decision).** Cumulative env steps are summed in the row order of
``history.csv``, the order in which results arrived and the GA applied them, because
``population_best`` and ``population_mean`` are the population after each row *in that
order*; with several workers it can differ from birth order (``runs.csv`` counts the
rows out of birth order). Best fitness so far is the running maximum of
``population_best``: the best robot the GA accepted (a robot it did not accept was worse
than the population's worst).

:func:`inheritance_tables` computes every table, :func:`write_inheritance` writes them,
:func:`main` is the command line.
"""

from __future__ import annotations

import math
import shlex
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
import scipy.stats

from analysis.cli import parser, report_folder, run_report
from analysis.equal_cost import equal_cost_table, plot_equal_cost, steps_to_target
from analysis.load import (
    PathsLike,
    RunDirectoryError,
    find_run_dirs,
    read_config,
    read_history,
    run_ids,
    run_setting,
)
from analysis.markdown import figure_link, fmt_ci, fmt_number, markdown_table
from analysis.population import cost_trace
from analysis.stats import CONFIDENCE, Resampling, bootstrap_ci, mean_interval
from evo.run.layout import RunLayout
from evo.run.records import RunSummary, read_run_summary

WITHOUT, WITH = METHODS = ("without", "with")
"""A run's method: without inheritance, then with it (the arms of
:mod:`analysis.equal_cost`)."""
NAME_PREFIXES = {"parent_": WITH, "with_": WITH, "off_": WITHOUT, "without_": WITHOUT}
"""A run folder's name prefix -> its method, for a run whose config does not say."""
INITIAL_OPERATOR = "random"
"""history's ``operator`` of a robot of the initial population."""
NEEDED = ("env_steps", "population_best", "population_mean")
"""history.csv columns this analysis needs beside :func:`analysis.load.read_history`'s."""
INHERITED, SCRATCH = "inherited", "from scratch"
REPORT = "report.md"


@dataclass(frozen=True)
class InheritanceRun:
    """One run directory as this analysis reads it.

    Attributes:
        run: Its id (:func:`analysis.load.run_ids`).
        method: :data:`WITH` or :data:`WITHOUT`.
        seed: The GA seed.
        population_size: The initial population size.
        path: The run directory.
        history: Its ``history.csv`` in row order (the order results arrived);
            ``accepted`` a bool, ``inherited_from`` "" where empty or missing.
        summary: Its ``summary.json`` (None when there is none).
    """

    run: str
    method: str
    seed: int
    population_size: int
    path: Path
    history: pd.DataFrame
    summary: RunSummary | None


# ---------------------------------------------------------------- reading the runs


def method_of(run_dir: Path) -> str:
    """:data:`WITH` or :data:`WITHOUT`: from ``config.yaml``'s ``ga.inheritance``, else
    the folder name's prefix (:data:`NAME_PREFIXES`).

    Raises:
        RunDirectoryError: If neither says.
    """
    if RunLayout(run_dir).config.is_file():
        mode = read_config(run_dir).ga.get("inheritance")
        if mode is not None:  # YAML reads a bare off as False
            return WITHOUT if mode is False or str(mode) == "off" else WITH
    for prefix, method in NAME_PREFIXES.items():
        if run_dir.name.startswith(prefix):
            return method
    raise RunDirectoryError(
        f"{run_dir}: cannot tell whether it inherits: its config.yaml has no "
        f"ga.inheritance and its name starts with none of {', '.join(NAME_PREFIXES)}")


def _history(run_dir: Path) -> pd.DataFrame:
    """history.csv, checked, with ``accepted`` a bool and ``inherited_from`` text."""
    history = read_history(run_dir).copy()
    missing = [c for c in NEEDED if c not in history.columns]
    if missing:
        raise RunDirectoryError(f"{RunLayout(run_dir).history}: lacks column(s) {missing}; "
                                f"it has {list(history.columns)}")
    history["accepted"] = history["accepted"].astype(str).str.lower().eq("true")
    if "inherited_from" not in history.columns:  # recorded before the column existed
        history["inherited_from"] = ""
    history["inherited_from"] = history["inherited_from"].fillna("").astype(str)
    return history.reset_index(drop=True)


def load_inheritance_runs(paths: PathsLike) -> list[InheritanceRun]:
    """Read the runs with and without inheritance, sorted by seed and method.

    Raises:
        FileNotFoundError: If a path does not exist.
        RunDirectoryError: A run that cannot be read, two runs of one method and seed,
            or no run of one of the methods.
    """
    runs = []
    dirs = find_run_dirs(paths)
    for run, run_dir in zip(run_ids(dirs), dirs, strict=True):
        seed, population = run_setting(run_dir)
        try:
            summary = read_run_summary(RunLayout(run_dir).summary)
        except ValueError as err:
            raise RunDirectoryError(str(err)) from None
        runs.append(InheritanceRun(run, method_of(run_dir), seed, population, run_dir,
                                   _history(run_dir), summary))
    seen: dict[tuple[str, int], Path] = {}
    for r in runs:
        if (r.method, r.seed) in seen:
            raise RunDirectoryError(f"{seen[(r.method, r.seed)]} and {r.path}: two runs "
                                    f"{r.method} inheritance with GA seed {r.seed}")
        seen[(r.method, r.seed)] = r.path
    absent = [m for m in METHODS if not any(r.method == m for r in runs)]
    if absent:
        raise RunDirectoryError(f"{', '.join(map(str, dirs))}: no run {absent[0]} "
                                "inheritance; give runs with and without it")
    return sorted(runs, key=lambda r: (r.seed, METHODS.index(r.method)))


# ---------------------------------------------------------------- traces and tables


def run_trace(run: InheritanceRun) -> pd.DataFrame:
    """Per history row, in row order: the run's cost trace
    (:func:`analysis.population.cost_trace`).

    Returns:
        ``run``, ``arm`` (its method), ``seed``, ``row`` (0-based), ``birth``,
        ``env_steps`` (cumulative, this row included), ``best`` (running maximum of
        ``population_best``) and ``pop_mean`` (``population_mean``).
    """
    history = run.history
    rows = pd.DataFrame(dict(
        run=run.run, arm=run.method, seed=run.seed, row=np.arange(len(history)),
        birth=history["birth"].astype(int).to_numpy(),
        steps=pd.to_numeric(history["env_steps"], errors="coerce").fillna(0)
        .astype(np.int64).to_numpy(),
        best=pd.to_numeric(history["population_best"], errors="coerce").to_numpy(float),
        pop_mean=pd.to_numeric(history["population_mean"], errors="coerce").to_numpy(float),
    ))
    trace = cost_trace(rows, steps="steps", best="best")
    return trace[["run", "arm", "seed", "row", "birth", "env_steps", "best", "pop_mean"]]


def offspring_table(run: InheritanceRun) -> pd.DataFrame:
    """The run's offspring: rows whose ``operator`` is not ``random`` (births from
    ``population_size`` on where there is no ``operator`` column).

    Returns:
        ``method``, ``seed``, ``kind`` (:data:`INHERITED` when ``inherited_from`` names a
        parent, else :data:`SCRATCH`), ``accepted`` and ``failed``.
    """
    history = run.history
    if "operator" in history.columns:
        mask = history["operator"].fillna("").astype(str) != INITIAL_OPERATOR
    else:
        mask = history["birth"].astype(int) >= run.population_size
    rows = history[mask]
    error = rows["error"].fillna("").astype(str) if "error" in rows else pd.Series("", rows.index)
    status = rows["status"].fillna("") if "status" in rows else pd.Series("", rows.index)
    return pd.DataFrame(dict(
        method=run.method, seed=run.seed,
        kind=np.where(rows["inherited_from"] != "", INHERITED, SCRATCH),
        accepted=rows["accepted"].to_numpy(bool),
        failed=((error != "") | (status == "failed")).to_numpy(bool)))


def _rate(accepted: pd.Series) -> float:
    return float(accepted.mean()) if len(accepted) else np.nan


def runs_table(runs: Sequence[InheritanceRun], trace: pd.DataFrame) -> pd.DataFrame:
    """One row per run: its size, cost, final best and population mean, accept rates.

    ``accept_rate`` is summary.json's (offspring with parents); the per-kind rates count
    :func:`offspring_table`'s offspring, a failed evaluation as not accepted.
    """
    rows = []
    for run in runs:
        last = trace[trace["run"] == run.run].iloc[-1]
        young = offspring_table(run)
        births = run.history["birth"].astype(int).to_numpy()
        rows.append(dict(
            run=run.run, method=run.method, seed=run.seed, robots=len(run.history),
            complete=bool(run.summary and run.summary.complete),
            env_steps=int(last["env_steps"]), best=float(last["best"]),
            pop_mean=float(last["pop_mean"]),
            accept_rate=run.summary.accept_rate if run.summary else np.nan,
            offspring=len(young), inherited=int((young["kind"] == INHERITED).sum()),
            accept_rate_inherited=_rate(young.loc[young["kind"] == INHERITED, "accepted"]),
            accept_rate_scratch=_rate(young.loc[young["kind"] == SCRATCH, "accepted"]),
            out_of_birth_order=int((births != np.sort(births)).sum()),
        ))
    return pd.DataFrame(rows)


def paired_at_cost(trace: pd.DataFrame) -> tuple[pd.DataFrame, int]:
    """Per seed with both runs: both at ``E`` and the run without at its own end
    (:func:`analysis.equal_cost.equal_cost_table` at ``E`` and at the end).

    Returns:
        The table (``best_diff``, ``pop_mean_diff``: with − without at ``E``;
        ``best_with_E_minus_end``, ``pop_mean_with_E_minus_end``: with at ``E`` − without
        at its end) and ``E``, the smallest final cumulative env steps of all runs.
    """
    cost = int(trace.groupby("run")["env_steps"].max().min())
    at, end = equal_cost_table(trace, cost), equal_cost_table(trace, np.inf)
    table = pd.DataFrame(dict(
        seed=at["seed"], E=at["E"], robots_with=at["robots_with"],
        robots_without=at["robots_without"], best_with=at["best_with"],
        best_without=at["best_without"], best_diff=at["best_with"] - at["best_without"],
        pop_mean_with=at["pop_mean_with"], pop_mean_without=at["pop_mean_without"],
        pop_mean_diff=at["pop_mean_with"] - at["pop_mean_without"],
        env_steps_without_end=end["env_steps_without"], best_without_end=end["best_without"],
        pop_mean_without_end=end["pop_mean_without"],
        best_with_E_minus_end=at["best_with"] - end["best_without"],
        pop_mean_with_E_minus_end=at["pop_mean_with"] - end["pop_mean_without"]))
    return table, cost


# ---------------------------------------------------------------- statistics


DIFFERENCES = (
    ("best_diff", "best fitness at E: with − without"),
    ("pop_mean_diff", "population mean at E: with − without"),
    ("best_with_E_minus_end", "best fitness: with at E − without at its end"),
    ("pop_mean_with_E_minus_end", "population mean: with at E − without at its end"),
)
"""The paired differences compared across seeds: column of the equal-cost table, label."""


def differences_table(paired: pd.DataFrame, resampling: Resampling) -> pd.DataFrame:
    """Per difference of :data:`DIFFERENCES`: seeds, mean, t interval and p
    (:func:`analysis.stats.mean_interval`), and a percentile bootstrap interval of the
    mean over seeds (:func:`analysis.stats.bootstrap_ci`)."""
    rows = []
    for column, label in DIFFERENCES:
        d = paired[column].to_numpy(float) if column in paired else np.array([])
        d = d[~np.isnan(d)]
        t = mean_interval(d)
        boot = bootstrap_ci([d], np.mean, resampling) if len(d) >= 2 else (np.nan, np.nan)
        rows.append(dict(difference=label, column=column, seeds=len(d), mean=t.estimate,
                         t_low=t.ci_low, t_high=t.ci_high, t_p=t.p, boot_low=boot[0],
                         boot_high=boot[1]))
    return pd.DataFrame(rows)


def acceptance_table(runs: Sequence[InheritanceRun]) -> pd.DataFrame:
    """Per method and kind of offspring (inherited, from scratch), pooled over seeds:
    offspring, accepted, failed and the accept rate (a failed one counts as not
    accepted)."""
    young = pd.concat([offspring_table(r) for r in runs], ignore_index=True)
    rows = []
    for method in METHODS:
        for kind in (INHERITED, SCRATCH):
            mine = young[(young["method"] == method) & (young["kind"] == kind)]
            if len(mine) or kind == SCRATCH:
                rows.append(dict(method=method, kind=kind, offspring=len(mine),
                                 accepted=int(mine["accepted"].sum()),
                                 failed=int(mine["failed"].sum()), rate=_rate(mine["accepted"])))
    return pd.DataFrame(rows)


def acceptance_tests(acceptance: pd.DataFrame) -> pd.DataFrame:
    """Fisher's exact test (two-sided) of inherited offspring's accept rate against
    from-scratch offspring's: of both kinds of run pooled, and of the runs without."""
    def pool(rows: pd.DataFrame) -> tuple[int, int]:
        return int(rows["accepted"].sum()), int(rows["offspring"].sum())

    inherited = pool(acceptance[acceptance["kind"] == INHERITED])
    scratch = acceptance[acceptance["kind"] == SCRATCH]
    without = scratch[scratch["method"] == WITHOUT]
    rows = []
    for label, other in (("from scratch, both kinds of run", pool(scratch)),
                         ("from scratch, runs without", pool(without))):
        odds, p = np.nan, np.nan
        if inherited[1] and other[1]:
            table = [[inherited[0], inherited[1] - inherited[0]], [other[0], other[1] - other[0]]]
            result = scipy.stats.fisher_exact(table)
            odds, p = float(result.statistic), float(result.pvalue)
        rows.append(dict(against=label, inherited_accepted=inherited[0],
                         inherited=inherited[1], other_accepted=other[0], other=other[1],
                         odds_ratio=odds, fisher_p=p))
    return pd.DataFrame(rows)


# ---------------------------------------------------------------- figure and report


@dataclass(frozen=True)
class Tables:
    """Every table of the report (see the module docstring)."""

    runs: pd.DataFrame
    equal_cost: pd.DataFrame
    cost: int
    differences: pd.DataFrame
    steps_to_target: pd.DataFrame
    acceptance: pd.DataFrame
    acceptance_tests: pd.DataFrame


def inheritance_tables(runs: Sequence[InheritanceRun], trace: pd.DataFrame,
                       resampling: Resampling) -> Tables:
    """The report's tables from the runs and their :func:`run_trace`."""
    paired, cost = paired_at_cost(trace)
    acceptance = acceptance_table(runs)
    return Tables(runs_table(runs, trace), paired, cost, differences_table(paired, resampling),
                  steps_to_target(trace), acceptance, acceptance_tests(acceptance))


def write_inheritance(paths: PathsLike, out: str | Path, resampling: Resampling,
                      command: str) -> Path:
    """Load the runs, write every table, the figure and ``out/report.md``; return it."""
    runs = load_inheritance_runs(paths)
    out = report_folder(out)
    trace = pd.concat([run_trace(r) for r in runs], ignore_index=True)
    tables = inheritance_tables(runs, trace, resampling)
    for name in ("runs", "equal_cost", "differences", "steps_to_target", "acceptance",
                 "acceptance_tests"):
        getattr(tables, name).to_csv(out / f"{name}.csv", index=False)
    figure = out / "best_so_far.png"
    plot_equal_cost(trace, legend="{} inheritance", cost=tables.cost, path=figure,
                    xlabel="env steps (cumulative, history.csv row order)")
    report = out / REPORT
    report.write_text(report_markdown(tables, runs, command, figure_link(
        figure, out, "best fitness so far and population mean against env steps")),
        encoding="utf-8")
    return report


def _reading(row: pd.Series, what: str) -> str:
    """One sentence on a paired difference of :func:`differences_table`."""
    if row["seeds"] < 2:
        return f"- {what}: {fmt_number(row['mean'])} ({row['seeds']} seed, no interval).\n"
    side = ("higher with inheritance" if row["t_low"] > 0 else
            "lower with inheritance" if row["t_high"] < 0 else "no clear difference")
    return (f"- {what}: mean difference {fmt_ci(row['mean'], row['t_low'], row['t_high'])} "
            f"(t {CONFIDENCE:.0%} CI, {row['seeds']} seeds): {side}"
            f"{'' if side != 'no clear difference' else ' (the interval includes 0)'}.\n")


def _statements(tables: Tables) -> list[str]:
    """Plain sentences on what the numbers say."""
    lines = [_reading(row, str(row["difference"]))
             for _, row in tables.differences.iterrows()]
    targets = tables.steps_to_target
    if len(targets):
        reached = targets[targets["reached"]]
        lines.append(
            f"- The run with inheritance reached the final best fitness of the run without "
            f"in {len(reached)} of {len(targets)} seeds"
            + (f", at {fmt_number(reached['with_ratio'].median(), 2)} (median) of the env "
               "steps the run without spent in all" if len(reached) else "") + "; the runs "
            "without reached their own final best at "
            f"{fmt_number(targets['without_ratio'].median(), 2)} (median) of theirs.\n")
    tests = tables.acceptance_tests
    if len(tests) and not np.isnan(tests["fisher_p"].iloc[0]):
        t = tests.iloc[0]
        lines.append(
            f"- Inherited offspring were accepted {t['inherited_accepted']} of "
            f"{t['inherited']} times ({t['inherited_accepted'] / t['inherited']:.0%}), "
            f"from-scratch offspring {t['other_accepted']} of {t['other']} "
            f"({t['other_accepted'] / t['other']:.0%}); Fisher's exact p = "
            f"{t['fisher_p']:.3g}. The populations they faced differ, so this compares "
            "the kinds of offspring in their own runs, not at equal footing.\n")
    elif len(tests):
        lines.append("- No offspring inherited a policy (or none started from scratch): no "
                     "acceptance test.\n")
    n = int(tables.differences["seeds"].max()) if len(tables.differences) else 0
    lines.append(
        f"- With {n} seeds the t intervals are wide (t quantile "
        f"{fmt_number(scipy.stats.t.ppf(0.975, max(n - 1, 1)), 2)}), and the bootstrap "
        f"interval of {n} values has at most {_distinct_resamples(n)} distinct resamples, "
        "so it is too narrow to trust: read it as a description, the t interval as the "
        "test.\n")
    return lines


def _distinct_resamples(n: int) -> int:
    """Distinct multisets of size ``n`` drawn from ``n`` values."""
    return math.comb(2 * n - 1, n) if n else 0


def report_markdown(tables: Tables, runs: Sequence[InheritanceRun], command: str,
                    figure: str) -> str:
    """``report.md``: the command, what the numbers say, the tables and the figure."""
    incomplete = [r.run for r in runs if not (r.summary and r.summary.complete)]
    order = int(tables.runs["out_of_birth_order"].sum())
    return "\n".join([
        "# Policy inheritance at equal cost\n",
        f"```bash\n{command}\n```\n",
        f"Runs with inheritance (`ga.inheritance` not off) against runs without, paired by "
        f"GA seed. E = {tables.cost:,} env steps, the smallest final cumulative env steps "
        "of all runs (a run with inheritance ends first: an inheriting offspring trains "
        "for a share of its budget). Cumulative env steps follow history.csv's row order "
        f"(the order results arrived); {order} row(s) of all runs arrived out of birth "
        "order. Best so far is the running maximum of history's `population_best`, the "
        "population mean its `population_mean`.\n",
        *(["Not complete (summary.json): " + ", ".join(incomplete)
           + "; their numbers may still change.\n"] if incomplete else []),
        "## What the numbers say\n", "".join(_statements(tables)),
        "## Runs\n", markdown_table(tables.runs),
        "## At equal cost (E) and the runs without at their end\n",
        markdown_table(tables.equal_cost),
        "## Paired differences across seeds\n",
        f"t: `scipy.stats.t` {CONFIDENCE:.0%} interval of the per-seed differences and the "
        "one-sample t-test's p; boot: percentile bootstrap of their mean, seeds resampled.\n",
        markdown_table(tables.differences.drop(columns="column")),
        "## Env steps to the final best of the run without\n",
        "`target`: the run without's final best fitness; `*_steps_to_target`: the "
        "cumulative env steps at which each run's best so far first reached it; "
        "`with_ratio`, `without_ratio`: those over the run without's total "
        "(`without_total`); empty where the run with inheritance never reached it.\n",
        markdown_table(tables.steps_to_target),
        "## Acceptance of offspring (seeds pooled)\n",
        markdown_table(tables.acceptance), markdown_table(tables.acceptance_tests),
        figure,
    ])


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m analysis.inheritance RUNS... --out DIR``; exit 0, or 2 on a bad input."""
    argv = list(sys.argv[1:] if argv is None else argv)
    cli = parser("Evolution with policy inheritance against without it, at equal cost.",
                 prog="python -m analysis.inheritance", first=False)
    args = cli.parse_args(argv)
    command = shlex.join(["python", "-m", "analysis.inheritance", *argv])
    return run_report(lambda: write_inheritance(
        args.runs, args.out, Resampling.seeded(args.seed, args.resamples), command))


if __name__ == "__main__":
    sys.exit(main())
