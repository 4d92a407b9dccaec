"""The hand-made robots retrained from scratch: one row per training, and per robot and
arena the deterministic success rate and evaluation return over the seeds.

    python docs/results/designer/table.py SWEEP [SWEEP ...] OUT
    python docs/results/designer/table.py runs/designer docs/results/designer
"""

from __future__ import annotations

import sys
from pathlib import Path

import pandas as pd
import yaml

from evo.run.records import read_train_summary


def trainings(sweep: Path) -> pd.DataFrame:
    """One row per finished job of the multirun in ``sweep``."""
    rows = []
    for job in sorted(p for p in sweep.iterdir() if p.name.isdigit()):
        overrides = yaml.safe_load((job / ".hydra" / "overrides.yaml").read_text())
        robot = next(o for o in overrides if o.startswith("robot=")).split("/")[-1]
        summary = read_train_summary(job / "summary.json")
        if summary is None:
            continue  # a job that did not finish
        rows.append(dict(robot=robot.removesuffix(".json"), arena=summary.arena,
                         seed=summary.seed, fitness=summary.fitness,
                         success_rate=summary.success_rate,
                         eval_mean_return=summary.eval_mean_return,
                         unstable_episodes=summary.unstable_episodes))
    return pd.DataFrame(rows)


def main(sweeps: list[Path], out: Path) -> None:
    table = pd.concat([trainings(sweep) for sweep in sweeps]).sort_values(
        ["arena", "robot", "seed"])
    table.to_csv(out / "trainings.csv", index=False)
    per_robot = table.groupby(["arena", "robot"]).agg(
        seeds=("seed", "count"), success_mean=("success_rate", "mean"),
        success_min=("success_rate", "min"), eval_return_mean=("eval_mean_return", "mean"),
        fitness_mean=("fitness", "mean"), unstable=("unstable_episodes", "sum"))
    per_robot.to_csv(out / "per_robot.csv")
    print(per_robot.round(3).to_string())


if __name__ == "__main__":
    main([Path(arg) for arg in sys.argv[1:-1]], Path(sys.argv[-1]))
