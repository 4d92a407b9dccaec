"""Time to a good robot: for each GA seed, the env steps (and the time on two cores they
cost) each method's run spent before it first evaluated a robot whose fitness reached
a target, and the ratio between two methods.

    python docs/results/early_rejection/headline.py NAME=RUN_DIR... --against NAME \
        [--targets 1.05 0.8] [--core-seconds 15.5 --per 51200] [--out FILE.md]

Each ``NAME=RUN_DIR`` names a method's run (several per name: one per GA seed; the seed
pairs the runs). A target is a fitness (Eq. 8, the mean return over the training,
which lies at or below what the trained policy returns after it). Time is what the env
steps cost at ``--core-seconds`` per ``--per`` env steps (one training of
``+exp=ablation``'s regime: 15.5 core-seconds per 51,200 env steps,
``docs/results/fitness-noise.md``), spread over two cores, as two workers would: a
measured rate, so the runs' own wall clocks, taken while other runs shared the cores,
do not enter it.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from analysis.load import load_runs
from analysis.markdown import markdown_table

CORES = 2


def steps_to(robots: pd.DataFrame, target: float) -> tuple[float, int]:
    """Cumulative env steps up to and including the first robot (birth order) whose
    fitness reaches ``target``, and its birth; NaN and -1 when none did."""
    rows = robots.sort_values("birth")
    spent = rows["budget"].cumsum().to_numpy(float)
    reached = np.flatnonzero(rows["fitness"].to_numpy(float) >= target)
    if not len(reached):
        return np.nan, -1
    return float(spent[reached[0]]), int(rows["birth"].iloc[reached[0]])


def headline(sides: dict[str, list[Path]], against: str, targets: Sequence[float],
             seconds_per_step: float) -> pd.DataFrame:
    """One row per target, method and seed: env steps and two-core minutes to the target
    (NaN where the run never reached it), its best fitness and its whole cost, and the
    ratio to the ``against`` method's run of the same seed."""
    rows = []
    for name, paths in sides.items():
        robots = load_runs(paths).robots
        for seed, mine in robots.groupby("seed"):
            for target in targets:
                steps, birth = steps_to(mine, target)
                rows.append(dict(target=target, method=name, seed=int(seed),
                                 robots=len(mine), best=float(mine["fitness"].max()),
                                 total_env_steps_M=float(mine["budget"].sum()) / 1e6,
                                 birth=birth, env_steps_M=steps / 1e6,
                                 minutes=steps * seconds_per_step / CORES / 60))
    table = pd.DataFrame(rows)
    base = table[table["method"] == against].set_index(["target", "seed"])["env_steps_M"]
    keys = pd.MultiIndex.from_frame(table[["target", "seed"]])
    table["ratio"] = table["env_steps_M"].to_numpy() / base.reindex(keys).to_numpy()
    return table


def medians(table: pd.DataFrame) -> pd.DataFrame:
    """Per target and method: the seeds that reached the target, and the median env
    steps and minutes to it, a run that never reached it counting as infinitely slow
    (so NaN where at least half never did)."""
    rows = []
    for (target, method), runs in table.groupby(["target", "method"], sort=False):
        steps = runs["env_steps_M"].fillna(np.inf).to_numpy(float)
        minutes = runs["minutes"].fillna(np.inf).to_numpy(float)
        middle = [float(np.median(v)) for v in (steps, minutes)]
        rows.append(dict(target=target, method=method,
                         reached=f"{int(np.isfinite(steps).sum())} of {len(steps)}",
                         **{k: v if np.isfinite(v) else np.nan
                            for k, v in zip(("env_steps_M", "minutes"), middle, strict=True)}))
    return pd.DataFrame(rows)


def main(argv: Sequence[str] | None = None) -> int:
    cli = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    cli.add_argument("runs", nargs="+", help="NAME=RUN_DIR")
    cli.add_argument("--against", required=True)
    cli.add_argument("--targets", nargs="+", type=float, default=[1.05])
    cli.add_argument("--core-seconds", type=float, default=15.5)
    cli.add_argument("--per", type=float, default=51_200)
    cli.add_argument("--out", type=Path)
    args = cli.parse_args(argv)
    sides: dict[str, list[Path]] = {}
    for item in args.runs:
        name, sep, path = item.partition("=")
        if not sep:
            cli.error(f"{item}: expected NAME=RUN_DIR")
        sides.setdefault(name, []).append(Path(path))
    if args.against not in sides:
        cli.error(f"--against {args.against}: not one of {', '.join(sides)}")
    table = headline(sides, args.against, args.targets, args.core_seconds / args.per)
    text = (f"# Time to a robot of fitness >= {', '.join(map(str, args.targets))}\n\n"
            f"{args.core_seconds} core-seconds per {args.per:,.0f} env steps, on {CORES} "
            f"cores.\n\n{markdown_table(table)}\n\nMedians over seeds (a run that never "
            f"reached the target counts as reaching it after its end: the median is empty "
            f"where half the runs or more never did):\n\n"
            f"{markdown_table(medians(table))}\n")
    print(text)
    if args.out is not None:
        args.out.write_text(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
