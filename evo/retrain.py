"""Retraining fixed structures under independent seeds: the trainings of a noise ceiling.

``python evo/main.py +exp=retrain noise_ceiling.random=24 hydra.run.dir=DIR`` (the
``retrain`` task), its alias ``python -m analysis.noise_ceiling``, and each trial of
the noise sweep (``analysis.noise_sweep``) train every structure of a fixed sample
``seeds`` times, each training with its own seed (:func:`training_seed`), and, with
``baseline``, once with the random learner (the same network, never updated). The
trainings run through the evaluation pool (``evo.pool``) on the config's executor, as
an evolution's do, and each lands in ``trainings.csv`` as it finishes (one
:class:`TrainingRow`), with the wall time so far in ``progress.json``.

Resumable: the same command again (or ``resume=DIR``) reuses the finished trainings
and trains the others, the ones in flight when it stopped included, with their own
seeds. ``settings.json`` holds what decides the numbers (:class:`Settings`); a folder
holding other settings is refused. The statistics and the report over the trainings
are :mod:`analysis.noise_ceiling`'s. The files are named in ``evo.run.layout``
(:class:`evo.run.layout.RetrainLayout`).
"""

from __future__ import annotations

import dataclasses
import json
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TypedDict, cast

import numpy as np
import pandas as pd

from evo.evaluation import Job, Outcome
from evo.pool import EvaluationPool
from evo.record import read_curve
from evo.robot import GeneratorParams, Limits, Robot
from evo.run.files import write_csv, write_json
from evo.run.layout import RetrainLayout
from evo.run.records import Candidate
from evo.run.store import RunStore

OPERATOR = "noise-ceiling"
"""``Candidate.operator`` of a retraining."""
TRAINING_COLUMNS = ("name", "structure", "role", "learner", "replicate", "seed", "budget",
                    "fitness", "fitness_late", "episodes", "env_steps", "wall_seconds",
                    "cpu_seconds")
"""``role``: ``seed`` (one of the K trainings) or ``baseline`` (the random learner);
``cpu_seconds``: the training's CPU time (its cost, whatever else the machine ran)."""


class RetrainError(ValueError):
    """A bad setting or output folder; the message names the key."""


@dataclass(frozen=True, slots=True)
class RetrainConfig:
    """``noise_ceiling``: which structures the ``retrain`` task trains, how often, how long.

    Attributes:
        robots: Folder of ``evo.robot/1`` files to train (or ``random``).
        random: How many random robots of distinct structure to draw with the root seed.
        seeds: Trainings per structure, each with its own seed.
        budget: Env steps per training; None: ``learner.total_steps``.
        baseline: Also train each structure once with the random learner.
        resamples: Bootstrap resamples of the report's intervals.
    """

    robots: str | None = None
    random: int | None = None
    seeds: int = 2
    budget: int | None = None
    baseline: bool = True
    resamples: int = 2000

    def __post_init__(self) -> None:
        if (self.robots is None) == (self.random is None):
            raise ValueError("robots: give either robots=<folder of robot files> or "
                             "random=<count>")
        if self.seeds < 2:
            raise ValueError(f"seeds: expected at least 2, got {self.seeds}")
        if self.random is not None and self.random < 3:
            raise ValueError(f"random: expected at least 3 robots, got {self.random}")
        if self.budget is not None and self.budget < 1:
            raise ValueError(f"budget: expected a positive env-step count, got {self.budget}")
        if self.resamples < 1:
            raise ValueError(f"resamples: expected at least 1, got {self.resamples}")


# ---------------------------------------------------------------- the plan


@dataclass(frozen=True, slots=True)
class Training:
    """One training of one structure.

    Attributes:
        name: Unique name (file stem in ``evals/``).
        structure: The robot's name.
        role: ``seed`` (one of the K trainings) or ``baseline`` (the random learner).
        replicate: Which of the K trainings of this structure (0-based).
        seed: Its seed.
    """

    name: str
    structure: str
    role: str
    replicate: int
    seed: int


def training_seed(root: int, structure: str, replicate: int) -> int:
    """The seed of a structure's ``replicate``-th training: the same for the same root
    seed whatever the other structures, the settings or the order of training."""
    key = int(structure.removeprefix("robot-")[:8], 16)
    return int(np.random.SeedSequence(root, spawn_key=(key, replicate)).generate_state(1)[0])


def plan_trainings(structures: Sequence[str], *, seeds: int, root: int,
                   baseline: bool) -> list[Training]:
    """K trainings per structure, and one random-learner training (seed of replicate 0)
    per structure when ``baseline``."""
    plan = [Training(f"{s}_s{r}", s, "seed", r, training_seed(root, s, r))
            for s in structures for r in range(seeds)]
    if baseline:
        plan += [Training(f"{s}_baseline", s, "baseline", 0, training_seed(root, s, 0))
                 for s in structures]
    return plan


def load_structures(robots: Path | None, random_count: int | None, seed: int, *,
                    generator: GeneratorParams, limits: Limits) -> list[Robot]:
    """The robots to train: every ``*.json`` of ``robots``, or ``random_count`` random
    robots of distinct structure drawn with ``seed`` (as ``task=robots`` draws them).

    Raises:
        RetrainError: For an empty or missing folder, a file that is not a valid robot
            (named), or fewer than three robots.
    """
    from evo.robot import InvalidRobotError, RobotFileError, load_robot, random_robots

    if robots is not None:
        if not robots.is_dir():
            raise RetrainError(f"noise_ceiling.robots {robots}: no such folder")
        files = sorted(robots.glob("*.json"))
        if not files:
            raise RetrainError(f"noise_ceiling.robots {robots}: no robot files (*.json) in it")
        found: dict[str, Robot] = {}
        for path in files:
            try:
                robot = load_robot(path, limits)
            except (RobotFileError, InvalidRobotError) as err:
                raise RetrainError(f"noise_ceiling.robots: {err}") from None
            found.setdefault(robot.name, robot)
        chosen = list(found.values())
        what = f"noise_ceiling.robots {robots}: {len(chosen)} distinct structure(s)"
    else:
        assert random_count is not None
        if random_count < 3:
            raise RetrainError(
                f"noise_ceiling.random: expected at least 3 robots, got {random_count}")
        rng = np.random.default_rng(seed)
        try:
            chosen = random_robots(rng, random_count, generator, limits)
        except ValueError as err:
            raise RetrainError(f"noise_ceiling.random {random_count}: {err}") from None
        what = f"noise_ceiling.random {random_count}"
    if len(chosen) < 3:
        raise RetrainError(f"{what}; a rank correlation needs at least 3")
    return chosen


# ---------------------------------------------------------------- the folder


class SettingsJSON(TypedDict):
    """:class:`Settings` as ``settings.json`` holds it (tuples as lists once read)."""

    overrides: Sequence[str]
    budget: int
    seeds: int
    root_seed: int
    baseline: bool
    structures: Sequence[str]
    config: str


@dataclass(frozen=True)
class Settings:
    """What decides a noise ceiling's numbers (stored in ``settings.json``)."""

    overrides: tuple[str, ...]
    budget: int
    seeds: int
    root_seed: int
    baseline: bool
    structures: tuple[str, ...]
    config: str  # the resolved config without the executor group

    def to_json(self) -> SettingsJSON:
        return cast(SettingsJSON, dataclasses.asdict(self))

    COMPARED = ("budget", "seeds", "root_seed", "baseline", "structures", "config")
    """What must match to continue a folder (the overrides may differ, e.g. the
    executor, as long as the resolved config without it is the same)."""


def stored_settings(out: Path) -> SettingsJSON | None:
    """``settings.json`` of the folder ``out`` as stored, or None when it has none.

    Raises:
        RetrainError: When it does not parse.
    """
    path = RetrainLayout(out).settings
    if not path.is_file():
        return None
    try:
        stored = json.loads(path.read_text())
    except json.JSONDecodeError as err:
        raise RetrainError(f"{path}: unreadable ({err})") from None
    assert isinstance(stored, dict)
    return cast(SettingsJSON, stored)


WhatTrains = Callable[[str], object]
"""The typed groups of a resolved config (:attr:`Settings.config`) that decide a
training's result (``evo.edge.what_trains``): two configs alike there train alike."""


def _check_settings(out: Path, settings: Settings, what_trains: WhatTrains) -> None:
    """Refuse an output folder that holds a noise ceiling of other settings."""
    stored: Mapping[str, object] | None = stored_settings(out)  # as read: keys may lack
    if stored is None:
        return
    mine: Mapping[str, object] = settings.to_json()
    differ = [k for k in Settings.COMPARED if k != "config"
              and json.dumps(stored.get(k)) != json.dumps(mine[k])]
    if what_trains(str(stored.get("config"))) != what_trains(settings.config):
        differ.append("config")
    if differ:
        raise RetrainError(
            f"hydra.run.dir {out}: holds a noise ceiling with other settings "
            f"({', '.join(differ)} differ); give the same arguments to continue it, or "
            "another output folder")


def open_folder(out: Path, settings: Settings, what_trains: WhatTrains) -> None:
    """Create ``out`` or continue it: refuse a folder that is not one or that holds a
    noise ceiling of other settings (``config`` compared by ``what_trains``), then store
    ``settings.json``."""
    if out.exists() and not out.is_dir():
        raise RetrainError(f"hydra.run.dir {out}: exists and is not a folder")
    out.mkdir(parents=True, exist_ok=True)
    _check_settings(out, settings, what_trains)
    RetrainLayout(out).settings.write_text(json.dumps(settings.to_json(), indent=2) + "\n")


# ---------------------------------------------------------------- the trainings


class TrainingRow(TypedDict):
    """One row of ``trainings.csv``: the columns of :data:`TRAINING_COLUMNS`."""

    name: str
    structure: str
    role: str
    learner: str
    replicate: int
    seed: int
    budget: int
    fitness: float
    fitness_late: float
    episodes: int
    env_steps: int
    wall_seconds: float
    cpu_seconds: float


def late_fitness(curve: pd.DataFrame, budget: float) -> float:
    """Mean return of the episodes completed after half the budget (``fitness_late``).

    Args:
        curve: A learning curve (``env_steps``, ``train/episodes``, ``train/mean_return`` per
            batch).
        budget: The training's budget, env steps.

    Returns:
        The episode-weighted mean; NaN when no episode ended in the second half.
    """
    late = curve[(curve["env_steps"] > budget / 2) & (curve["train/episodes"] > 0)
                 & np.isfinite(curve["train/mean_return"])]
    if late["train/episodes"].sum() <= 0:
        return float("nan")
    return float(np.average(late["train/mean_return"], weights=late["train/episodes"]))


def read_trainings(out: Path) -> pd.DataFrame:
    """``trainings.csv`` of a noise-ceiling folder (empty when it has none yet); a
    column that an older folder lacks (``cpu_seconds``) reads as missing values."""
    path = RetrainLayout(out).trainings
    if not path.is_file():
        return pd.DataFrame(columns=list(TRAINING_COLUMNS))
    table = pd.read_csv(path)
    return table.reindex(columns=[*table.columns, *(c for c in TRAINING_COLUMNS
                                                    if c not in table.columns)])


def wall_seconds(out: Path) -> float:
    """Wall seconds spent training into ``out`` so far, over every session."""
    path = RetrainLayout(out).progress
    return float(json.loads(path.read_text())["wall_seconds"]) if path.is_file() else 0.0


@dataclass(frozen=True)
class Retraining:
    """Everything the trainings of one noise ceiling need, checked.

    Attributes:
        out: The output folder (the run directory).
        settings: What decides the numbers.
        robots: The structures, in the order planned.
        jobs: The evaluation job of each role: ``seed`` (the learner) and ``baseline``
            (the random learner: the same network, never updated).
        baseline: Whether the random learner's trainings are planned (``baseline`` and
            a learner that learns).
    """

    out: Path
    settings: Settings
    robots: tuple[Robot, ...]
    jobs: dict[str, Job]
    baseline: bool

    def plan(self) -> list[Training]:
        """Every training of the noise ceiling, in the order they are submitted."""
        s = self.settings
        return plan_trainings(s.structures, seeds=s.seeds, root=s.root_seed,
                              baseline=self.baseline)


def _training_row(out: Path, training: Training, learner: str, budget: int,
                  outcome: Outcome) -> TrainingRow:
    """The ``trainings.csv`` row of one finished training."""
    curve = read_curve(RetrainLayout(out).curve(training.name))
    return TrainingRow(
        name=training.name, structure=training.structure, role=training.role, learner=learner,
        replicate=training.replicate, seed=training.seed, budget=budget,
        fitness=outcome.fitness, fitness_late=late_fitness(curve, budget),
        episodes=outcome.episodes, env_steps=outcome.env_steps,
        wall_seconds=outcome.wall_seconds, cpu_seconds=outcome.cpu_seconds)


class Retrainer:
    """Drives the evaluation pool through a :class:`Retraining`'s plan: the trainings
    not yet in ``trainings.csv`` are submitted in the plan's order, and each one that
    finishes is appended there (a failed one is reported through ``log`` and left out,
    so the next session tries it again)."""

    def __init__(self, retraining: Retraining, log: Callable[[str], None] = print) -> None:
        self.retraining, self.log = retraining, log
        self.layout = RetrainLayout(retraining.out)
        self.rows: list[TrainingRow] = read_trainings(retraining.out).to_dict("records")
        done = {row["name"] for row in self.rows}
        self.plan = retraining.plan()
        self.todo = [t for t in self.plan if t.name not in done]
        self.robots = {r.name: r for r in retraining.robots}
        self.submitted: dict[str, Training] = {}
        self.wall_before, self.started = wall_seconds(retraining.out), time.perf_counter()

    def next_candidate(self, running: Sequence[Candidate]) -> tuple[Candidate, Job] | None:
        """The next planned training, or None when every one is submitted."""
        if not self.todo:
            return None
        training = self.todo.pop(0)
        robot = self.robots[training.structure]
        candidate = Candidate(len(self.rows) + len(running), training.name,
                              robot.canonical_json(), self.retraining.settings.budget,
                              training.seed, (), OPERATOR)
        self.submitted[training.name] = training
        return candidate, self.retraining.jobs[training.role]

    def on_outcome(self, candidate: Candidate, outcome: Outcome) -> None:
        """Append a finished training to ``trainings.csv`` and the wall time so far to
        ``progress.json``."""
        training = self.submitted.pop(candidate.name)
        if outcome.error is not None:
            self.log(f"{training.name}: failed ({outcome.error.strip().splitlines()[-1]})")
            return
        learner = self.retraining.jobs[training.role].learner.name
        self.rows.append(_training_row(self.retraining.out, training, learner,
                                       self.retraining.settings.budget, outcome))
        write_csv(self.layout.trainings, self.table())
        self.write_progress()
        self.log(f"{len(self.rows)}/{len(self.plan)} {training.name}: fitness "
                 f"{outcome.fitness:+.3f} ({outcome.env_steps:,} env steps, "
                 f"{outcome.wall_seconds:.0f} s)")

    def table(self) -> pd.DataFrame:
        """The trainings finished so far, ``trainings.csv``'s columns."""
        return pd.DataFrame(self.rows, columns=list(TRAINING_COLUMNS))

    def write_progress(self) -> None:
        """``progress.json``: the wall time spent training so far, over every session."""
        seconds = self.wall_before + time.perf_counter() - self.started
        write_json(self.layout.progress, {"wall_seconds": seconds})


def run_trainings(retraining: Retraining, pool: EvaluationPool,
                  log: Callable[[str], None] = print) -> pd.DataFrame:
    """Train every planned training not yet in ``trainings.csv`` through ``pool``,
    appending each result as it arrives (and the wall time so far, over every session,
    to ``progress.json``).

    Returns:
        The whole trainings table. Failed trainings are reported through ``log`` and
        left out, so the next call tries them again.
    """
    store = RunStore(retraining.out)
    store.prepare()
    for robot in retraining.robots:
        store.save_robot(robot.name, robot)
    retrainer = Retrainer(retraining, log)
    log(f"{len(retrainer.plan) - len(retrainer.todo)} of {len(retrainer.plan)} trainings "
        f"already done; {len(retrainer.todo)} to run")
    try:
        pool.run(retrainer.next_candidate, retrainer.on_outcome)
    finally:
        retrainer.write_progress()
    return retrainer.table()
