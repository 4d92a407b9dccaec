"""The deployed controller's protocol table: per robot, arena and lever, the deterministic
and the noisy policy's success after training (mean and worst seed), and along the
training the policy's spread and its mean actions outside the action box.

    python docs/results/deployed/table.py LEVER=RETRAIN_DIR ... --out docs/results/deployed \
        [--keep docs/results/deployed/protocol.csv]

Each RETRAIN_DIR is a ``+exp=designer`` folder (``trainings.csv`` and the curves
``evals/<training>.csv``) trained with ``learner.eval_interval``. Beside the evaluation
after training of the policy a training hands back (``success_rate``, 20 episodes, seed
+ 1), the table gives the last periodic evaluation (16 episodes, seed + 2): that of the
last policy, which is the handed-back one unless ``learner.keep_best`` chose another.
Writes ``protocol.csv`` (one row per training), ``protocol.md`` and ``periodic.csv``
(the periodic evaluations' success along the training, the mean over seeds per lever,
arena, robot and env steps); ``--keep`` adds the rows of an earlier ``protocol.csv``
(and of the ``periodic.csv`` beside it) for the levers and arenas the folders do not give.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import pandas as pd

from analysis.markdown import markdown_table
from evo.run.layout import RetrainLayout
from evo.run.records import read_trainings


def trainings(lever: str, folder: Path) -> tuple[pd.DataFrame, pd.DataFrame]:
    """One row per finished training of ``folder``, with its curve's summaries, and its
    periodic evaluations' success, one row per evaluation (each curve read once)."""
    layout = RetrainLayout(folder)
    out, evaluations = [], []
    for row in read_trainings(layout.trainings).itertuples():
        curve = pd.read_csv(layout.curve(str(row.name)))
        evaluated = curve.dropna(subset=["eval/success_rate"])
        out.append({
            "lever": lever, "robot": row.robot, "arena": row.arena, "seed": row.seed,
            "fitness": row.fitness,
            "success": row.success_rate, "noisy_success": row.stochastic_success_rate,
            "eval_return": row.eval_mean_return, "noisy_return": row.stochastic_mean_return,
            "last_periodic_success": evaluated["eval/success_rate"].iloc[-1],
            "best_periodic_success": evaluated["eval/success_rate"].max(),
            "late_train_success": curve["train/success_rate"].iloc[-10:].mean(),
            "final_action_std": curve["train/action_std"].iloc[-1],
            "final_mean_outside": curve["train/mean_outside"].iloc[-1],
            "wall_seconds": row.wall_seconds,
        })
        evaluations.append(pd.DataFrame({
            "lever": lever, "arena": row.arena, "robot": row.robot, "seed": row.seed,
            "env_steps": evaluated["env_steps"].astype(int),
            "success": evaluated["eval/success_rate"]}))
    return pd.DataFrame(out), pd.concat(evaluations, ignore_index=True)


def along(evaluations: pd.DataFrame) -> pd.DataFrame:
    """Per lever, arena, robot and env steps: the mean periodic success and its seeds."""
    grouped = evaluations.groupby(["lever", "arena", "robot", "env_steps"], sort=True)
    return grouped.agg(seeds=("seed", "size"), success=("success", "mean")).reset_index()


def kept(earlier: pd.DataFrame, table: pd.DataFrame) -> pd.DataFrame:
    """The rows of ``earlier`` whose lever and arena ``table`` does not give."""
    given = set(zip(table["lever"], table["arena"], strict=True))
    keep = [(lever, arena) not in given
            for lever, arena in zip(earlier["lever"], earlier["arena"], strict=True)]
    return earlier[keep]


def summary(table: pd.DataFrame) -> pd.DataFrame:
    """Per lever, arena and robot: means and worst seeds."""
    grouped = table.groupby(["lever", "arena", "robot"], sort=True)
    return grouped.agg(
        seeds=("seed", "size"),
        success=("success", "mean"), success_worst=("success", "min"),
        noisy=("noisy_success", "mean"), noisy_worst=("noisy_success", "min"),
        gap_worst=("gap", "max"),
        last_periodic=("last_periodic_success", "mean"),
        late_train=("late_train_success", "mean"),
        action_std=("final_action_std", "mean"),
        mean_outside=("final_mean_outside", "mean"),
        minutes=("wall_seconds", lambda s: s.mean() / 60),
    ).reset_index()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("folders", nargs="+", metavar="LEVER=RETRAIN_DIR")
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--keep", type=Path, help="an earlier protocol.csv")
    args = parser.parse_args(argv)
    parts, evaluations = [], []
    for given in args.folders:
        lever, _, folder = given.partition("=")
        rows, evaluated = trainings(lever, Path(folder))
        parts.append(rows)
        evaluations.append(evaluated)
    table = pd.concat(parts, ignore_index=True)
    table["gap"] = table["noisy_success"] - table["success"]
    curves = along(pd.concat(evaluations, ignore_index=True))
    if args.keep is not None:
        table = pd.concat([kept(pd.read_csv(args.keep), table), table], ignore_index=True)
        beside = args.keep.parent / "periodic.csv"
        if beside.exists():
            curves = pd.concat([kept(pd.read_csv(beside), curves), curves], ignore_index=True)
        else:
            print(f"{beside}: not found; periodic.csv gets only the folders' evaluations",
                  file=sys.stderr)
    args.out.mkdir(parents=True, exist_ok=True)
    table.to_csv(args.out / "protocol.csv", index=False)
    curves.round(4).to_csv(args.out / "periodic.csv", index=False)
    text = markdown_table(summary(table).round(3))
    (args.out / "protocol.md").write_text(text + "\n")
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
