"""Early rejection calibrated offline: replay the stopping rule on fully trained curves.

    python bench/early_rejection.py RUN... [--margins 0 0.05 0.1 0.2]
        [--predictors value curve rate] [--checkpoints 0.2 0.35 0.5] [--first N]
        [--out FILE.md]

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

import pandas as pd

from analysis.load import load_runs
from analysis.markdown import markdown_table
from analysis.rejection import replay_runs, score
from evo.early_rejection import EarlyRejection


def calibrate(paths: Sequence[Path], predictors: Sequence[str], margins: Sequence[float],
              checkpoints: Sequence[float], first: int | None = None) -> pd.DataFrame:
    """The table of :func:`score` for every predictor and margin (on each run's first
    ``first`` robots, or all)."""
    runs = load_runs(paths, first=first)
    rows = []
    for predictor, margin in itertools.product(predictors, margins):
        rule = EarlyRejection(enabled=True, checkpoints=tuple(checkpoints),
                              predictor=predictor, margin=margin)
        offspring, all_steps = replay_runs(runs, rule)
        rows.append(dict(predictor=predictor, margin=margin, **score(offspring, all_steps)))
    return pd.DataFrame(rows)


def main(argv: Sequence[str] | None = None) -> int:
    cli = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    cli.add_argument("runs", nargs="+", type=Path)
    cli.add_argument("--predictors", nargs="+", default=["value", "curve"])
    cli.add_argument("--margins", nargs="+", type=float, default=[0.0, 0.05, 0.1, 0.2])
    cli.add_argument("--checkpoints", nargs="+", type=float, default=[0.2, 0.35, 0.5])
    cli.add_argument("--first", type=int, default=None,
                     help="replay each run's first N robots only (default: all)")
    cli.add_argument("--out", type=Path, default=None, help="Markdown file for the table")
    args = cli.parse_args(argv)
    table = calibrate(args.runs, args.predictors, args.margins, args.checkpoints, args.first)
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
