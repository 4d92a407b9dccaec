"""Runs from their ``history.csv`` and ``summary.json`` alone, without curves or config.

A results folder commits only these two small files per run
(``docs/results/<study>/runs/<run>/``). :func:`load_histories` reads such copies into
the same :class:`analysis.load.Runs` as :func:`analysis.load.load_runs`, with an empty
curves table (no learning-curve figures), so every table of a report, and the figures
drawn from fitness alone, can be regenerated from what is committed:

* the GA ``seed`` from ``config.yaml`` when the copy has one, else from the directory
  name, which must end in ``seed<S>`` (``E+L_seed0``);
* the initial population size from ``config.yaml``, else the GA default
  (:data:`analysis.load.DEFAULT_POPULATION`);
* ``complete`` from ``summary.json`` (a copy holds no lock: a run that was still
  going when it was copied reads ``partial``).
"""

from __future__ import annotations

import re
from pathlib import Path

import pandas as pd

from analysis.load import (
    DEFAULT_POPULATION,
    EXTRA_ROBOT_COLUMNS,
    RUN_COLUMNS,
    PathsLike,
    RunConfig,
    RunDirectoryError,
    Runs,
    as_int,
    find_run_dirs,
    read_config,
    read_history,
    robots_of_run,
    run_ids,
    run_method,
)
from analysis.tables import CURVE_COLUMNS, ROBOT_COLUMNS
from evo.run.layout import RunLayout
from evo.run.records import read_run_summary

SEED_IN_NAME = re.compile(r"seed(\d+)$")


def run_setting(run_dir: Path) -> tuple[int, int]:
    """The GA seed and initial population size of a run copy.

    Raises:
        RunDirectoryError: If there is no ``config.yaml`` and the name gives no seed.
    """
    if RunLayout(run_dir).config.is_file():
        config = read_config(run_dir)
        seed = 0 if config.seed is None else config.seed
        population = config.ga.get("population_size", DEFAULT_POPULATION)
        return as_int(seed), as_int(population)
    match = SEED_IN_NAME.search(run_dir.name)
    if match is None:
        raise RunDirectoryError(f"{run_dir}: no config.yaml and the name does not end in "
                                "seed<S>; name the copy <method>_seed<S>")
    return int(match.group(1)), DEFAULT_POPULATION


def _complete(run_dir: Path) -> bool:
    try:
        summary = read_run_summary(RunLayout(run_dir).summary)
    except ValueError as err:
        raise RunDirectoryError(str(err)) from None
    return summary is not None and summary.complete


def load_histories(paths: PathsLike, first: int | None = None) -> Runs:
    """Read run copies' ``history.csv`` and ``summary.json`` (see the module docstring).

    Args:
        paths: Run directories, or folders holding them.
        first: Keep only each run's first ``first`` robots; None keeps them all.

    Returns:
        The robots table, an empty curves table, one row per run and notes.

    Raises:
        FileNotFoundError: If a path does not exist.
        RunDirectoryError: Naming the directory or file that cannot be read.
    """
    robots, runs = [], []
    notes = ["Read from history.csv and summary.json only: no learning curves."]
    dirs = find_run_dirs(paths)
    for run, run_dir in zip(run_ids(dirs), dirs, strict=True):
        seed, population = run_setting(run_dir)
        history = read_history(run_dir)
        table = robots_of_run(run, run_method(run_dir, history, RunConfig()), seed, history)
        if first is not None:
            kept = table[table["birth"] < first].reset_index(drop=True)
            notes.append(f"run {run}: its first {len(kept)} robots of {len(table)}")
            table = kept
        table["curve_source"] = ""
        complete = _complete(run_dir)
        if not complete:
            notes.append(f"run {run}: not complete when copied (summary.json), "
                         f"{len(table)} robot(s) here")
        robots.append(table)
        runs.append(dict(run=run, method=table["method"].iloc[0] if len(table) else "",
                         seed=seed, population_size=population, robots=len(table),
                         complete=complete, status="complete" if complete else "partial",
                         curves_mcap=0, curves_csv=0, curves_missing=len(table),
                         path=str(run_dir)))
    robots_table = pd.concat(robots, ignore_index=True)[[*ROBOT_COLUMNS, *EXTRA_ROBOT_COLUMNS]]
    return Runs(robots_table, pd.DataFrame(columns=list(CURVE_COLUMNS)),
                pd.DataFrame(runs, columns=list(RUN_COLUMNS)), notes)
