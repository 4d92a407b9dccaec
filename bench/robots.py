"""Benchmark of robot structures: what the generator makes, how crossover fares, how fast.

    python bench/robots.py [--count 10000] [--pairs 2000] [--compile-count 1000] [--seed 0]

Prints three tables, all single process:

* generation: over ``--count`` random robots at the default settings, the share that is
  valid (must be 100%), distinct hashes, module counts and the share with motors/pivots;
* crossover: over ``--pairs`` random parent pairs, the share that gives a valid child on
  the first try, the mean number of tries and the failures;
* speed: random generation + validation (robots/s, goal >= 1,000) and MJCF build +
  MuJoCo compile (robots/s, goal >= 100).
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from rich.console import Console
from rich.table import Table

from evo.robot import GeneratorParams, ModuleType, OperatorError, Robot, crossover, random_robot
from evo.robot.builder import build
from evo.robot.validate import violations

GENERATION_GOAL = 1_000.0
"""Random generation + validation, robots/s."""
COMPILE_GOAL = 100.0
"""MJCF build + MuJoCo compile, robots/s."""


@dataclass(frozen=True)
class Generated:
    """Random robots and the time it took to draw and validate them."""

    robots: list[Robot]
    valid: int
    seconds: float


def generate(count: int, rng: np.random.Generator) -> Generated:
    """Draw ``count`` robots at the default settings, validating each one again."""
    params, robots, valid = GeneratorParams(), [], 0
    start = time.perf_counter()
    for _ in range(count):
        robot = random_robot(rng, params)
        valid += not violations(robot.root)
        robots.append(robot)
    return Generated(robots, valid, time.perf_counter() - start)


def share(part: float, whole: float) -> str:
    return f"{100 * part / whole:.2f}%" if whole else "-"


def generation_table(gen: Generated) -> Table:
    robots, n = gen.robots, len(gen.robots)
    sizes = np.array([len(r) for r in robots])
    depths = np.array([r.depth for r in robots])
    motors = np.array([r.n_motors for r in robots])
    pivots = np.array([r.n_pivots for r in robots])
    table = Table(title=f"(a) {n:,} random robots, default settings")
    table.add_column("measure")
    table.add_column("value", justify="right")
    rows = [
        ("valid", f"{share(gen.valid, n)}  ({gen.valid:,} of {n:,})"),
        ("distinct hashes", f"{len({r.hash for r in robots}):,}  ({share(len(set(robots)), n)})"),
        ("modules per robot: mean / max", f"{sizes.mean():.2f} / {sizes.max()}"),
        ("modules per robot: min / median", f"{sizes.min()} / {np.median(sizes):.0f}"),
        ("depth: mean / max", f"{depths.mean():.2f} / {depths.max()}"),
        ("with >= 1 motor", share(int((motors >= 1).sum()), n)),
        ("with >= 1 pivot", share(int((pivots >= 1).sum()), n)),
        ("with >= 1 motor and >= 1 pivot", share(int(((motors >= 1) & (pivots >= 1)).sum()), n)),
        ("with a passive wheel pair", share(sum(_has_passive_wheels(r) for r in robots), n)),
        (
            "action size m + n: mean / max",
            f"{(motors + pivots).mean():.2f} / {(motors + pivots).max()}",
        ),
    ]
    for row in rows:
        table.add_row(*row)
    return table


def _has_passive_wheels(robot: Robot) -> bool:
    return any(
        p.node.type is ModuleType.MAIN
        and any(e.module.type is ModuleType.WHEEL for e in p.node.children)
        for p in robot.modules()
    )


def crossover_table(robots: Sequence[Robot], pairs: int, rng: np.random.Generator) -> Table:
    """Cross random pairs of ``robots``; count tries, failures and offspring."""
    tries, failures, offspring, invalid, new = [], 0, 0, 0, 0
    start = time.perf_counter()
    for _ in range(pairs):
        i, j = rng.choice(len(robots), size=2, replace=False)
        a, b = robots[i], robots[j]
        try:
            result = crossover(a, b, rng)
        except OperatorError:
            failures += 1
            continue
        tries.append(result.tries)
        offspring += len(result.offspring)
        invalid += sum(bool(violations(c.root)) for c in result.offspring)
        new += sum(c not in (a, b) for c in result.offspring)
    seconds = time.perf_counter() - start
    t = np.array(tries)
    table = Table(title=f"(b) subtree crossover of {pairs:,} random pairs")
    table.add_column("measure")
    table.add_column("value", justify="right")
    table.add_row("valid child on the first try", share(int((t == 1).sum()), pairs))
    table.add_row("tries: mean / max", f"{t.mean():.3f} / {t.max()}" if len(t) else "-")
    table.add_row("no valid child within 100 tries", f"{failures:,}")
    table.add_row("offspring per crossover (1 or 2)", f"{offspring / max(len(t), 1):.2f}")
    table.add_row("offspring invalid", f"{invalid:,}")
    table.add_row("offspring unlike both parents", share(new, offspring))
    table.add_row("crossovers/s", f"{pairs / seconds:,.0f}")
    return table


def compile_rate(robots: Sequence[Robot]) -> tuple[float, int]:
    """Robots/s of MJCF build + MuJoCo compile, and the most actuators seen."""
    start, most = time.perf_counter(), 0
    for robot in robots:
        model = build(robot).compile()
        most = max(most, model.nu)
    return len(robots) / (time.perf_counter() - start), most


def speed_table(gen: Generated, compile_robots: Sequence[Robot]) -> Table:
    gen_rate = len(gen.robots) / gen.seconds
    build_rate, _ = compile_rate(compile_robots)
    table = Table(title="(c) speed, one process")
    for column in ("step", "robots", "robots/s", "goal", "met"):
        table.add_column(column, justify="left" if column == "step" else "right")
    for step, n, rate, goal in (
        ("random generation + validation", len(gen.robots), gen_rate, GENERATION_GOAL),
        ("MJCF build + MuJoCo compile", len(compile_robots), build_rate, COMPILE_GOAL),
    ):
        met = "[green]yes[/green]" if rate >= goal else "[red]no[/red]"
        table.add_row(step, f"{n:,}", f"{rate:,.0f}", f">= {goal:,.0f}", met)
    return table


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--count", type=int, default=10_000, help="random robots to draw")
    parser.add_argument("--pairs", type=int, default=2_000, help="crossover parent pairs")
    parser.add_argument(
        "--compile-count", type=int, default=1_000, help="robots to build and compile"
    )
    parser.add_argument("--seed", type=int, default=0, help="seed of every random draw")
    args = parser.parse_args(argv)
    if args.count < 2:
        parser.error("--count must be at least 2 (crossover needs pairs)")
    console = Console(width=200)
    rng = np.random.default_rng(args.seed)
    gen = generate(args.count, rng)
    console.print(generation_table(gen))
    console.print(crossover_table(gen.robots, args.pairs, rng))
    console.print(speed_table(gen, gen.robots[: args.compile_count]))


if __name__ == "__main__":
    main()
