"""The evolution loop (paper section 6): a steady-state GA over robot structures.

Read ``Evolution.run`` top to bottom: keep every worker busy with an evaluation (an
initial random robot while the population is not full, then an offspring bred from the
population as it stands), and whenever one finishes, apply steady-state replacement,
record it, and save the state. Stop once ``robot_budget`` robots have been evaluated.
With one worker this is the paper's loop; with more it is an asynchronous steady state.
When breeding finds no new valid child (parents too small to cross over, or a converged
population), the next robot is a fresh random one (operator ``random-fallback``).

Resumable: the whole state (population, history, breeding RNG, next birth, robots in
flight) is written atomically to ``state.json`` after every submission and every
result, before anything else. ``Evolution.resume`` reloads it: finished robots are
never evaluated again, robots in flight when the run stopped are evaluated again with
their own seed, so a serial run interrupted and resumed gives the same history.

Run directory: ``config.yaml`` (resolved), ``state.json``, ``history.csv`` (one row per
evaluated robot), ``population.json``, ``summary.json``, ``robots/<name>.json``,
``evals/<name>.pt`` (policy) and ``evals/<name>.csv`` (learning curve).
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable
from concurrent.futures import FIRST_COMPLETED, Future, wait
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from evo.components.executors import EvalExecutor
from evo.components.ga import GAConfig, Member, Offspring, StructureStrategy
from evo.evaluation import Candidate, Job, Outcome, evaluate, outcome_of
from evo.history import HISTORY_COLUMNS, HistoryRow
from evo.interrupt import critical
from evo.record import RecordConfig
from evo.record.run import Birth, RunRecorder
from evo.robot.builder import PhysicsParams, build
from evo.robot.io import RobotFileError, load_robot, save_robot
from evo.robot.operators import OperatorError
from evo.robot.validate import InvalidRobotError
from evo.rundir import write_csv, write_json

STATE_VERSION = 1
RANDOM_FALLBACK = "random-fallback"
"""History ``operator`` of a random robot made because breeding found no valid child."""


def evaluation_seed(seed: int, birth: int) -> int:
    """The seed of the ``birth``-th evaluation, independent of evaluation order."""
    return int(np.random.SeedSequence(seed, spawn_key=(birth,)).generate_state(1)[0])


class Evolution:
    """One GA run in ``run_dir``; see the module docstring.

    ``evaluate`` trains one robot (``evo.evaluation.evaluate``; tests pass a cheaper
    one), ``on_result`` sees every history row as it is recorded.
    """

    def __init__(
        self,
        run_dir: Path,
        *,
        ga: GAConfig,
        strategy: StructureStrategy,
        job: Job,
        executor: EvalExecutor,
        seed: int,
        on_result: Callable[[HistoryRow], None] | None = None,
        evaluate: Callable[[Candidate, Job], Outcome] = evaluate,
    ) -> None:
        self.run_dir, self.ga, self.strategy, self.job = run_dir, ga, strategy, job
        self.executor, self.seed, self.on_result = executor, seed, on_result
        self.evaluate = evaluate  # a module-level function: executors pickle it
        self.rng = np.random.default_rng(seed)
        self.population: list[Member] = []
        self.history: list[HistoryRow] = []
        self.pending: list[Candidate] = []  # submitted, not yet recorded
        self.next_birth = 0
        self.wall_before = 0.0
        self.started = time.perf_counter()

    # ---- the loop -------------------------------------------------------------------------
    def run(self) -> dict[str, Any]:
        """Evaluate robots until the budget is spent; returns the summary.

        Interrupted (any exception, ``evo.interrupt.Interrupted`` included), it stops the
        evaluations in flight instead of finishing them: they are in the saved state's
        ``pending`` and are evaluated again, with their own seeds, on resume.
        """
        (self.run_dir / "robots").mkdir(parents=True, exist_ok=True)
        if not (self.run_dir / "state.json").exists():
            self._save()  # a new run has a state from its first moment
        running: dict[Future[Outcome], Candidate] = {}
        try:
            for candidate in self.pending:  # in flight when a previous session stopped
                running[self.executor.submit(self.evaluate, candidate, self.job)] = candidate
            while True:
                while len(running) < self.executor.workers and self._can_submit(running):
                    with critical():
                        candidate = self._next_candidate(running)
                        self.pending.append(candidate)
                        self._save()
                    running[self.executor.submit(self.evaluate, candidate, self.job)] = candidate
                if not running:
                    break
                done, _ = wait(running, return_when=FIRST_COMPLETED)
                for future in done:
                    candidate = running.pop(future)
                    with critical():
                        self._record(candidate, outcome_of(future, candidate, self.executor))
        except BaseException:
            self.executor.terminate()
            raise
        self.executor.shutdown()
        return self.summary()

    def _can_submit(self, running: dict[Future[Outcome], Candidate]) -> bool:
        if self.next_birth >= self.ga.robot_budget:
            return False
        if len(self.population) >= self.ga.population_size:
            return True
        initial_running = sum(1 for t in running.values() if not t.parents)
        return len(self.population) + initial_running < self.ga.population_size

    def _next_candidate(self, running: dict[Future[Outcome], Candidate]) -> Candidate:
        """Breed (or draw) the next robot and give it a unique name, budget and seed."""
        birth = self.next_birth
        if len(self.population) < self.ga.population_size:
            offspring = self.strategy.initial(self.rng)
        else:
            try:
                offspring = self.strategy.breed(self.population, self.rng)
            except OperatorError:
                # No parent pair gave a new valid child (tiny robots have no crossover
                # site; a converged population gives its parents back): a fresh random
                # robot keeps the run going, marked in the history's operator column.
                fresh = self.strategy.initial(self.rng)
                offspring = Offspring(fresh.robot, (), RANDOM_FALLBACK)
        taken = {row.name for row in self.history} | {t.name for t in self.pending}
        name = (
            offspring.robot.name
            if offspring.robot.name not in taken
            else (f"{offspring.robot.name}-{birth}")
        )
        save_robot(offspring.robot, self.run_dir / "robots" / f"{name}.json")
        self.next_birth += 1
        budget = self.ga.schedule.budget(birth, self.ga.population_size, self.ga.robot_budget)
        full = len(self.population) >= self.ga.population_size
        threshold = (min(m.fitness for m in self.population)
                     if self.job.early.enabled and full else math.nan)
        return Candidate(
            birth,
            name,
            offspring.robot.canonical_json(),
            budget,
            evaluation_seed(self.seed, birth),
            offspring.parents,
            offspring.operator,
            threshold,
        )

    def _record(self, candidate: Candidate, outcome: Outcome) -> None:
        """Apply replacement, append the history row, save the state."""
        accepted, replaced = False, ""
        if outcome.error is None and math.isfinite(outcome.fitness) and not outcome.stopped_early:
            robot = load_robot(self._robot_path(candidate.name))
            member = Member(candidate.name, robot, outcome.fitness)
            if not candidate.parents and len(self.population) < self.ga.population_size:
                self.population.append(member)
                accepted = True
            else:
                gone = self.ga.replacement.apply(self.population, member)
                accepted, replaced = gone is not None, gone.name if gone else ""
        fitness = [m.fitness for m in self.population]
        row = HistoryRow(
            birth=candidate.birth,
            name=candidate.name,
            method=self.job.method,
            parents=candidate.parents,
            operator=candidate.operator,
            budget=candidate.budget,
            seed=candidate.seed,
            fitness=outcome.fitness,
            accepted=accepted,
            replaced=replaced,
            env_steps=outcome.env_steps,
            episodes=outcome.episodes,
            wall_seconds=outcome.wall_seconds,
            error=outcome.error or "",
            population_best=max(fitness) if fitness else math.nan,
            population_mean=float(np.mean(fitness)) if fitness else math.nan,
            status=("failed" if outcome.error is not None
                    else "stopped-early" if outcome.stopped_early else "trained"),
            predicted=outcome.predicted,
        )
        self.history.append(row)
        self.pending = [t for t in self.pending if t.birth != candidate.birth]
        self._save()
        if self.on_result is not None:
            self.on_result(row)

    def _robot_path(self, name: str) -> Path:
        return self.run_dir / "robots" / f"{name}.json"

    # ---- state ----------------------------------------------------------------------------
    def _save(self) -> None:
        """Write the state first (atomically), then the files derived from it."""
        state = {
            "version": STATE_VERSION,
            "seed": self.seed,
            "next_birth": self.next_birth,
            "rng": self.rng.bit_generator.state,
            "population": [{"name": m.name, "fitness": m.fitness} for m in self.population],
            "history": [row.record() for row in self.history],
            "pending": [asdict(t) for t in self.pending],
            "wall_seconds": self.wall_seconds,
        }
        write_json(self.run_dir / "state.json", state)
        if self.history:
            write_csv(self.run_dir / "history.csv",
                      pd.DataFrame([row.record() for row in self.history],
                                   columns=list(HISTORY_COLUMNS)))
        write_json(self.run_dir / "population.json", {"population": state["population"]})
        write_json(self.run_dir / "summary.json", self.summary())

    @property
    def wall_seconds(self) -> float:
        """Wall time over every session of this run."""
        return self.wall_before + time.perf_counter() - self.started

    def resume(self, saved: SavedState | None = None) -> None:
        """Continue from ``saved`` (by default :func:`load_state` of the run directory).

        Raises:
            ValueError: From :func:`load_state`, before anything is written.
        """
        saved = load_state(self.run_dir) if saved is None else saved
        self.seed, self.next_birth = saved.seed, saved.next_birth
        self.rng.bit_generator.state = saved.rng
        self.history, self.pending = list(saved.history), list(saved.pending)
        self.population, self.wall_before = list(saved.population), saved.wall_seconds
        # The run may have stopped between the state and the files derived from it.
        self._save()

    def summary(self) -> dict[str, Any]:
        """Robots evaluated, the best robot, env steps and speed so far."""
        done = [r for r in self.history if not r.failed]
        trained = [r for r in done if not r.stopped_early]
        # A robot none of whose episodes ended has only a provisional fitness (the mean
        # return of its unfinished episodes): it is named best only if no robot is better
        # placed, and then with a note. A robot stopped early is never named best.
        finished = [r for r in trained if r.episodes > 0]
        best = max(finished or trained, key=lambda r: r.fitness, default=None)
        initial = [r.fitness for r in done if not r.parents]
        steps = int(sum(r.env_steps for r in self.history))
        stopped = [r for r in self.history if r.stopped_early]
        offspring = [r for r in self.history if r.parents]
        return {
            "method": self.job.method,
            "robots_evaluated": len(self.history),
            "robot_budget": self.ga.robot_budget,
            "failed": len(self.history) - len(done),
            "best_robot": best.name if best else None,
            "best_fitness": best.fitness if best else None,
            "best_initial_fitness": max(initial) if initial else None,
            "accept_rate": float(np.mean([r.accepted for r in offspring])) if offspring else None,
            "env_steps": steps,
            "wall_seconds": self.wall_seconds,
            "steps_per_second": steps / max(self.wall_seconds, 1e-9),
            "complete": len(self.history) >= self.ga.robot_budget,
            "stopped_early": len(stopped),
            "env_steps_saved": int(sum(max(0, r.budget - r.env_steps) for r in stopped)),
            "best_note": (
                "no robot finished an episode within its budget: the best fitness is the "
                "mean return of unfinished episodes" if best and not finished else ""),
        }


@dataclass(frozen=True)
class SavedState:
    """A run's saved state, checked (see :func:`load_state`)."""

    seed: int
    next_birth: int
    rng: dict[str, Any]
    population: list[Member]
    history: list[HistoryRow]
    pending: list[Candidate]
    wall_seconds: float


def load_state(run_dir: Path) -> SavedState:
    """Read and check ``state.json`` and the files it refers to, writing nothing.

    Checked: the state parses, has this version, its RNG state loads, every birth up to
    ``next_birth`` is either in the history or in flight (once), every robot it names is
    a valid file in ``robots/``, the population's members are in the history, and
    ``history.csv`` (derived from the state, and rebuilt from it) holds no row the state
    does not.

    Raises:
        ValueError: Naming the file and what is wrong with it.
    """
    path = run_dir / "state.json"
    try:
        state = json.loads(path.read_text())
    except FileNotFoundError:
        raise ValueError(f"{path}: no saved state; is this an evo run directory?") from None
    except (OSError, ValueError) as err:
        raise ValueError(f"{path}: unreadable run state ({err})") from None
    try:
        if not isinstance(state, dict) or state.get("version") != STATE_VERSION:
            version = state.get("version") if isinstance(state, dict) else None
            raise ValueError(f"state version {version!r}, expected {STATE_VERSION}")
        np.random.default_rng().bit_generator.state = state["rng"]
        history = [HistoryRow.from_record(row) for row in state["history"]]
        pending = [Candidate(**{**t, "parents": tuple(t["parents"])}) for t in state["pending"]]
        fitness = {str(m["name"]): float(m["fitness"]) for m in state["population"]}
        saved = (int(state["seed"]), int(state["next_birth"]), float(state["wall_seconds"]))
        births = sorted([r.birth for r in history] + [t.birth for t in pending])
        names = [r.name for r in history] + [t.name for t in pending]
    except (KeyError, TypeError, ValueError, AttributeError) as err:
        raise ValueError(f"{path}: unreadable run state ({err})") from None
    if births != list(range(saved[1])):
        raise ValueError(f"{path}: inconsistent run state (births {births} recorded or in "
                         f"flight, expected each of 0..{saved[1] - 1} once)")
    if not set(fitness) <= set(names):
        raise ValueError(f"{path}: inconsistent run state (population members "
                         f"{sorted(set(fitness) - set(names))} are not in its history)")
    robots = {}
    for name in dict.fromkeys(names):
        try:
            robots[name] = load_robot(run_dir / "robots" / f"{name}.json")
        except (RobotFileError, InvalidRobotError) as err:
            raise ValueError(f"{path} needs robot {name}: {err}") from None
    _check_history_csv(run_dir / "history.csv", [r.name for r in history])
    population = [Member(name, robots[name], f) for name, f in fitness.items()]
    return SavedState(saved[0], saved[1], state["rng"], population, history, pending, saved[2])


def _check_history_csv(path: Path, names: list[str]) -> None:
    """``history.csv`` may lag the state by a row, never lead it or disagree with it."""
    if not path.exists():
        return
    try:
        rows = pd.read_csv(path, usecols=["name"])["name"].astype(str).tolist()
    except (OSError, ValueError) as err:
        raise ValueError(f"{path}: unreadable ({err}); it is rebuilt from state.json if you "
                         "move it away") from None
    if rows != names[: len(rows)]:
        raise ValueError(f"{path}: its rows do not match state.json's history (is it from "
                         "another run?); it is rebuilt from state.json if you move it away")


class RunLog:
    """Mirrors the run into ``run.mcap`` and ``run.rrd`` (``evo.record.RunRecorder``):
    every history row as a birth, and at the end the best robots' geometry."""

    EXTRA = ("method", "parents", "operator", "budget", "env_steps", "wall_seconds", "error",
             "status")
    """The history columns a birth carries beside its fitness and population figures."""

    def __init__(self, run_dir: Path, record: RecordConfig, metadata: dict[str, Any]) -> None:
        self.run_dir = run_dir
        self.recorder = (RunRecorder(run_dir, metadata, mcap=record.mcap, rerun=record.rerun)
                         if record.enabled else None)

    def __call__(self, row: HistoryRow) -> None:
        if self.recorder is not None:
            record = row.record()
            self.recorder.birth(Birth(
                row.birth, row.name, row.fitness, row.accepted, row.population_best,
                row.population_mean, extra={k: record[k] for k in self.EXTRA},
            ))

    def close(self, history: list[HistoryRow], physics: PhysicsParams, top: int = 5,
              summary: dict[str, Any] | None = None) -> None:
        """Add the ``top`` fittest robots' geometry, then close the files (a SIGINT or
        SIGTERM meanwhile waits until they are closed)."""
        if self.recorder is None:
            return
        with critical():
            try:
                done = [r for r in history if not r.failed and math.isfinite(r.fitness)]
                for row in sorted(done, key=lambda r: r.fitness, reverse=True)[:top]:
                    robot = load_robot(self.run_dir / "robots" / f"{row.name}.json")
                    self.recorder.robot(row.name, build(robot, physics).compile(),
                                        fitness=row.fitness)
            finally:
                self.recorder.close(summary or {})
