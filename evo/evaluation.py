"""One evaluation of one robot: train its behaviour, keep its files, report its fitness.

``evaluate`` runs in a worker process (or a Ray task), so its inputs and outputs are
plain picklable values. It never raises: a failure comes back as an ``Outcome`` with the
error, and the evolution loop records it and goes on.
"""

from __future__ import annotations

import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path

from evo.envs.task import EnvConfig
from evo.learners.common import LearnerConfig, get_learner, save_checkpoint
from evo.robot.builder import PhysicsParams
from evo.robot.io import parse_robot


@dataclass(frozen=True, slots=True)
class Job:
    """What every evaluation of a run shares."""

    physics: PhysicsParams
    env: EnvConfig
    learner: LearnerConfig
    run_dir: str
    method: str = "E+L"


@dataclass(frozen=True, slots=True)
class Task:
    """One robot to evaluate.

    Attributes:
        birth: Birth order in the run (0-based).
        name: Unique id of the evaluation (the robot's name, made unique if needed).
        robot: The robot's canonical ``evo.robot/1`` JSON.
        budget: Training budget, env steps.
        seed: The evaluation's own seed.
        parents: Names of the parents (empty for random robots).
        operator: How the robot was made (random, crossover, ...).
    """

    birth: int
    name: str
    robot: str
    budget: int
    seed: int
    parents: tuple[str, ...] = ()
    operator: str = "random"


@dataclass(frozen=True, slots=True)
class Outcome:
    """What came back from one evaluation."""

    birth: int
    name: str
    fitness: float = float("nan")
    env_steps: int = 0
    episodes: int = 0
    wall_seconds: float = 0.0
    error: str | None = None
    extra: dict[str, float] = field(default_factory=dict)


def evaluate(task: Task, job: Job) -> Outcome:
    """Train ``task``'s robot for its budget; write ``evals/<name>.pt`` and ``.csv``."""
    import json

    start = time.perf_counter()
    try:
        robot = parse_robot(json.loads(task.robot), source=task.name)
        train = get_learner(job.learner)
        result = train(
            robot,
            physics=job.physics,
            env=job.env,
            config=job.learner,
            budget=task.budget,
            seed=task.seed,
        )
        evals = Path(job.run_dir) / "evals"
        evals.mkdir(parents=True, exist_ok=True)
        result.curve.to_csv(evals / f"{task.name}.csv", index=False)
        save_checkpoint(result.policy, evals / f"{task.name}.pt", job.learner)
    except Exception:  # noqa: BLE001 - any failure is recorded and the run goes on
        return Outcome(
            task.birth,
            task.name,
            wall_seconds=time.perf_counter() - start,
            error=traceback.format_exc(limit=8),
        )
    return Outcome(
        task.birth,
        task.name,
        fitness=result.fitness,
        env_steps=result.env_steps,
        episodes=result.episodes,
        wall_seconds=time.perf_counter() - start,
        extra={"unstable": float(result.unstable)},
    )
