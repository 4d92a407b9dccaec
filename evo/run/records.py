"""The typed records of a run's files, each with its one writer and its one reader.

* :class:`HistoryRow`: one row of ``history.csv``, an evaluated robot and what the GA did
  with it. The evolution appends one after every result and hands it to its listeners
  (progress, ``run.mcap``/``run.rrd``). Its fields are the columns of ``history.csv``, in
  order (:data:`HISTORY_COLUMNS`); ``record()`` is the row as ``state.json`` and
  ``history.csv`` store it, where ``parents`` is one text cell, the parents' names joined
  by ``;`` (:data:`PARENT_SEPARATOR`). :func:`write_history` writes the file,
  :func:`read_history` reads it back as a table with those columns.
* :class:`Candidate` and :class:`Member`: a robot in flight and a member of the
  population, as an evolution's ``state.json`` holds them (``evo.run.store``, which
  writes and reads that file); the evaluation is given a ``Candidate``, the GA keeps its
  population as ``Member`` records.
* :class:`RunSummary`: an evolution's ``summary.json`` (:func:`write_run_summary`,
  :func:`read_run_summary`).
* :class:`TrainSummary`: a one-robot training's ``summary.json`` (``+exp=train``;
  :func:`write_train_summary`, :func:`read_train_summary`).

Each record's JSON form is its ``record()``, a :data:`~evo.run.files.JSONObject` keyed by
its fields: the dataclass is the one list of the file's keys.
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from evo.robot.tree import Robot
from evo.run.files import JSONObject, write_csv, write_json, write_text

PARENT_SEPARATOR = ";"
"""Joins the parents' names in the ``parents`` cell of history.csv and state.json."""

STATUSES = ("trained", "stopped-early", "failed")
"""``trained``: its whole budget; ``stopped-early``: early rejection stopped it (it never
enters the population; ``fitness`` is Eq. 8 over the episodes it completed and
``predicted`` the rule's prediction); ``failed``: the evaluation raised (``error``)."""


@dataclass(frozen=True, slots=True)
class HistoryRow:
    """One evaluated robot.

    Attributes:
        birth: Birth order in the run (0-based).
        name: The robot's unique name in the run (``robots/<name>.json``).
        method: The run's method label (``E+L``, ``R+R``, ...).
        parents: The parents' names; empty for a random robot.
        operator: How it was made (``random``, ``crossover``, ``random-fallback``, ...).
        budget: Its training budget, env steps.
        seed: Its evaluation seed.
        fitness: Eq. 8 (NaN when the evaluation failed).
        accepted: Whether it entered the population.
        replaced: The member it replaced ("" if none).
        env_steps: Env steps its training took.
        episodes: Episodes its fitness averages.
        wall_seconds: Wall time of its evaluation.
        error: The failure's traceback ("" if none).
        population_best: Best fitness in the population after it was recorded.
        population_mean: Mean fitness of the population after it was recorded.
        status: One of :data:`STATUSES`.
        predicted: Early rejection's predicted final fitness (NaN if none).
        threshold: The population minimum it was bred against, the fitness it had to
            beat to enter (NaN for a robot of the initial population, and in runs
            recorded before the column existed).
        inherited_from: The parent whose trained policy its training started from
            (``ga.inheritance``); "" when it started from scratch, and in runs recorded
            before the column existed.
        eval_success_rate: The deterministic (mean action) success rate of the policy
            its training handed back, from the periodic evaluations
            (``learner.eval_interval``: the last one, or the best with
            ``learner.keep_best``); None (an empty cell) without them.
        eval_mean_return: That evaluation's mean return.
    """

    birth: int
    name: str
    method: str
    parents: tuple[str, ...]
    operator: str
    budget: int
    seed: int
    fitness: float
    accepted: bool
    replaced: str
    env_steps: int
    episodes: int
    wall_seconds: float
    error: str
    population_best: float
    population_mean: float
    status: str
    predicted: float
    threshold: float = math.nan
    inherited_from: str = ""
    eval_success_rate: float | None = None
    eval_mean_return: float | None = None

    def __post_init__(self) -> None:
        if self.status not in STATUSES:
            raise ValueError(f"status must be one of {', '.join(STATUSES)}, got {self.status!r}")

    @property
    def failed(self) -> bool:
        """Whether the evaluation failed."""
        return bool(self.error)

    @property
    def stopped_early(self) -> bool:
        """Whether early rejection stopped its training."""
        return self.status == "stopped-early"

    def record(self) -> JSONObject:
        """The row as ``state.json`` and ``history.csv`` hold it: its fields in order
        (:data:`HISTORY_COLUMNS`), ``parents`` joined by :data:`PARENT_SEPARATOR`."""
        row: JSONObject = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        row["parents"] = PARENT_SEPARATOR.join(self.parents)
        return row

    @classmethod
    def from_record(cls, row: Mapping[str, Any]) -> HistoryRow:
        """The row ``record()`` wrote, from ``state.json`` or a row of :func:`read_history`
        (an empty text cell, read as NaN, is ""); a run from before ``status``,
        ``predicted``, ``threshold``, ``inherited_from`` and the evaluation's columns existed
        gets ``trained``/``failed``, NaN, NaN, "" and None.

        Raises:
            KeyError, TypeError, ValueError: A missing column or a value of the wrong type.
        """
        parents = _text(row["parents"])
        error = _text(row["error"])
        return cls(
            birth=int(row["birth"]),
            name=str(row["name"]),
            method=str(row["method"]),
            parents=tuple(parents.split(PARENT_SEPARATOR)) if parents else (),
            operator=str(row["operator"]),
            budget=int(row["budget"]),
            seed=int(row["seed"]),
            fitness=float(row["fitness"]),
            accepted=bool(row["accepted"]),
            replaced=_text(row["replaced"]),
            env_steps=int(row["env_steps"]),
            episodes=int(row["episodes"]),
            wall_seconds=float(row["wall_seconds"]),
            error=error,
            population_best=float(row["population_best"]),
            population_mean=float(row["population_mean"]),
            status=_text(row.get("status")) or ("failed" if error else "trained"),
            predicted=float(row.get("predicted", math.nan)),
            threshold=float(row.get("threshold", math.nan)),
            inherited_from=_text(row.get("inherited_from")),
            eval_success_rate=_number(row.get("eval_success_rate")),
            eval_mean_return=_number(row.get("eval_mean_return")),
        )


def _number(value: object) -> float | None:
    """An optional number cell: None for a missing one (None, or NaN as pandas reads an
    empty cell)."""
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return None
    return float(value)  # type: ignore[arg-type]


def _text(value: object) -> str:
    """A text cell: "" for a missing one (None, or NaN as pandas reads an empty cell)."""
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return ""
    return str(value)


HISTORY_COLUMNS = tuple(f.name for f in dataclasses.fields(HistoryRow))
"""The columns of history.csv, in order (one row per evaluated robot)."""

HISTORY_TEXT_COLUMNS = ("name", "parents", "error", "replaced", "operator", "inherited_from")
"""The columns of history.csv read as text whatever they hold (an empty cell is NaN)."""


def write_history(path: Path, rows: Sequence[HistoryRow]) -> Path:
    """Write ``history.csv`` (atomically): one row per evaluated robot, in ``rows``' order."""
    return write_csv(path, pd.DataFrame([row.record() for row in rows],
                                        columns=list(HISTORY_COLUMNS)))


def read_history(path: Path) -> pd.DataFrame:
    """``history.csv`` as written by :func:`write_history`, a column per field of
    :class:`HistoryRow` it holds (a run recorded before a column existed lacks it).

    Raises:
        OSError, ValueError: The file is missing or not a readable CSV.
    """
    return pd.read_csv(path, dtype=dict.fromkeys(HISTORY_TEXT_COLUMNS, str))


# ---------------------------------------------------------------- the saved state's records


@dataclass(frozen=True, slots=True)
class Candidate:
    """One robot to evaluate (a candidate structure of the run); ``state.json`` holds
    those in flight.

    Attributes:
        birth: Birth order in the run (0-based).
        name: Unique id of the evaluation (the robot's name, made unique if needed).
        robot: The robot's canonical ``evo.robot/1`` JSON.
        budget: Training budget, env steps.
        seed: The evaluation's own seed.
        parents: Names of the parents (empty for random robots).
        operator: How the robot was made (random, crossover, ...).
        threshold: The population minimum it was bred against, which it must beat to
            enter the population (NaN when it enters anyway: an initial robot).
        inherit: The parent whose trained policy it starts from ("" for none:
            ``ga.inheritance`` off, or a robot without parents); its checkpoint is the
            run's ``evals/<inherit>.pt``.
        inherit_actuators: For each of its actuators, the parent's actuator it follows,
            or -1 (``evo.components.inheritance.PolicyStart``).
    """

    birth: int
    name: str
    robot: str
    budget: int
    seed: int
    parents: tuple[str, ...] = ()
    operator: str = "random"
    threshold: float = float("nan")
    inherit: str = ""
    inherit_actuators: tuple[int, ...] = ()

    def record(self) -> JSONObject:
        """The candidate as ``state.json`` holds it: its fields."""
        data: JSONObject = dataclasses.asdict(self)
        return data

    @classmethod
    def from_record(cls, data: Mapping[str, Any]) -> Candidate:
        """The candidate ``record()`` wrote; one saved before ``inherit_actuators``
        existed follows no parent's actuators.

        Raises:
            KeyError, TypeError: A missing field or one it does not have.
        """
        return cls(**{**data, "parents": tuple(data["parents"]),
                      "inherit_actuators": tuple(data.get("inherit_actuators", ()))})


@dataclass(frozen=True, slots=True)
class Member:
    """One evaluated robot in the population; ``state.json`` and ``population.json``
    hold its name and fitness (``record()``), its robot is ``robots/<name>.json``."""

    name: str
    robot: Robot
    fitness: float

    def record(self) -> JSONObject:
        """The member as ``state.json`` and ``population.json`` hold it."""
        return {"name": self.name, "fitness": self.fitness}


# ---------------------------------------------------------------- an evolution's summary


@dataclass(frozen=True)
class RunSummary:
    """An evolution run so far: its ``summary.json``.

    Attributes:
        method: The run's method label (``E+L``, ...).
        robots_evaluated: History rows so far.
        robot_budget: Robots the run evaluates in all.
        failed: Evaluations that failed.
        best_robot: The best robot's name (None before one is trained).
        best_fitness: Its fitness.
        best_initial_fitness: The best fitness of a random (parentless) robot.
        accept_rate: The share of offspring that entered the population.
        env_steps: Env steps of every evaluation.
        wall_seconds: Wall time over every session of the run.
        steps_per_second: ``env_steps / wall_seconds``.
        complete: Whether the budget is spent.
        stopped_early: Offspring early rejection stopped.
        env_steps_saved: Env steps of their budgets they did not use.
        best_note: Why the best fitness is provisional ("" when it is not).
    """

    method: str
    robots_evaluated: int
    robot_budget: int
    failed: int
    best_robot: str | None
    best_fitness: float | None
    best_initial_fitness: float | None
    accept_rate: float | None
    env_steps: int
    wall_seconds: float
    steps_per_second: float
    complete: bool
    stopped_early: int = 0
    env_steps_saved: int = 0
    best_note: str = ""

    @classmethod
    def of(cls, history: Sequence[HistoryRow], *, method: str, robot_budget: int,
           wall_seconds: float) -> RunSummary:
        """The summary of a run with ``history`` so far."""
        done = [r for r in history if not r.failed]
        trained = [r for r in done if not r.stopped_early]
        # A robot none of whose episodes ended has only a provisional fitness (the mean
        # return of its unfinished episodes): it is named best only if no robot is better
        # placed, and then with a note. A robot stopped early is never named best.
        finished = [r for r in trained if r.episodes > 0]
        best = max(finished or trained, key=lambda r: r.fitness, default=None)
        initial = [r.fitness for r in done if not r.parents]
        steps = int(sum(r.env_steps for r in history))
        stopped = [r for r in history if r.stopped_early]
        offspring = [r for r in history if r.parents]
        return cls(
            method=method,
            robots_evaluated=len(history),
            robot_budget=robot_budget,
            failed=len(history) - len(done),
            best_robot=best.name if best else None,
            best_fitness=best.fitness if best else None,
            best_initial_fitness=max(initial) if initial else None,
            accept_rate=float(np.mean([r.accepted for r in offspring])) if offspring else None,
            env_steps=steps,
            wall_seconds=wall_seconds,
            steps_per_second=steps / max(wall_seconds, 1e-9),
            complete=len(history) >= robot_budget,
            stopped_early=len(stopped),
            env_steps_saved=int(sum(max(0, r.budget - r.env_steps) for r in stopped)),
            best_note=(
                "no robot finished an episode within its budget: the best fitness is the "
                "mean return of unfinished episodes" if best and not finished else ""),
        )

    def record(self) -> JSONObject:
        """The summary as ``summary.json`` (and the run's recordings) hold it: its fields."""
        return dataclasses.asdict(self)


def write_run_summary(path: Path, summary: RunSummary) -> Path:
    """Write an evolution's ``summary.json`` (atomically)."""
    return write_json(path, summary.record())


def read_run_summary(path: Path) -> RunSummary | None:
    """An evolution's ``summary.json``; None when there is none yet.

    Raises:
        ValueError: Naming the file, when it is not a summary :func:`write_run_summary`
            wrote (older runs lack ``stopped_early``, ``env_steps_saved`` and
            ``best_note``, and read with their defaults).
    """
    data = _read_json(path)
    if data is None:
        return None
    known = {f.name for f in dataclasses.fields(RunSummary)}
    try:
        return RunSummary(**{k: v for k, v in data.items() if k in known})
    except TypeError as err:
        raise ValueError(f"{path}: not an evolution's summary ({err})") from None


# ---------------------------------------------------------------- a training's summary


@dataclass(frozen=True)
class TrainSummary:
    """One robot's training (``+exp=train``): its ``summary.json``.

    Attributes:
        robot: The robot's name.
        seed: The training seed.
        fitness: Eq. 8 over its training episodes.
        env_steps: Env steps it trained for.
        learner: The learner's name.
        arena: The env's name.
        episodes: Episodes its fitness averages.
        wall_seconds: Wall time of the training.
        steps_per_second: Its speed.
        unstable_episodes: Episodes cut short by a numerical blow-up.
        timing_seconds: Wall time by phase of the training.
        success_rate: Success rate of the deterministic evaluation (None without one).
        eval_mean_return: Its mean return.
        eval_episodes: Its episodes.
        eval_time_to_target: Its mean simulated seconds to reach the target over the
            episodes that reached it; None when none did (and in summaries written
            before the key existed).
        stochastic_success_rate: Success rate of the same episodes with the policy's
            random actions, as training draws them (None without an evaluation, and in
            summaries written before the key existed).
        stochastic_mean_return: Their mean return.
        kept_at: With ``learner.keep_best``, the env steps at which the written policy
            scored best in the periodic evaluation (absent otherwise).
    """

    robot: str
    seed: int
    fitness: float
    env_steps: float = math.nan
    learner: str = ""
    arena: str = ""
    episodes: int = 0
    wall_seconds: float = math.nan
    steps_per_second: float = math.nan
    unstable_episodes: int = 0
    timing_seconds: dict[str, float] = field(default_factory=dict)
    success_rate: float | None = None
    eval_mean_return: float | None = None
    eval_episodes: int | None = None
    eval_time_to_target: float | None = None
    stochastic_success_rate: float | None = None
    stochastic_mean_return: float | None = None
    kept_at: int | None = None

    EVALUATION = ("success_rate", "eval_mean_return", "eval_episodes", "eval_time_to_target",
                  "stochastic_success_rate", "stochastic_mean_return")
    """The keys of the evaluation after training, written only after one."""

    def record(self) -> JSONObject:
        """The summary as ``summary.json`` holds it: its fields, the evaluation's only
        after one."""
        data: JSONObject = dataclasses.asdict(self)
        if self.eval_episodes is None:
            for key in self.EVALUATION:
                data.pop(key)
        if self.kept_at is None:
            data.pop("kept_at")
        return data


def write_train_summary(path: Path, summary: TrainSummary) -> Path:
    """Write a training's ``summary.json`` (atomically)."""
    return write_json(path, summary.record())


def read_train_summary(path: Path) -> TrainSummary | None:
    """A training's ``summary.json``; None when there is none, or it is another kind of
    summary (an evolution's, an evaluation's: it names no ``robot``, ``seed`` and
    ``fitness``).

    A summary written before ``eval_time_to_target`` existed reads with None there.

    Raises:
        ValueError: Naming the file, when it is not readable JSON.
    """
    data = _read_json(path)
    if data is None or not {"robot", "seed", "fitness"} <= data.keys():
        return None
    known = {f.name for f in dataclasses.fields(TrainSummary)}
    return TrainSummary(**{k: v for k, v in data.items() if k in known})


def _read_json(path: Path) -> dict[str, Any] | None:
    """A JSON object file; None when it is missing or holds something else."""
    if not path.is_file():
        return None
    try:
        data = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as err:
        raise ValueError(f"{path}: not readable JSON ({err})") from None
    return data if isinstance(data, dict) else None


# ---------------------------------------------------------------- a retraining's files


@dataclass(frozen=True)
class RetrainSettings:
    """What decides a retraining's numbers (``+exp=retrain``): its ``settings.json``.

    Attributes:
        overrides: The command's config overrides.
        budget: Env steps per training.
        seeds: Trainings per structure, each with its own seed.
        root_seed: The root seed (of a random sample and of spawned training seeds).
        baseline: Whether each structure is also trained once with the random learner.
        structures: The structures' names, in the order planned.
        config: The resolved config without the executor group (YAML).
        first_seed: None: each training's seed is spawned from the root seed, the
            structure and the replicate; an integer N: the trainings of a structure use
            seeds N, N+1, ... as ``+exp=train seed=N`` does.
        evaluate: Whether each training is followed by a deterministic evaluation.
        confirm: Trainings under fresh seeds of the best structure of each origin.
        labels: The structures' labels (a robot file's name, a GA run's), in order.
    """

    overrides: tuple[str, ...]
    budget: int
    seeds: int
    root_seed: int
    baseline: bool
    structures: tuple[str, ...]
    config: str
    first_seed: int | None = None
    evaluate: bool = False
    confirm: int = 0
    labels: tuple[str, ...] = ()

    COMPARED = ("budget", "root_seed", "baseline", "first_seed", "evaluate", "config")
    """What must match to continue a folder: the settings of every training in it. The
    structures, the seeds per structure and the confirmation may change (a folder grows:
    finished trainings are kept, and the others run), and so may the overrides that do
    not change the resolved config (the executor's)."""

    def record(self) -> JSONObject:
        """The settings as ``settings.json`` holds them."""
        data: JSONObject = dataclasses.asdict(self)
        return data

    @classmethod
    def from_record(cls, data: Mapping[str, Any]) -> RetrainSettings:
        """The settings of a ``settings.json`` (lists as tuples; keys that an older folder
        lacks take their defaults, keys this version does not know are left out)."""
        known = {f.name for f in dataclasses.fields(cls)}
        kept: dict[str, Any] = {k: tuple(v) if isinstance(v, list) else v
                                for k, v in data.items() if k in known}
        return cls(**kept)


def write_retrain_settings(path: Path, settings: RetrainSettings) -> Path:
    """Write a retraining's ``settings.json`` (atomically)."""
    return write_text(path, json.dumps(settings.record(), indent=2) + "\n")


def read_retrain_settings(path: Path) -> RetrainSettings | None:
    """A retraining's ``settings.json``; None when there is none.

    Raises:
        ValueError: Naming the file, when it does not parse as settings.
    """
    data = _read_json(path)
    if data is None:
        return None
    try:
        return RetrainSettings.from_record(data)
    except TypeError as err:
        raise ValueError(f"{path}: not a retraining's settings ({err})") from None


def read_progress(path: Path) -> float:
    """A retraining's ``progress.json``: the wall seconds spent training so far, over
    every session (0 before the first training finished)."""
    data = _read_json(path)
    return 0.0 if data is None else float(data["wall_seconds"])


def write_progress(path: Path, wall_seconds: float) -> Path:
    """Write a retraining's ``progress.json`` (atomically)."""
    return write_json(path, {"wall_seconds": wall_seconds})


TRAINING_ROLES = ("seed", "baseline")
"""``seed``: one of a structure's trainings under the learner; ``baseline``: its training
with the random learner (the same network, never updated)."""


@dataclass(frozen=True, slots=True)
class TrainingRow:
    """One finished training of a retraining: a row of ``trainings.csv``.

    Attributes:
        name: Unique name (its files are ``evals/<name>.*``).
        structure: The robot's name (``robot-<hash8>``).
        role: One of :data:`TRAINING_ROLES`.
        learner: The learner's name.
        replicate: Which of the structure's trainings (0-based; the confirmation's go on
            after the others').
        seed: Its seed.
        budget: Its budget, env steps.
        fitness: Eq. 8 over its episodes.
        fitness_late: The mean return of the episodes completed after half the budget.
        episodes: Episodes its fitness averages.
        env_steps: Env steps it trained for.
        wall_seconds: Its wall time.
        cpu_seconds: Its process's CPU time (its cost, whatever else the machine ran).
        robot: The structure's label (a robot file's name, a GA run's name, ...).
        origin: Where the structure came from: ``random``, ``designed`` (a robot file),
            ``evolved`` (a GA run's best) or ``population`` (a GA run's population).
        method: The GA run's method (``E+L``, ...), or the origin for a structure of no run.
        run: The GA run it came from ("" for none).
        arena: The env's name.
        success_rate: The deterministic evaluation's share of episodes that reached the
            target (NaN without one).
        eval_mean_return: Its mean return.
        eval_time_to_target: Its mean simulated seconds to reach the target over the
            episodes that did (NaN when none did).
        eval_episodes: Its episodes (0 without one).
        confirmation: Whether it is a confirmation's training (a fresh seed of a
            structure chosen on the others).
        stochastic_success_rate: The same episodes' success rate with the policy's
            random actions, as training draws them (NaN without an evaluation).
        stochastic_mean_return: Their mean return.
    """

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
    robot: str = ""
    origin: str = ""
    method: str = ""
    run: str = ""
    arena: str = ""
    success_rate: float = math.nan
    eval_mean_return: float = math.nan
    eval_time_to_target: float = math.nan
    eval_episodes: int = 0
    confirmation: bool = False
    stochastic_success_rate: float = math.nan
    stochastic_mean_return: float = math.nan

    def record(self) -> JSONObject:
        """The row as ``trainings.csv`` holds it."""
        data: JSONObject = dataclasses.asdict(self)
        return data


TRAINING_COLUMNS = tuple(f.name for f in dataclasses.fields(TrainingRow))
"""The columns of ``trainings.csv``, in order (a folder written before the columns after
``cpu_seconds`` existed reads with them missing)."""


def write_trainings(path: Path, table: pd.DataFrame) -> Path:
    """Write ``trainings.csv`` (atomically) from a table of :data:`TRAINING_COLUMNS`."""
    return write_csv(path, table[list(TRAINING_COLUMNS)])


def read_trainings(path: Path) -> pd.DataFrame:
    """``trainings.csv`` as a table of :data:`TRAINING_COLUMNS` and any others it has
    (empty when there is none yet); a column an older folder lacks reads as missing
    values."""
    if not path.is_file():
        return pd.DataFrame(columns=list(TRAINING_COLUMNS))
    table = pd.read_csv(path)
    return table.reindex(columns=[*table.columns, *(c for c in TRAINING_COLUMNS
                                                    if c not in table.columns)])


@dataclass(frozen=True, slots=True)
class SweepTrial:
    """What one trial of the noise sweep measured: its ``trial.json``.

    Attributes:
        objective: The agreement metric the sweep maximises.
        value: Its value (the point estimate over the trial's structures).
        core_seconds_per_robot: The trainings' mean CPU time, the cost minimised.
        spearman: Spearman ρ between seeds.
        icc: ICC(1).
        top_quarter: Top-quarter agreement.
        env_steps_per_second: Env steps over the trainings' wall time.
        overrides: The trial's overrides (the command's and the sweeper's).
    """

    objective: str
    value: float
    core_seconds_per_robot: float
    spearman: float
    icc: float
    top_quarter: float
    env_steps_per_second: float
    overrides: tuple[str, ...]

    def values(self) -> tuple[float, float]:
        """The two objectives Optuna is told: agreement (max) and cost (min)."""
        return self.value, self.core_seconds_per_robot

    def record(self) -> JSONObject:
        """The trial as ``trial.json`` holds it."""
        data: JSONObject = dataclasses.asdict(self)
        return data


def write_sweep_trial(path: Path, trial: SweepTrial) -> Path:
    """Write a trial's ``trial.json`` (atomically)."""
    return write_text(path, json.dumps(trial.record(), indent=2) + "\n")


def read_sweep_trial(path: Path) -> SweepTrial | None:
    """A trial's ``trial.json``; None when there is none.

    Raises:
        ValueError: Naming the file, when it is not a trial's.
    """
    data = _read_json(path)
    if data is None:
        return None
    try:
        return SweepTrial(**{**data, "overrides": tuple(data["overrides"])})
    except (TypeError, KeyError) as err:
        raise ValueError(f"{path}: not a noise sweep trial ({err})") from None
