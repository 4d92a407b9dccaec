"""The cross-task matrix: every body trained on every task (SPEC section 3b).

    python -m analysis.tasks TASK=RETRAIN_DIR ... --out docs/results/tasks

Each RETRAIN_DIR is a ``+exp=designer`` folder (``retrain.robots=<folder of bodies>``,
``env/task=TASK``): the same bodies, each retrained from scratch under a few seeds on one
task and evaluated deterministically after training. A body is named by its robot
file's stem, ``<task>_<evolved|designed>`` for the best evolved and the best hand-made
body of a task (so ``locomotion_evolved`` is the body evolution found for locomotion).

Writes ``matrix.csv`` (one row per body and task: the mean evaluation return with its t
interval, the deterministic success and the trainings' fitness), ``matrix.md`` (the
matrix, and for each task whether the body evolved for it is the best or tied-best on
it: its interval overlaps the best body's) and ``matrix.png`` (a heatmap of each
task's returns scaled to its best body's).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pandas as pd

from analysis.markdown import fmt_ci, markdown_table
from analysis.plots import finish, new_figure
from analysis.stats import mean_interval
from evo.run.layout import RetrainLayout
from evo.run.records import read_trainings

EVOLVED, DESIGNED = "evolved", "designed"


def cells(task: str, folder: Path) -> pd.DataFrame:
    """One row per body of ``folder`` (trained on ``task``): its evaluation return's mean
    and t interval over its trainings, its success and fitness."""
    table = read_trainings(RetrainLayout(folder).trainings)
    if "role" in table:
        table = table[table["role"] == "seed"]
    rows = []
    for body, group in table.groupby("robot", sort=True):
        ret = mean_interval(group["eval_mean_return"].to_numpy(dtype=float))
        rows.append({"body": str(body), "task": task, "trainings": len(group),
                     "eval_return": ret.estimate, "low": ret.ci_low, "high": ret.ci_high,
                     "success": float(group["success_rate"].mean()),
                     "fitness": float(group["fitness"].mean())})
    return pd.DataFrame(rows)


def matrix(parts: dict[str, Path]) -> pd.DataFrame:
    """Every body on every task: :func:`cells` of each folder, stacked."""
    return pd.concat([cells(task, folder) for task, folder in parts.items()],
                     ignore_index=True)


def diagonal(table: pd.DataFrame) -> pd.DataFrame:
    """Per task, the best body and whether the body evolved for the task is the best or
    tied with it (its interval reaches the best body's mean, or the best's reaches its)."""
    rows = []
    for task, group in table.groupby("task", sort=True):
        best = group.loc[group["eval_return"].idxmax()]
        own = group[group["body"] == f"{task}_{EVOLVED}"]
        if own.empty:
            rows.append({"task": task, "best": best["body"], "own": "", "verdict": "no body "
                         "evolved for it"})
            continue
        mine = own.iloc[0]
        if mine["body"] == best["body"]:
            verdict = "best"
        elif mine["high"] >= best["eval_return"] or best["low"] <= mine["eval_return"]:
            verdict = "tied with the best"
        else:
            verdict = "beaten"
        rows.append({"task": task, "best": best["body"], "own": mine["body"], "verdict": verdict})
    return pd.DataFrame(rows)


def write(table: pd.DataFrame, out: Path, command: str) -> None:
    """``matrix.csv``, ``matrix.md`` and ``matrix.png`` under ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    table.to_csv(out / "matrix.csv", index=False)
    shown = table.assign(cell=[fmt_ci(r.eval_return, r.low, r.high, 2)
                               for r in table.itertuples()])
    grid = shown.pivot(index="body", columns="task", values="cell").reset_index()
    text = ["# Every body on every task", "", f"Command: `{command}`", "",
            "Mean evaluation return after training [95 % t interval over the trainings]; a "
            "row per body (`<task>_evolved`: the best body evolution found for that task; "
            "`<task>_designed`: the best hand-made one), a column per task it was trained "
            "on.", "", markdown_table(grid), "", "## The body evolved for each task, on it",
            "", markdown_table(diagonal(table)), "", "![matrix](matrix.png)", ""]
    (out / "matrix.md").write_text("\n".join(text))
    scaled = table.assign(scaled=table["eval_return"]
                          / table.groupby("task")["eval_return"].transform("max"))
    heat = scaled.pivot(index="body", columns="task", values="scaled")
    fig, (ax,) = new_figure(1, width=1.6 + 1.2 * heat.shape[1], height=1.2 + 0.45 * len(heat))
    image = ax.imshow(heat.to_numpy(dtype=float), cmap="viridis", vmax=1.0, aspect="auto")
    ax.set_xticks(range(heat.shape[1]), list(heat.columns))
    ax.set_yticks(range(len(heat)), list(heat.index))
    for (i, j), value in np.ndenumerate(heat.to_numpy(dtype=float)):
        ax.text(j, i, f"{value:.2f}", ha="center", va="center", color="w", fontsize=8)
    fig.colorbar(image, ax=ax, label="evaluation return / the task's best")
    ax.set_title("Every body on every task")
    finish(fig, out / "matrix.png")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("folders", nargs="+", metavar="TASK=RETRAIN_DIR")
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args(argv)
    parts = {}
    for given in args.folders:
        task, sep, folder = given.partition("=")
        if not sep or not Path(folder, "trainings.csv").exists():
            parser.error(f"{given!r}: expected TASK=RETRAIN_DIR with a trainings.csv")
        parts[task] = Path(folder)
    table = matrix(parts)
    write(table, args.out, "python -m analysis.tasks " + " ".join(args.folders)
          + f" --out {args.out}")
    print((args.out / "matrix.md").read_text())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
