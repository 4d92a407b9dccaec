"""The evolution loop (paper section 6): a steady-state GA over robot structures.

Read ``Evolution.run`` top to bottom: keep every worker busy with an evaluation (an
initial random robot while the population is not full, then an offspring bred from the
population as it stands), and whenever one finishes, apply steady-state replacement,
record it, and save the state. Stop once ``robot_budget`` robots have been evaluated.
With one worker this is the paper's loop; with more it is an asynchronous steady state.
When breeding finds no new valid child (parents too small to cross over, or a converged
population), the next robot is a fresh random one (operator ``random-fallback``).

With ``ga.inheritance`` on, an offspring's training starts from the trained policy of
one of its parents (``evo.components.inheritance``): its candidate names the parent and
the slot map, so a worker reads the parent's checkpoint from the run directory and a
robot in flight restarts from the same policy on resume.

Resumable: the whole state (population, history, breeding RNG, next birth, robots in
flight) is saved by the run's store (``evo.run.store.RunStore``) after every submission
and every result, before anything else. ``Evolution.resume`` reloads it: finished robots
are never evaluated again, robots in flight when the run stopped are evaluated again
with their own seed, so a serial run interrupted and resumed gives the same history.
The files of the run directory are named in ``evo.run.layout``.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping, Sequence

import numpy as np

from evo.components.executors import EvalExecutor
from evo.components.ga import GAConfig, Offspring, StructureStrategy
from evo.components.inheritance import PolicyStart, policy_start
from evo.evaluation import Job, Outcome, evaluate
from evo.interrupt import critical
from evo.pool import EvaluationPool
from evo.record import RecordConfig
from evo.record.run import Birth, RunMetadata, RunRecorder
from evo.robot.builder import PhysicsParams, build
from evo.robot.operators import OperatorError
from evo.run.records import Candidate, HistoryRow, Member, RunSummary
from evo.run.store import RunStore, SavedState, rng_state

RANDOM_FALLBACK = "random-fallback"
"""History ``operator`` of a random robot made because breeding found no valid child."""


def evaluation_seed(seed: int, birth: int) -> int:
    """The seed of the ``birth``-th evaluation, independent of evaluation order."""
    return int(np.random.SeedSequence(seed, spawn_key=(birth,)).generate_state(1)[0])


class Evolution:
    """One GA run, saved in ``store``; see the module docstring.

    ``evaluate`` trains one robot (``evo.evaluation.evaluate``; tests pass a cheaper
    one), ``on_result`` sees every history row as it is recorded.
    """

    def __init__(
        self,
        store: RunStore,
        *,
        ga: GAConfig,
        strategy: StructureStrategy,
        job: Job,
        executor: EvalExecutor,
        seed: int,
        on_result: Callable[[HistoryRow], None] | None = None,
        evaluate: Callable[[Candidate, Job], Outcome] = evaluate,
    ) -> None:
        self.store, self.ga, self.strategy, self.job = store, ga, strategy, job
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
    def run(self) -> RunSummary:
        """Evaluate robots until the budget is spent; returns the summary.

        Interrupted (any exception, ``evo.interrupt.Interrupted`` included), it stops the
        evaluations in flight instead of finishing them: they are in the saved state's
        ``pending`` and are evaluated again, with their own seeds, on resume.
        """
        self.store.prepare()
        if not self.store.has_state():
            self._save()  # a new run has a state from its first moment
        pool = EvaluationPool(self.executor, self.evaluate)
        pool.run(self._submission, self._finished,
                 resumed=[(candidate, self.job) for candidate in self.pending])
        return self.summary()

    def _submission(self, running: Sequence[Candidate]) -> tuple[Candidate, Job] | None:
        """The next robot to evaluate, saved as in flight before it is submitted; None
        when the budget or the population's fill allows none now."""
        if not self._can_submit(running):
            return None
        with critical():
            candidate = self._next_candidate(running)
            self.pending.append(candidate)
            self._save()
        return candidate, self.job

    def _finished(self, candidate: Candidate, outcome: Outcome) -> None:
        with critical():
            self._record(candidate, outcome)

    def _can_submit(self, running: Sequence[Candidate]) -> bool:
        if self.next_birth >= self.ga.robot_budget:
            return False
        if len(self.population) >= self.ga.population_size:
            return True
        initial_running = sum(1 for t in running if not t.parents)
        return len(self.population) + initial_running < self.ga.population_size

    def _next_candidate(self, running: Sequence[Candidate]) -> Candidate:
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
        self.store.save_robot(name, offspring.robot)
        self.next_birth += 1
        budget = self.ga.schedule.budget(birth, self.ga.population_size, self.ga.robot_budget)
        start = self._policy_start(offspring)
        if start is not None:
            budget = self.ga.schedule.inherited_budget(budget)
        full = len(self.population) >= self.ga.population_size
        threshold = min(m.fitness for m in self.population) if full else math.nan
        return Candidate(
            birth,
            name,
            offspring.robot.canonical_json(),
            budget,
            evaluation_seed(self.seed, birth),
            offspring.parents,
            offspring.operator,
            threshold,
            start.parent if start is not None else "",
            start.actuators if start is not None else (),
        )

    def _policy_start(self, offspring: Offspring) -> PolicyStart | None:
        """The parent's policy ``offspring`` starts from (``ga.inheritance``), or None.
        Its parents are members of the population: it was just bred from them."""
        if self.ga.inheritance == "off" or not offspring.parents:
            return None
        robots = {m.name: m.robot for m in self.population}
        parents = [(name, robots[name]) for name in offspring.parents]
        return policy_start(self.ga.inheritance, offspring.robot, parents, offspring.origins)

    def _record(self, candidate: Candidate, outcome: Outcome) -> None:
        """Apply replacement, append the history row, save the state."""
        accepted, replaced = False, ""
        if outcome.error is None and math.isfinite(outcome.fitness) and not outcome.stopped_early:
            robot = self.store.load_robot(candidate.name)
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
            threshold=candidate.threshold,
            inherited_from=candidate.inherit,
            **({} if outcome.periodic is None else dict(
                eval_success_rate=outcome.periodic[0], eval_mean_return=outcome.periodic[1])),
        )
        self.history.append(row)
        self.pending = [t for t in self.pending if t.birth != candidate.birth]
        self._save()
        if self.on_result is not None:
            self.on_result(row)

    # ---- state ----------------------------------------------------------------------------
    def _save(self) -> None:
        """Save the state and the files derived from it (``RunStore.save``)."""
        wall_seconds = self.wall_seconds
        self.store.save(
            SavedState(self.seed, self.next_birth, rng_state(self.rng),
                       self.population, self.history, self.pending, wall_seconds),
            self._summary(wall_seconds))

    @property
    def wall_seconds(self) -> float:
        """Wall time over every session of this run."""
        return self.wall_before + time.perf_counter() - self.started

    def resume(self, saved: SavedState | None = None) -> None:
        """Continue from ``saved`` (by default the store's checked state).

        Raises:
            ValueError: From :meth:`evo.run.store.RunStore.load`, before anything is
                written.
        """
        saved = self.store.load() if saved is None else saved
        self.seed, self.next_birth = saved.seed, saved.next_birth
        self.rng.bit_generator.state = saved.rng
        self.history, self.pending = list(saved.history), list(saved.pending)
        self.population, self.wall_before = list(saved.population), saved.wall_seconds
        # The run may have stopped between the state and the files derived from it.
        self._save()

    def summary(self) -> RunSummary:
        """Robots evaluated, the best robot, env steps and speed so far."""
        return self._summary(self.wall_seconds)

    def _summary(self, wall_seconds: float) -> RunSummary:
        return RunSummary.of(self.history, method=self.job.method,
                             robot_budget=self.ga.robot_budget, wall_seconds=wall_seconds)


class RunLog:
    """Mirrors the run into ``run.mcap`` and ``run.rrd`` (``evo.record.RunRecorder``):
    every history row as a birth, and at the end the best robots' geometry."""

    EXTRA = ("method", "parents", "operator", "budget", "env_steps", "wall_seconds", "error",
             "status", "inherited_from")
    """The history columns a birth carries beside its fitness and population figures."""

    def __init__(self, store: RunStore, record: RecordConfig, metadata: RunMetadata) -> None:
        self.store = store
        self.recorder = (RunRecorder(store.root, metadata, mcap=record.mcap, rerun=record.rerun)
                         if record.enabled else None)

    def __call__(self, row: HistoryRow) -> None:
        if self.recorder is not None:
            record: Mapping[str, object] = row.record()
            self.recorder.birth(Birth(
                row.birth, row.name, row.fitness, row.accepted, row.population_best,
                row.population_mean, extra={k: record[k] for k in self.EXTRA},
            ))

    def close(self, history: list[HistoryRow], physics: PhysicsParams, top: int = 5,
              summary: RunSummary | None = None) -> None:
        """Add the ``top`` fittest robots' geometry, then close the files (a SIGINT or
        SIGTERM meanwhile waits until they are closed)."""
        if self.recorder is None:
            return
        with critical():
            try:
                done = [r for r in history if not r.failed and math.isfinite(r.fitness)]
                for row in sorted(done, key=lambda r: r.fitness, reverse=True)[:top]:
                    robot = self.store.load_robot(row.name)
                    self.recorder.robot(row.name, build(robot, physics).compile(),
                                        fitness=row.fitness)
            finally:
                self.recorder.close(summary.record() if summary is not None else {})
