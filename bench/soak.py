"""Memory over long runs: many small evaluations through one pool, RSS per block.

Submits ``--evals`` tiny evaluations (``evo.evaluation.evaluate`` on a cycle of random
robots, a few hundred env steps each, recording on unless ``--record off``) through one
executor of ``evo.components.executors`` at a time, keeping its workers busy, and after
every ``--every`` finished evaluations prints the resident set size (RSS) of the main
process and of the worker processes (the pool's spawned workers, or Ray's ``ray::``
worker processes; the serial executor evaluates in the main process). The goal: after
the first block, RSS grows by at most 5 % over the rest of the run.

Usage::

    python bench/soak.py [--evals 1000] [--every 100] [--executor serial local ray]
                         [--record on|off] [--workers 2] [--steps 256] [--quick]

``--quick`` is a smoke-sized run (20 evaluations, a row every 5, serial only unless
``--executor`` is given).
"""

from __future__ import annotations

import argparse
import gc
import os
import tempfile
import time
from collections.abc import Callable, Iterator
from concurrent.futures import FIRST_COMPLETED, Future, wait
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

from evo.components.executors import EvalExecutor, LocalExecutor, RayExecutor, SerialExecutor
from evo.envs.params import EnvConfig
from evo.envs.tasks.reach import Reach
from evo.evaluation import Job, Outcome, evaluate
from evo.learners.ppo import PPO
from evo.pool import outcome_of
from evo.record import RecordConfig
from evo.robot import random_robot
from evo.robot.builder import PhysicsParams
from evo.run.records import Candidate

GROWTH_GOAL = 0.05
"""Most RSS growth after the first block, as a fraction of the RSS at its end."""
MIB = 2**20


# --- RSS of a process and of its workers ----------------------------------------------


def rss(pid: int) -> int:
    """Resident set size of process ``pid`` in bytes (0 once it is gone)."""
    try:
        import psutil
    except ImportError:
        try:
            status = Path(f"/proc/{pid}/status").read_text()
        except OSError:
            return 0
        kib = next((line.split()[1] for line in status.splitlines()
                    if line.startswith("VmRSS:")), "0")
        return int(kib) * 1024
    try:
        return int(psutil.Process(pid).memory_info().rss)
    except psutil.Error:
        return 0


def descendants() -> list[tuple[int, str]]:
    """Every process below this one: (pid, command line)."""
    try:
        import psutil
    except ImportError:
        return _proc_descendants(os.getpid())
    found = []
    for child in psutil.Process().children(recursive=True):
        try:
            found.append((child.pid, " ".join(child.cmdline())))
        except psutil.Error:
            continue
    return found


def _proc_descendants(root: int) -> list[tuple[int, str]]:
    parents: dict[int, int] = {}
    commands: dict[int, str] = {}
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
            command = (entry / "cmdline").read_bytes().replace(b"\0", b" ").decode()
            commands[int(entry.name)] = command
        except OSError:
            continue
        parents[int(entry.name)] = int(stat.rsplit(")", 1)[1].split()[1])
    below, frontier = [], [root]
    while frontier:
        pid = frontier.pop()
        children = [child for child, parent in parents.items() if parent == pid]
        below += children
        frontier += children
    return [(pid, commands[pid]) for pid in below]


def threads() -> int:
    """Threads of this process (a leaked recording stream leaves idle threads behind)."""
    status = Path("/proc/self/status").read_text()
    return int(next((line.split()[1] for line in status.splitlines()
                     if line.startswith("Threads:")), "0"))


def is_worker(command: str) -> bool:
    """A process-pool worker (spawned by multiprocessing) or a Ray worker process."""
    return "spawn_main" in command or command.startswith("ray::")


@dataclass(frozen=True)
class Sample:
    """RSS after a block of evaluations."""

    done: int
    seconds: float
    main: int
    workers: list[int]
    objects: int
    threads: int
    failed: int


def sample(done: int, seconds: float, failed: int) -> Sample:
    """The RSS of this process and of every worker process below it, now."""
    workers = sorted((rss(pid) for pid, command in descendants() if is_worker(command)),
                     reverse=True)
    return Sample(done, seconds, rss(os.getpid()), [w for w in workers if w],
                  len(gc.get_objects()), threads(), failed)


# --- the evaluations -------------------------------------------------------------------


@dataclass(frozen=True)
class Settings:
    """What every soak evaluation shares."""

    evals: int
    every: int
    workers: int
    steps: int
    robots: int
    record: bool
    seed: int

    def job(self, run_dir: str) -> Job:
        """The tiny evaluation: 2 arenas x 64 steps per batch, 50-step episodes."""
        learner = PPO(num_envs=2, rollout_steps=64, epochs=1, minibatch_size=64,
                                hidden=(32, 32), eval_episodes=0)
        record = RecordConfig() if self.record else RecordConfig(mcap=False, rerun=False)
        return Job(PhysicsParams(), EnvConfig(task=Reach(t_max=50)), learner, run_dir,
                   record=record)


def candidates(settings: Settings) -> Iterator[Candidate]:
    """``settings.evals`` candidates cycling through ``settings.robots`` random robots."""
    rng = np.random.default_rng(settings.seed)
    robots = [random_robot(rng).canonical_json() for _ in range(settings.robots)]
    for birth in range(settings.evals):
        yield Candidate(birth, f"soak-{birth:05d}", robots[birth % len(robots)],
                        settings.steps, seed=settings.seed + birth)


def soak(executor: EvalExecutor, settings: Settings, run_dir: str,
         on_sample: Callable[[Sample], None]) -> list[Sample]:
    """Run every candidate through ``executor``, ``executor.workers`` in flight at once,
    and sample the RSS after every ``settings.every`` finished evaluations."""
    job, pending = settings.job(run_dir), candidates(settings)
    running: dict[Future[Outcome], Candidate] = {}
    samples: list[Sample] = []
    done = failed = 0
    start = time.perf_counter()
    while True:
        while len(running) < executor.workers and (candidate := next(pending, None)):
            running[executor.submit(evaluate, candidate, job)] = candidate
        if not running:
            return samples
        finished, _ = wait(running, return_when=FIRST_COMPLETED)
        for future in finished:
            outcome = outcome_of(future, running.pop(future), executor)
            failed += outcome.error is not None
            done += 1
            if done % settings.every == 0 or done == settings.evals:
                samples.append(sample(done, time.perf_counter() - start, failed))
                on_sample(samples[-1])


def make_executor(name: str, workers: int) -> EvalExecutor:
    """One of the project's executors, one compute thread per worker."""
    if name == "serial":
        return SerialExecutor()
    if name == "local":
        return LocalExecutor(workers=workers)
    return RayExecutor(workers=workers)


# --- report ----------------------------------------------------------------------------


def growth(samples: list[Sample], of: Callable[[Sample], int]) -> float:
    """RSS growth from the end of the first block to the end of the run (fraction)."""
    if len(samples) < 2 or of(samples[0]) == 0:
        return float("nan")
    return of(samples[-1]) / of(samples[0]) - 1


def row(executor: str, s: Sample) -> list[str]:
    """One table row: RSS in MiB of the main process, the workers (sum, each)."""
    each = " ".join(f"{w / MIB:.0f}" for w in s.workers) or "-"
    return [executor, f"{s.done:,}", f"{s.seconds:,.0f}", f"{s.main / MIB:,.1f}",
            f"{sum(s.workers) / MIB:,.1f}", each, f"{s.objects:,}", str(s.threads),
            str(s.failed)]


def verdict(executor: str, samples: list[Sample]) -> str:
    """The growth after the first block, of the main process and of the workers."""
    main = growth(samples, lambda s: s.main)
    workers = growth(samples, lambda s: sum(s.workers))
    worst = max((g for g in (main, workers) if g == g), default=float("nan"))
    mark = "ok" if worst <= GROWTH_GOAL else f"OVER the {GROWTH_GOAL:.0%} goal"
    others = f"workers {workers:+.1%}" if workers == workers else "no worker processes"
    return (f"{executor}: after the first {samples[0].done} evaluations RSS grew "
            f"main {main:+.1%}, {others} over the rest ({mark})")


def parse() -> argparse.Namespace:
    """The command line; ``--quick`` fills in what is not given."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--evals", type=int, help="evaluations per executor (default 1000)")
    parser.add_argument("--every", type=int, help="evaluations per RSS row (default 100)")
    parser.add_argument("--executor", nargs="+", choices=("serial", "local", "ray"),
                        help="executors to soak, one after the other (default: all three)")
    parser.add_argument("--record", choices=("on", "off"), default="on",
                        help="write the .mcap and .rrd recordings (default on)")
    parser.add_argument("--workers", type=int, default=2, help="pool workers / Ray tasks")
    parser.add_argument("--steps", type=int, default=256, help="env steps per evaluation")
    parser.add_argument("--robots", type=int, default=10, help="random robots to cycle through")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--quick", action="store_true", help="20 evaluations, a row every 5")
    args = parser.parse_args()
    args.evals = args.evals or (20 if args.quick else 1_000)
    args.every = args.every or (5 if args.quick else 100)
    args.executor = args.executor or (["serial"] if args.quick else ["serial", "local", "ray"])
    if min(args.evals, args.every, args.workers, args.steps, args.robots) < 1:
        parser.error("--evals, --every, --workers, --steps and --robots must be >= 1")
    return args


def main() -> None:
    args = parse()
    settings = Settings(args.evals, args.every, args.workers, args.steps, args.robots,
                        args.record == "on", args.seed)
    console = Console(width=200)
    job = settings.job("")
    console.print(
        f"soak: {settings.evals:,} evaluations per executor, a row every {settings.every}; "
        f"{settings.steps} env steps each, {job.learner.num_envs} arenas x "
        f"{job.learner.rollout_steps} steps per batch, {job.env.task.t_max}-step episodes, "
        f"hidden {list(job.learner.hidden)}, {settings.robots} random robots (seed "
        f"{settings.seed}), recording {args.record}, {settings.workers} workers x 1 thread")
    verdicts = []
    for name in args.executor:
        table = Table(title=f"RSS, MiB ({name})")
        for column in ("executor", "evaluations", "s", "main", "workers", "each worker",
                       "main objects", "main threads", "failed"):
            table.add_column(column, justify="right")
        with tempfile.TemporaryDirectory(prefix="soak-") as run_dir:
            executor = make_executor(name, settings.workers)
            def progress(s: Sample, name: str = name) -> None:
                console.print(" ".join(row(name, s)), style="dim")

            try:
                samples = soak(executor, settings, run_dir, progress)
            finally:
                executor.shutdown()
        for s in samples:
            table.add_row(*row(name, s))
        console.print(table)
        verdicts.append(verdict(name, samples))
    for line in verdicts:
        console.print(line)


if __name__ == "__main__":
    main()
