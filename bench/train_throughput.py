"""End-to-end PPO throughput, with its time split, against the raw physics rate.

For every example robot and arena (or task: ``--arenas locomotion push rough``) this
trains PPO with the learner of one-robot training (``+exp=train``:
``conf/learner/ppo.yaml`` with ``conf/exp/train.yaml``'s overrides, and any Hydra
overrides given on the command line) for ``--steps`` env steps on ``--nthread`` physics
threads and prints, from the same run:

* env steps/s end to end (collection + GAE + update + curve bookkeeping);
* the split of wall time: physics (inside ``mujoco.batch``), env (the rest of the
  environment's step: observations, rewards, TensorDicts), policy and collector (the
  rest of collection), update (GAE, PPO epochs, statistics);
* the raw physics rate of the same compiled model, N arenas, same threads and frame
  skip (``bench/env_throughput.py``'s ``raw_rate``) and the ratio.

With ``--quality`` it also evaluates the trained policy deterministically (20 episodes)
and prints the success rate: use ``--steps 150000`` for the learning-quality figures;
``--curves DIR`` keeps every run's learning curve (CSV) and draws them (``curves.png``).
With ``--profile`` it trains each robot once more under ``cProfile`` (after the timed
run, so the figures above are not slowed) and prints where the time goes by library
(MuJoCo, torch, tensordict, TorchRL, numpy, evo, the rest of Python), with the costliest
functions of each: the per-step cost outside MuJoCo, located.

Usage: ``python bench/train_throughput.py [--steps 30000] [--quality] [--robots ...]
[learner.num_envs=32 learner.rollout_steps=64 ...]``
"""

from __future__ import annotations

import argparse
import cProfile
import dataclasses
import functools
import glob
import pstats
import re
from collections import defaultdict
from collections.abc import Callable
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import torch
from env_throughput import raw_rate, setting_override  # bench/ is on sys.path here
from rich.console import Console
from rich.table import Table

from evo.edge import TrainingParts, compose_config, typed_config
from evo.envs.torchrl_env import make_env
from evo.learners.ppo import train
from evo.learners.rollouts import evaluate_policy
from evo.record import read_curve
from evo.robot import load_robot


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=30_000, help="training budget, env steps")
    parser.add_argument("--robots", nargs="+", default=sorted(glob.glob("robots/*.json")))
    parser.add_argument("--arenas", nargs="+", default=["clean", "cluttered"])
    parser.add_argument("--nthread", type=int, default=2, help="physics threads")
    parser.add_argument("overrides", nargs="*", help="Hydra overrides, e.g. learner.num_envs=32")
    parser.add_argument("--quality", action="store_true", help="also evaluate success rate")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--profile", action="store_true",
                        help="also profile each training and print the time per library")
    parser.add_argument("--curves", type=Path, default=None,
                        help="folder for every run's learning curve (CSV) and curves.png")
    args = parser.parse_args()
    torch.set_num_threads(1)
    config = trained_with(args.arenas[0], args.overrides).learner
    print(config)
    table = Table(title=f"PPO end to end, {args.steps:,} env steps, {config.num_envs} arenas x "
                  f"{config.rollout_steps} steps, minibatch {config.minibatch_size}, "
                  f"{args.nthread} physics threads")
    columns = ["robot", "arena", "steps/s", "physics", "env", "policy+collector", "update",
               "raw physics", "ratio", "fitness"]
    if args.quality:
        columns.append("eval success")
    for column in columns:
        table.add_column(column, justify="right")
    for path in args.robots:
        robot = load_robot(path)
        for arena in args.arenas:
            parts = trained_with(arena, args.overrides)
            physics, env = parts.physics, dataclasses.replace(parts.env, nthread=args.nthread)
            probe = make_env(robot, physics, env, config.num_envs, args.seed)
            probe.reset()
            raw = raw_rate(probe, 100, np.random.default_rng(0))
            result = train(robot, physics=physics, env=env, config=config, budget=args.steps,
                           seed=args.seed)
            t, wall = result.timing, result.wall_seconds
            split = {
                "physics": t["physics"],
                "env": t["env"] - t["physics"],
                "policy+collector": t["collect"] - t["env"],
                "update": t["update"],
            }
            row = [Path(path).stem, arena, f"{result.steps_per_second:,.0f}"]
            row += [f"{v / wall:.0%}" for v in split.values()]
            row += [f"{raw:,.0f}", f"{result.steps_per_second / raw:.2f}", f"{result.fitness:+.3f}"]
            if args.quality:
                ev = evaluate_policy(robot, result.policy, physics=physics, env=env,
                                     episodes=20, seed=args.seed + 1)
                row.append(f"{ev.success_rate:.0%}")
            table.add_row(*row)
            if args.curves is not None:
                args.curves.mkdir(parents=True, exist_ok=True)
                result.curve.to_csv(args.curves / f"{Path(path).stem}-{arena}.csv", index=False)
            print(" | ".join(f"{c}: {v}" for c, v in zip(columns, row, strict=True)), flush=True)
            if args.profile:
                again = functools.partial(train, robot, physics=physics, env=env,
                                          config=config, budget=args.steps, seed=args.seed)
                Console(width=200).print(profile_by_library(
                    again, f"{Path(path).stem}, {arena}: profiled time by library"))
    Console(width=200).print(table)
    if args.curves is not None:
        print(plot_curves(args.curves))


LIBRARIES = ("mujoco", "torchrl", "tensordict", "torch", "numpy")
"""Libraries the profile names; everything else is evo or the rest of Python."""


def library_of(filename: str, function: str) -> str:
    """The library a profiled function belongs to, from its file (or, for a built-in,
    its qualified name)."""
    where = filename if filename != "~" else function
    for library in LIBRARIES:
        if re.search(rf"(site-packages/|\b){library}[/._]", where):
            return library
    if "/evo/" in filename:
        return "evo"
    return "python"


def profile_by_library(run: Callable[[], object], title: str, top: int = 3) -> Table:
    """Run ``run`` under cProfile; a table of each library's share of the time spent in
    its own functions, with its ``top`` costliest functions."""
    profile = cProfile.Profile()
    profile.runcall(run)
    own: dict[str, float] = defaultdict(float)
    functions: dict[str, list[tuple[float, str]]] = defaultdict(list)
    # Stats keeps its per-function table in ``stats``, an attribute typeshed does not declare:
    # (file, line, function) -> (primitive calls, calls, own time, cumulative time, callers).
    entries: dict[tuple[str, int, str], tuple[int, int, float, float, dict[object, object]]]
    entries = pstats.Stats(profile).stats  # type: ignore[attr-defined]
    for (filename, line, function), row in entries.items():
        library, seconds = library_of(filename, function), row[2]
        own[library] += seconds
        functions[library].append((seconds, f"{Path(filename).name}:{line}({function})"
                                   if filename != "~" else function))
    total = sum(own.values())
    table = Table(title=title)
    for column in ("library", "share", "seconds", "costliest functions (own time)"):
        table.add_column(column, justify="left" if column.startswith(("lib", "cost")) else "right")
    for library, seconds in sorted(own.items(), key=lambda kv: -kv[1]):
        costly = sorted(functions[library], reverse=True)[:top]
        table.add_row(library, f"{seconds / total:.0%}", f"{seconds:.2f}",
                      "; ".join(f"{name} {t:.2f}s" for t, name in costly))
    return table


def trained_with(arena: str, overrides: list[str]) -> TrainingParts:
    """What ``python evo/main.py +exp=train env=<arena> <overrides>`` trains with (or
    ``env/task=<task>`` for a task other than reach: ``--arenas locomotion push rough``)."""
    return typed_config(compose_config(["+exp=train", setting_override(arena),
                                        *overrides])).training


def plot_curves(folder: Path) -> Path:
    """``folder/curves.png``: success rate and mean return against env steps, every run."""
    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 3.8))
    for path in sorted(folder.glob("*.csv")):
        curve = read_curve(path)
        style = "-" if path.stem.endswith("-clean") else "--"
        for ax, column in ((left, "train/success_rate"), (right, "train/mean_return")):
            ax.plot(curve["env_steps"], curve[column].interpolate(), style, label=path.stem)
    left.set(xlabel="env steps", ylabel="success rate (finished episodes)")
    right.set(xlabel="env steps", ylabel="mean return (finished episodes)")
    right.legend(fontsize="small", loc="lower right")
    fig.tight_layout()
    fig.savefig(folder / "curves.png", dpi=110)
    return folder / "curves.png"


if __name__ == "__main__":
    main()
