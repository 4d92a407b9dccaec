"""Early rejection calibrated offline: replay the stopping rule on fully trained curves.

    python bench/early_rejection.py RUN... [--margins 0 0.05 0.1 0.2]
        [--predictors value curve] [--checkpoints 0.2 0.35 0.5] [--out FILE.md]

For every offspring of the given evolution runs (trained over its whole budget, rule
off), the rule (``evo.early_rejection``, as the GA applies it) is replayed on its
recorded learning curve against the population minimum it actually had to beat. Per
predictor and margin it prints:

* ``false rejections``: offspring the rule would have stopped although full training
  accepted them, as a share of the accepted ones, with a Wilson 95 % CI (goal <= 5 %);
* ``saved``: the env steps the rule saves on the offspring full training rejected, as
  a share of what those offspring used (goal >= 60 %);
* ``schedule``: the env steps of the whole run with the rule against without it
  (first order: the rest of each run kept as it happened; goal: 1.3x fewer).

Offspring of random-structure methods count too (they face the same minimum); the
initial population is never stopped and is left out. The curves come from the runs'
MCAP recordings (or ``evals/*.csv``) through ``analysis.load``.
"""

from __future__ import annotations

import argparse
import itertools
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import NotRequired, TypedDict

import numpy as np
import pandas as pd
import scipy.stats

from analysis.load import load_runs
from analysis.markdown import markdown_table
from analysis.population import population_trace
from evo.early_rejection import Curve, EarlyRejection, replay_rule


def replay(robots: pd.DataFrame, curves: pd.DataFrame, population_sizes: dict[str, int],
           rule: EarlyRejection) -> pd.DataFrame:
    """Per offspring: the minimum it faced, whether it was accepted, whether (and at
    which fraction of its budget) the rule stops it."""
    rows = []
    for run, run_robots in robots.groupby("run"):
        trace = population_trace(run_robots, population_sizes.get(str(run), 20))
        merged = run_robots.merge(trace[["name", "threshold"]], on="name")
        by_name = {name: Curve.from_rows(c) for name, c in
                   curves[curves["run"] == run].groupby("name")}
        for robot in merged.itertuples(index=False):
            if not np.isfinite(robot.threshold) or robot.name not in by_name:
                continue
            budget = float(robot.scheduled_budget or robot.budget)  # as the GA gave it
            verdict = replay_rule(rule, by_name[robot.name], budget, float(robot.threshold))
            rows.append(dict(run=run, name=robot.name, budget=budget,
                             accepted=bool(robot.accepted), threshold=robot.threshold,
                             stopped=verdict is not None,
                             fraction=verdict.fraction if verdict else 1.0))
    return pd.DataFrame(rows)


class Score(TypedDict):
    """A rule's replay (:func:`score`); with no offspring, only their count."""

    offspring: int
    accepted: NotRequired[int]
    stopped: NotRequired[int]
    false_rejections: NotRequired[float]  # share of the accepted offspring the rule stops
    ci_low: NotRequired[float]  # Wilson CI of false_rejections
    ci_high: NotRequired[float]
    saved: NotRequired[float]  # share of the rejected offspring's env steps saved
    schedule: NotRequired[float]  # all env steps over those left to train


def score(offspring: pd.DataFrame, all_steps: float) -> Score:
    """False rejections (with a Wilson CI), env steps saved, schedule ratio."""
    if offspring.empty:
        return Score(offspring=0)
    accepted = offspring[offspring["accepted"]]
    false = int(accepted["stopped"].sum())
    ci = (scipy.stats.binomtest(false, len(accepted)).proportion_ci(method="wilson")
          if len(accepted) else None)
    rejected = offspring[~offspring["accepted"]]
    saved = float(((1 - rejected["fraction"]) * rejected["budget"]).sum())
    lost = float(((1 - accepted["fraction"]) * accepted["budget"]).sum())
    return Score(
        offspring=len(offspring), accepted=len(accepted), stopped=int(offspring["stopped"].sum()),
        false_rejections=false / len(accepted) if len(accepted) else np.nan,
        ci_low=ci.low if ci else np.nan, ci_high=ci.high if ci else np.nan,
        saved=saved / max(float(rejected["budget"].sum()), 1.0),
        schedule=all_steps / max(all_steps - saved - lost, 1.0),
    )


def calibrate(paths: Sequence[Path], predictors: Sequence[str], margins: Sequence[float],
              checkpoints: Sequence[float]) -> pd.DataFrame:
    """The table of :func:`score` for every predictor and margin."""
    runs = load_runs(paths)
    robots = runs.robots[runs.robots["status"] != "stopped-early"]
    all_steps = float(robots["budget"].sum())
    rows = []
    for predictor, margin in itertools.product(predictors, margins):
        rule = EarlyRejection(enabled=True, checkpoints=tuple(checkpoints),
                              predictor=predictor, margin=margin)
        offspring = replay(robots, runs.curves, runs.population_sizes, rule)
        rows.append(dict(predictor=predictor, margin=margin, **score(offspring, all_steps)))
    return pd.DataFrame(rows)


def main(argv: Sequence[str] | None = None) -> int:
    cli = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    cli.add_argument("runs", nargs="+", type=Path)
    cli.add_argument("--predictors", nargs="+", default=["value", "curve"])
    cli.add_argument("--margins", nargs="+", type=float, default=[0.0, 0.05, 0.1, 0.2])
    cli.add_argument("--checkpoints", nargs="+", type=float, default=[0.2, 0.35, 0.5])
    cli.add_argument("--out", type=Path, default=None, help="Markdown file for the table")
    args = cli.parse_args(argv)
    table = calibrate(args.runs, args.predictors, args.margins, args.checkpoints)
    if not table["offspring"].any():
        print(f"error: no offspring to replay in {' '.join(map(str, args.runs))}: a run has "
              "offspring only after its first population_size robots", file=sys.stderr)
        return 2
    text = markdown_table(table)
    print(text)
    if args.out is not None:
        args.out.write_text(f"# Early rejection replayed on {', '.join(map(str, args.runs))}"
                            f"\n\nCheckpoints {args.checkpoints}.\n\n{text}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
