"""One robot trained or evaluated from the command line (``+exp=train``, ``+exp=evaluate``).

``train_robot`` writes into the run directory (``evo.run.layout.TrainLayout``):
``robot.json``, ``curve.csv`` (the learning curve, one row per collector batch),
``policy.pt`` (loads with ``torch.load(..., weights_only=True)``) and ``summary.json``
(``evo.run.records.TrainSummary``: ``fitness``, ``success_rate``, ``eval_mean_return``,
``eval_time_to_target``, ``env_steps``, ``wall_seconds``, ``steps_per_second`` and more),
and shows progress while it runs.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Protocol

from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

from evo.envs.params import EnvConfig, observation_size
from evo.learners.common import LearnerConfig, TrainResult, load_checkpoint, save_checkpoint
from evo.learners.rollouts import PolicyEvaluationJSON, evaluate_policy
from evo.robot.builder import PhysicsParams
from evo.robot.io import save_robot
from evo.robot.tree import Robot
from evo.run.files import write_csv, write_json
from evo.run.layout import TrainLayout
from evo.run.records import TrainSummary, write_train_summary


class TrainingSetup(Protocol):
    """What a training or an evaluation of one robot is set up with (the config edge's
    ``evo.edge.TrainingParts`` is one): its module constants, env and learner."""

    @property
    def physics(self) -> PhysicsParams: ...

    @property
    def env(self) -> EnvConfig: ...

    @property
    def learner(self) -> LearnerConfig: ...


def _progress(console: Console) -> Progress:
    return Progress(
        TextColumn("[bold]{task.description}"),
        BarColumn(),
        TextColumn("{task.completed:,.0f}/{task.total:,.0f} steps"),
        TextColumn("{task.fields[status]}"),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
        console=console,
    )


def train_robot(robot: Robot, parts: TrainingSetup, *, seed: int, out: Path,
                console: Console | None = None) -> TrainSummary:
    """Train ``robot`` for ``parts.learner.total_steps``, evaluate it, write the run files.

    Returns:
        The summary also written to ``out/summary.json``.
    """
    physics, env, learner = parts.physics, parts.env, parts.learner
    console = console or Console()
    out.mkdir(parents=True, exist_ok=True)
    layout = TrainLayout(out)
    save_robot(robot, layout.robot)
    train = learner.train_function()
    with _progress(console) as bar:
        task = bar.add_task(f"{learner.name} {robot.name}", total=learner.total_steps, status="")

        def show(row: dict[str, float]) -> None:
            ret, ok = row["train/mean_return"], row["train/success_rate"]
            status = "" if math.isnan(ret) else f"return {ret:+.3f}  success {ok:.0%}"
            bar.update(task, completed=min(row["env_steps"], learner.total_steps), status=status)

        result = train(
            robot,
            physics=physics,
            env=env,
            config=learner,
            budget=learner.total_steps,
            seed=seed,
            on_curve=show,
        )
    write_csv(layout.curve, result.curve)
    save_checkpoint(result.policy, layout.policy, learner, robot=robot.hash)
    summary = _train_summary(robot, result, physics=physics, env=env, learner=learner,
                             seed=seed)
    write_train_summary(layout.summary, summary)
    console.print(
        f"{robot.name}: fitness {result.fitness:+.4f} over {result.episodes} episodes, "
        f"{result.env_steps:,} env steps in {result.wall_seconds:.1f} s "
        f"({result.steps_per_second:,.0f} steps/s)"
    )
    if summary.success_rate is not None and summary.eval_mean_return is not None:
        console.print(
            f"deterministic evaluation: success {summary.success_rate:.0%}, mean return "
            f"{summary.eval_mean_return:+.4f} over {learner.eval_episodes} episodes "
            f"(with the policy's noise: success {summary.stochastic_success_rate:.0%}, "
            f"mean return {summary.stochastic_mean_return:+.4f})"
        )
    console.print(f"files: {out}")
    return summary


def _train_summary(robot: Robot, result: TrainResult, *, physics: PhysicsParams,
                   env: EnvConfig, learner: LearnerConfig, seed: int) -> TrainSummary:
    """``summary.json`` of one training, with the deterministic evaluation (seed + 1)
    when ``learner.eval_episodes`` asks for one."""
    summary = TrainSummary(
        robot=robot.name,
        learner=learner.name,
        arena=env.name,
        seed=seed,
        fitness=result.fitness,
        episodes=result.episodes,
        env_steps=result.env_steps,
        wall_seconds=result.wall_seconds,
        steps_per_second=result.steps_per_second,
        unstable_episodes=result.unstable,
        timing_seconds=result.timing,
        kept_at=result.kept_at,
    )
    if learner.eval_episodes:
        evaluation, noisy = (evaluate_policy(robot, result.policy, physics=physics, env=env,
                                             episodes=learner.eval_episodes, seed=seed + 1,
                                             stochastic=stochastic)
                             for stochastic in (False, True))
        summary = dataclasses.replace(
            summary, success_rate=evaluation.success_rate,
            eval_mean_return=evaluation.mean_return, eval_episodes=learner.eval_episodes,
            eval_time_to_target=evaluation.time_to_target,
            stochastic_success_rate=noisy.success_rate,
            stochastic_mean_return=noisy.mean_return)
    return summary


class EvaluationSummary(PolicyEvaluationJSON):
    """``summary.json`` of ``+exp=evaluate``: the policy's evaluation and what it ran."""

    robot: str
    checkpoint: str
    arena: str
    episodes: int
    seed: int


def evaluate_robot(robot: Robot, checkpoint: Path, parts: TrainingSetup, *, seed: int,
                   out: Path, console: Console | None = None) -> EvaluationSummary:
    """Run the policy in ``checkpoint`` deterministically for the learner's
    ``eval_episodes`` episodes."""
    physics, env, episodes = parts.physics, parts.env, parts.learner.eval_episodes
    console = console or Console()
    policy = load_checkpoint(checkpoint, robot=robot, obs_size=observation_size(robot, env.task))
    evaluation = evaluate_policy(robot, policy, physics=physics, env=env, episodes=episodes,
                                 seed=seed)
    summary: EvaluationSummary = {
        "robot": robot.name,
        "checkpoint": str(checkpoint),
        "arena": env.name,
        "episodes": episodes,
        "seed": seed,
        **evaluation.summary(),
    }
    out.mkdir(parents=True, exist_ok=True)
    write_json(TrainLayout(out).summary, summary)
    console.print(
        f"{robot.name}: success {evaluation.success_rate:.0%}, mean return "
        f"{evaluation.mean_return:+.4f} over {episodes} deterministic episodes"
    )
    return summary
