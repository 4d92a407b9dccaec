"""One evaluation of one robot: train its behaviour, keep its files, report its fitness.

``evaluate`` runs in a worker process (or a Ray task), so its inputs and outputs are
plain picklable values. A failure of the evaluation comes back as an ``Outcome`` with
its error in one line (an unexpected exception's traceback goes to
``evals/<name>.log``), and the evolution loop records it and goes on. A write that
fails for want of room is not the robot's failure: it raises
``evo.run.files.WriteFailed``, the run stops, and the robot, still in flight, is
evaluated again on resume. The learner is the one the job's
learner config names (its ``train_function``) unless the caller passes another;
so are the recorder's opener (``evo.record.open_recorder``) and the policy's writer
(``evo.learners.common.save_checkpoint``).
"""

from __future__ import annotations

import dataclasses
import gc
import json
import math
import time
import traceback
from contextlib import ExitStack
from dataclasses import dataclass, field
from pathlib import Path

from evo.early_rejection import EarlyRejection, StoppingRule
from evo.envs.params import EnvConfig
from evo.envs.scene import compile_scene
from evo.interrupt import critical, raised
from evo.learners import Learner
from evo.learners.common import (
    Inheritance,
    LearnerConfig,
    SavePolicy,
    load_checkpoint,
    save_checkpoint,
)
from evo.learners.rollouts import PolicyEvaluation, evaluate_policy, play
from evo.record import (
    Episode,
    OpenRecorder,
    RecordConfig,
    Recorder,
    open_recorder,
    should_record,
)
from evo.robot.builder import PhysicsParams
from evo.robot.io import parse_robot
from evo.robot.tree import Robot
from evo.run.files import WriteFailed, write_csv, write_failure, write_text
from evo.run.layout import RunLayout
from evo.run.records import Candidate


@dataclass(frozen=True, slots=True)
class Job:
    """What every evaluation of a run shares."""

    physics: PhysicsParams
    env: EnvConfig
    learner: LearnerConfig
    run_dir: str
    method: str = "E+L"
    record: RecordConfig = field(default_factory=RecordConfig)
    config_yaml: str = ""
    timeout_s: float = 0.0
    """Wall-clock limit of one evaluation in seconds, checked after every collector
    batch (0 = none); an evaluation past it stops with an ``EvaluationTimeout`` error."""
    early: EarlyRejection = field(default_factory=EarlyRejection)
    """When an offspring's training may stop early (``ga.early_rejection``)."""
    eval_episodes: int = 0
    """Episodes of a deterministic evaluation after training (the policy's mean action,
    seed + 1, as ``+exp=train`` evaluates it); 0: none."""


class EvaluationTimeout(RuntimeError):
    """An evaluation ran past ``Job.timeout_s``."""


@dataclass(frozen=True, slots=True)
class Outcome:
    """What came back from one evaluation."""

    birth: int
    name: str
    fitness: float = float("nan")
    env_steps: int = 0
    episodes: int = 0
    wall_seconds: float = 0.0
    cpu_seconds: float = 0.0
    """CPU time of the evaluation's process (all its threads): its cost in core-seconds,
    which unlike ``wall_seconds`` does not grow with the machine's other load."""
    error: str | None = None
    extra: dict[str, float] = field(default_factory=dict)
    stopped_early: bool = False
    """Training stopped at a checkpoint: the offspring cannot enter the population;
    ``fitness`` is Eq. 8 over the episodes it completed."""
    predicted: float = float("nan")
    """The early-rejection rule's last prediction of the final fitness."""
    evaluation: PolicyEvaluation | None = None
    """The deterministic evaluation after training (``Job.eval_episodes``), if any."""
    stochastic: PolicyEvaluation | None = None
    """The same episodes with the policy's random actions, beside it."""
    periodic: tuple[float, float] | None = None
    """The handed-back policy's periodic evaluation during training (success rate, mean
    return; ``learner.eval_interval``), if any."""


EXPECTED = (EvaluationTimeout,)
"""Failures that are outcomes of an evaluation, not faults of the code: one line each."""


def one_line(err: BaseException) -> str:
    """The message of ``err`` up to its first line break."""
    lines = str(err).strip().splitlines()
    return lines[0] if lines else ""


def first_line(err: BaseException) -> str:
    """``Type: message`` of ``err``, its message cut at the first line break."""
    message = one_line(err)
    return f"{type(err).__name__}: {message}" if message else type(err).__name__


def error_cell(err: BaseException, candidate: Candidate, job: Job) -> str:
    """``history.csv``'s one-line ``error`` of an evaluation that ``err`` ended: an
    expected outcome's message, or an unexpected exception's first line and the file
    (``evals/<name>.log``) that holds its traceback. Call it while ``err`` is handled."""
    if isinstance(err, EXPECTED):
        return first_line(err)
    layout = RunLayout(Path(job.run_dir))
    log = layout.error_log(candidate.name)
    log.parent.mkdir(parents=True, exist_ok=True)
    write_text(log, traceback.format_exc())
    return f"{first_line(err)} (traceback in {layout.relative(log)})"


class EpisodeSampler:
    """Passes the episodes the record config asks for to the recorder.

    Every episode of the traced arena comes through here, numbered by the tracer; the
    chosen ones are recorded at once, and the latest other one is held back in case it
    turns out to be the last (``finish``). Episodes cut short by a numerical blow-up
    (``Episode.unstable``) are counted but never recorded.
    """

    def __init__(self, recorder: Recorder, config: RecordConfig) -> None:
        self.recorder, self.config = recorder, config
        self.count = 0  # episodes seen
        self.held: Episode | None = None

    def __call__(self, episode: Episode) -> None:
        self.count = episode.index + 1
        if episode.unstable:
            return
        if should_record(self.config, episode.index, is_last=False):
            self.recorder.episode(episode)
            self.held = None
        else:
            self.held = episode

    def finish(self) -> None:
        """Record the last episode if the config asks for it and it is not recorded."""
        if self.held is not None and should_record(self.config, self.held.index, is_last=True):
            self.recorder.episode(self.held)
        self.held = None


def evaluate(candidate: Candidate, job: Job, learner: Learner | None = None, *,
             open_recorder: OpenRecorder = open_recorder,
             save_policy: SavePolicy = save_checkpoint) -> Outcome:
    """Train ``candidate``'s robot for its budget; write its policy, its learning curve
    and the recordings the record config asks for (``evo.run.layout.RunLayout``).

    Args:
        candidate: The robot to train.
        job: What every evaluation of the run shares.
        learner: The training function; by default the one ``job.learner`` names.
        open_recorder: Opens the evaluation's recorder (what ``job.record`` asks for).
        save_policy: Writes the trained policy to ``evals/<name>.pt``.
    """

    start, cpu_start = time.perf_counter(), time.process_time()
    try:
        robot = parse_robot(json.loads(candidate.robot), source=candidate.name)
        train = job.learner.train_function() if learner is None else learner
        outcome = _train_and_record(robot, candidate, job, train, start,
                                    open_recorder=open_recorder,
                                    save_policy=save_policy)
    except Exception as err:  # noqa: BLE001 - any failure is recorded and the run goes on
        if (stop := raised()) is not None:  # a signal, turned into another error on its way
            raise stop from err
        if (full := write_failure(err)) is not None:  # the disk's fault, not the robot's:
            # the run stops, the robot stays in flight (evo.run.files). A new exception:
            # raising ``full`` again would reorder its chain, where the first is the deepest.
            raise WriteFailed(full.errno, full.strerror, full.filename) from err
        return Outcome(candidate.birth, candidate.name, wall_seconds=time.perf_counter() - start,
                       cpu_seconds=time.process_time() - cpu_start,
                       error=error_cell(err, candidate, job))
    finally:
        # The evaluation's reference cycles (recording streams among them) hold native
        # memory that a long-lived worker would otherwise keep until a rare full collection.
        gc.collect()
    return dataclasses.replace(outcome, wall_seconds=time.perf_counter() - start,
                               cpu_seconds=time.process_time() - cpu_start)


def inheritance(candidate: Candidate, layout: RunLayout) -> Inheritance | None:
    """The parent's policy ``candidate`` starts from, read from the run directory
    (``evals/<parent>.pt``), or None when it starts from scratch.

    Raises:
        ValueError: The parent's checkpoint is missing or unreadable (naming it).
    """
    if not candidate.inherit:
        return None
    parent = load_checkpoint(layout.policy(candidate.inherit))
    return Inheritance(parent, candidate.inherit_actuators)


def _train_and_record(robot: Robot, candidate: Candidate, job: Job, learner: Learner,
                      start: float, *, open_recorder: OpenRecorder,
                      save_policy: SavePolicy) -> Outcome:
    layout = RunLayout(Path(job.run_dir))
    layout.evals.mkdir(parents=True, exist_ok=True)
    scene = compile_scene(robot, job.physics, job.env.arena, job.env.task)  # the one compile
    metadata = {
        "robot": candidate.robot, "config": job.config_yaml, "seed": candidate.seed,
        "method": job.method, "birth": candidate.birth, "budget": candidate.budget,
        "parents": list(candidate.parents), "replay_seed": candidate.seed,
    }
    rule = (StoppingRule(job.early, candidate.budget, candidate.threshold, job.env.task.t_max)
            if job.early.enabled and math.isfinite(candidate.threshold) else None)
    with ExitStack() as stack:
        with critical():  # a signal here waits until the recorder is on the stack
            recorder = stack.enter_context(
                open_recorder(job.record, layout.evals, candidate.name, scene.model, metadata))

        def on_curve(row: dict[str, float]) -> bool:
            recorder.curve(row)
            elapsed = time.perf_counter() - start
            if job.timeout_s > 0 and elapsed > job.timeout_s:
                raise EvaluationTimeout(
                    f"{candidate.name}: timed out after {elapsed:.1f} s at {row['env_steps']:.0f} "
                    f"of {candidate.budget} env steps (ga.eval_timeout_s = {job.timeout_s:g})"
                )
            return rule is not None and rule(row)

        sampler = EpisodeSampler(recorder, job.record)
        result = learner(
            robot, physics=job.physics, env=job.env, config=job.learner, budget=candidate.budget,
            seed=candidate.seed, on_curve=on_curve,
            on_episode=sampler if job.record.enabled else None,
            start=inheritance(candidate, layout), scene=scene,
        )
        sampler.finish()
        if job.record.enabled:  # one deterministic episode, as `evo.replay` re-plays it
            _, (final,) = play(robot, result.policy, physics=job.physics, env=job.env,
                               seed=candidate.seed, scene=scene)
            recorder.episode(dataclasses.replace(final, index=sampler.count,
                                                 env_step=result.env_steps))
        write_csv(layout.curve(candidate.name), result.curve)
        save_policy(result.policy, layout.policy(candidate.name), job.learner,
                    robot=robot.hash)
        predicted = rule.predicted if rule is not None else float("nan")
        evaluation, noisy = ((evaluate_policy(robot, result.policy, physics=job.physics,
                                              env=job.env, episodes=job.eval_episodes,
                                              seed=candidate.seed + 1, scene=scene,
                                              stochastic=stochastic)
                              for stochastic in (False, True))
                             if job.eval_episodes else (None, None))
        recorder.close({"fitness": result.fitness, "env_steps": result.env_steps,
                        "episodes": result.episodes, "predicted": predicted,
                        "status": "stopped-early" if result.stopped_early else "complete"})
    return Outcome(candidate.birth, candidate.name, fitness=result.fitness,
                   env_steps=result.env_steps, episodes=result.episodes,
                   extra={"unstable": float(result.unstable)},
                   stopped_early=result.stopped_early, predicted=predicted,
                   evaluation=evaluation, stochastic=noisy, periodic=result.evaluation)
