"""Logging overhead: one evaluation with recording on against recording off.

Runs ``evo.evaluation.evaluate`` on the same robot, seed and budget twice per repeat
(record settings from ``conf/record/default.yaml``, then recording off), interleaved,
and prints env steps/s of each, the slowdown and the sizes of the files written.
The recorded run also plays one deterministic episode after training (so ``evo.replay``
can reproduce it); that time is part of the overhead.

Usage: ``python bench/record_overhead.py [--steps 30000] [--repeats 2] [--robot FILE]``
"""

from __future__ import annotations

import argparse
import dataclasses
import tempfile
from pathlib import Path

import torch
from rich.console import Console
from rich.table import Table

from evo.envs.params import EnvConfig
from evo.evaluation import Job, evaluate
from evo.learners.ppo import PPO
from evo.record import RecordConfig
from evo.robot import load_robot
from evo.robot.builder import PhysicsParams
from evo.run.records import Candidate


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=30_000)
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--robot", default="robots/four_wheeler.json")
    parser.add_argument("--nthread", type=int, default=1)
    args = parser.parse_args()
    torch.set_num_threads(1)
    robot = load_robot(args.robot)
    candidate = Candidate(0, robot.name, robot.canonical_json(), args.steps, seed=3)
    rates: dict[str, float] = {"on": 0.0, "off": 0.0}
    sizes: dict[str, int] = {}
    with tempfile.TemporaryDirectory() as tmp:
        base = Job(PhysicsParams(), EnvConfig(nthread=args.nthread), PPO(), tmp)
        jobs = {"on": dataclasses.replace(base, record=RecordConfig()),
                "off": dataclasses.replace(base, record=RecordConfig(mcap=False, rerun=False))}
        for _ in range(args.repeats):
            for label, job in jobs.items():
                outcome = evaluate(candidate, job)
                if outcome.error:
                    raise SystemExit(outcome.error)
                rates[label] = max(rates[label], outcome.env_steps / outcome.wall_seconds)
        for path in sorted(Path(tmp, "evals").iterdir()):
            sizes[path.suffix] = path.stat().st_size
    table = Table(title=f"recording overhead, {robot.name}, {args.steps:,} env steps, "
                  f"best of {args.repeats}")
    for column in ("recording", "env steps/s", "slowdown"):
        table.add_column(column, justify="right")
    table.add_row("off", f"{rates['off']:,.0f}", "")
    table.add_row("on", f"{rates['on']:,.0f}", f"{1 - rates['on'] / rates['off']:.1%}")
    console = Console(width=200)
    console.print(table)
    for suffix, size in sizes.items():
        console.print(f"evals/<name>{suffix}: {size / 1e3:,.0f} kB")


if __name__ == "__main__":
    main()
