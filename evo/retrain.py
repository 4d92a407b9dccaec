"""Retraining fixed structures: evo's one engine for every training outside an evolution.

``task=retrain`` trains the structures of its sources (a random sample, robot files or a
folder of them, each GA run's best, a GA run's population) ``seeds`` times each, every
training with its own seed, through the evaluation pool (``evo.pool``) on the config's
executor, as an evolution's evaluations run: the same lost-work retries, signals, lock
and ``resume=``. Each training lands in ``trainings.csv`` as it finishes (one
:class:`evo.run.records.TrainingRow`), with the wall time so far in ``progress.json``.
Its uses:

* the noise ceiling (``+exp=retrain``): a sample trained under seeds spawned from the
  root seed, and once with the random learner (``baseline``); ``analysis.noise_ceiling``
  reports how well one seed's fitness ranks the structures as another's does, and the
  noise sweep's trials (:mod:`evo.sweep`) optimise it;
* the designer comparison (``+exp=designer``): each GA run's best robot and every
  hand-made robot trained as ``+exp=train seed=N`` trains them (``first_seed``), each
  followed by a deterministic evaluation (``evaluate``), then the best of each origin
  trained again under fresh seeds (``confirm``); ``analysis.designer`` compares them.

Resumable: the same command again (or ``resume=DIR``) reuses the finished trainings and
trains the others, the ones in flight when it stopped included, with their own seeds.
``settings.json`` holds what decides the numbers
(:class:`evo.run.records.RetrainSettings`); a folder whose trainings ran under other
settings is refused, while one that gains structures or seeds grows. The files are
named in ``evo.run.layout`` (:class:`evo.run.layout.RetrainLayout`).
"""

from __future__ import annotations

import json
import math
import os
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from evo.evaluation import Job, Outcome
from evo.pool import EvaluationPool
from evo.record import read_curve
from evo.robot import (
    GeneratorParams,
    InvalidRobotError,
    Limits,
    Robot,
    RobotFileError,
    load_robot,
    random_robots,
)
from evo.run.layout import RetrainLayout, RunLayout, file_stem
from evo.run.records import (
    TRAINING_COLUMNS,
    Candidate,
    RetrainSettings,
    TrainingRow,
    read_progress,
    read_retrain_settings,
    read_run_summary,
    read_trainings,
    write_progress,
    write_retrain_settings,
    write_trainings,
)
from evo.run.store import RunStore

OPERATOR = "retrain"
"""``Candidate.operator`` of a retraining."""
ORIGINS = ("random", "designed", "evolved", "population")
"""Where a structure came from: a random sample, a robot file, a GA run's best, a GA
run's population."""
CONFIRMED_ORIGINS = ("evolved", "designed")
"""The origins whose best structure a confirmation trains again."""


class RetrainError(ValueError):
    """A bad setting, robot or output folder; the message names the key."""


@dataclass(frozen=True, slots=True)
class RetrainConfig:
    """``retrain``: which structures ``task=retrain`` trains, how often, how long.

    Attributes:
        robots: A robot file, or a folder of them (every ``*.json``), each under its
            file name.
        random: How many random robots of distinct structure to draw with the root seed
            (at least 3).
        runs: GA run directories, or folders holding them: each run's best robot
            (``summary.json``'s ``best_robot``), under the run's name.
        population: A GA run directory: the robots of its population (``state.json``).
        seeds: Trainings per structure, each with its own seed (at least 2).
        first_seed: None: each training's seed is spawned from the root seed, the
            structure and the replicate (:func:`training_seed`); N: a structure's
            trainings use seeds N, N+1, ... as ``+exp=train seed=N`` does.
        budget: Env steps per training; None: ``learner.total_steps``.
        baseline: Also train each structure once with the random learner.
        evaluate: Evaluate each training deterministically (``learner.eval_episodes``
            episodes of the policy's mean action, seed + 1), as ``+exp=train`` does.
        confirm: Once every training is done, train the best evolved and the best
            designed structure (highest mean evaluation return, or fitness without an
            evaluation) again under this many fresh seeds (0: none; else at least 2).
    """

    robots: str | None = None
    random: int | None = None
    runs: tuple[str, ...] = ()
    population: str | None = None
    seeds: int = 2
    first_seed: int | None = None
    budget: int | None = None
    baseline: bool = True
    evaluate: bool = False
    confirm: int = 0

    def __post_init__(self) -> None:
        if self.robots is None and self.random is None and not self.runs and (
                self.population is None):
            raise ValueError("robots: give the structures to train: robots=<robot file or "
                             "folder>, random=<count>, runs=[<GA run>, ...] or "
                             "population=<GA run>")
        if self.seeds < 2:
            raise ValueError(f"seeds: expected at least 2, got {self.seeds}")
        if self.random is not None and self.random < 3:
            raise ValueError(f"random: expected at least 3 robots, got {self.random}")
        if self.budget is not None and self.budget < 1:
            raise ValueError(f"budget: expected a positive env-step count, got {self.budget}")
        if self.first_seed is not None and self.first_seed < 0:
            raise ValueError(f"first_seed: expected a non-negative seed, got {self.first_seed}")
        if self.confirm == 1 or self.confirm < 0:
            raise ValueError(f"confirm: expected 0 or at least 2 fresh seeds, got {self.confirm}")


# ---------------------------------------------------------------- the structures


@dataclass(frozen=True)
class Entry:
    """One structure to train.

    Attributes:
        label: Its name in the retraining (a robot file's name, a GA run's, or the
            robot's own for a random one).
        origin: One of :data:`ORIGINS`.
        method: The GA run's method (``E+L``, ...), or the origin for no run.
        run: The GA run it came from ("" for none).
        robot: The robot.
    """

    label: str
    origin: str
    method: str
    run: str
    robot: Robot


def _robot_files(path: Path, limits: Limits) -> list[Entry]:
    """Every robot file at ``path`` (a file, or a folder's ``*.json``), under its name."""
    if path.is_file():
        files = [path]
    elif path.is_dir():
        files = sorted(path.glob("*.json"))
        if not files:
            raise RetrainError(f"retrain.robots {path}: no robot files (*.json) in it")
    else:
        raise RetrainError(f"retrain.robots {path}: no such folder")
    try:
        return [Entry(p.stem, "designed", "designed", "", load_robot(p, limits)) for p in files]
    except (RobotFileError, InvalidRobotError) as err:
        raise RetrainError(f"retrain.robots: {err}") from None


def run_dirs(paths: Sequence[Path]) -> list[Path]:
    """Every evolution run directory in ``paths`` (run directories or folders holding
    them, at any depth), each once, in the order given.

    Raises:
        RetrainError: For a path that is no run directory and holds none.
    """
    found: dict[Path, None] = {}
    for path in paths:
        inside = [path] if RunLayout(path).is_run() else (
            RunLayout.runs_under(path) if path.is_dir() else [])
        if not inside:
            raise RetrainError(f"retrain.runs {path}: not a GA run directory (no "
                               f"{RunLayout(path).history.name}) and holds none")
        found.update((p.resolve(), None) for p in inside)
    return list(found)


def run_labels(dirs: Sequence[Path]) -> list[str]:
    """Short unique names of run directories: their names, or their paths relative to
    the folder they share when two names are alike."""
    names = [d.name for d in dirs]
    if len(set(names)) == len(names):
        return names
    common = Path(os.path.commonpath(dirs))
    return [d.relative_to(common).as_posix() or d.name for d in dirs]


def _runs_best(paths: Sequence[Path], limits: Limits) -> list[Entry]:
    """The best robot of every GA run in ``paths``, under the run's name."""
    dirs = run_dirs(paths)
    entries = []
    for run_dir, label in zip(dirs, run_labels(dirs), strict=True):
        layout = RunLayout(run_dir)
        try:
            summary = read_run_summary(layout.summary)
        except ValueError as err:
            raise RetrainError(f"retrain.runs: {err}") from None
        if summary is None or summary.best_robot is None:
            raise RetrainError(f"retrain.runs: {layout.summary} names no best_robot "
                               "(no robot trained yet?)")
        try:
            robot = load_robot(layout.robot(summary.best_robot), limits)
        except (RobotFileError, InvalidRobotError) as err:
            raise RetrainError(f"retrain.runs: {err}") from None
        entries.append(Entry(label, "evolved", summary.method or "evolved", str(run_dir), robot))
    return entries


def _population(run_dir: Path) -> list[Entry]:
    """The robots of a GA run's population as its ``state.json`` holds it."""
    try:
        state = RunStore(run_dir).load()
        method = state.history[0].method if state.history else "evolved"
    except (OSError, ValueError) as err:
        raise RetrainError(f"retrain.population: {err}") from None
    return [Entry(m.name, "population", method, str(run_dir.resolve()), m.robot)
            for m in state.population]


def load_entries(config: RetrainConfig, root_seed: int, *, generator: GeneratorParams,
                 limits: Limits) -> list[Entry]:
    """The structures of every source of ``config``: the runs' best first, then the
    population, the robot files and the random sample.

    Raises:
        RetrainError: For a missing or empty folder, a file that is not a valid robot, a
            run without a best robot (each named), or two structures under one label.
    """
    entries = _runs_best([Path(p) for p in config.runs], limits)
    if config.population is not None:
        entries += _population(Path(config.population))
    if config.robots is not None:
        entries += _robot_files(Path(config.robots), limits)
    if config.random is not None:
        try:
            robots = random_robots(np.random.default_rng(root_seed), config.random, generator,
                                   limits)
        except ValueError as err:
            raise RetrainError(f"retrain.random {config.random}: {err}") from None
        entries += [Entry(r.name, "random", "random", "", r) for r in robots]
    seen: dict[str, Entry] = {}
    for entry in entries:
        if entry.label in seen:
            raise RetrainError(
                f"two structures are named {entry.label!r} ({seen[entry.label].origin} and "
                f"{entry.origin}); rename the run directory or the robot file")
        seen[entry.label] = entry
    return entries


# ---------------------------------------------------------------- the plan


@dataclass(frozen=True, slots=True)
class Training:
    """One training of one structure.

    Attributes:
        name: Unique name (file stem in ``evals/``).
        label: The structure's label.
        role: ``seed`` (one of its trainings) or ``baseline`` (the random learner).
        replicate: Which of the structure's trainings (0-based).
        seed: Its seed.
        confirmation: Whether it is a confirmation's.
    """

    name: str
    label: str
    role: str
    replicate: int
    seed: int
    confirmation: bool = False


def training_seed(root: int, structure: str, replicate: int) -> int:
    """The seed of a structure's ``replicate``-th training: the same for the same root
    seed whatever the other structures, the settings or the order of training."""
    key = int(structure.removeprefix("robot-")[:8], 16)
    return int(np.random.SeedSequence(root, spawn_key=(key, replicate)).generate_state(1)[0])


def _training(entry: Entry, settings: RetrainSettings, replicate: int, *,
              role: str = "seed", confirmation: bool = False) -> Training:
    """The ``replicate``-th training of ``entry``: with spawned seeds named by its
    structure (``robot-…_s1``, ``robot-…_baseline``), with ``first_seed`` by its label and
    seed (``four_wheeler_seed3``)."""
    if settings.first_seed is None:
        seed = training_seed(settings.root_seed, entry.robot.name, replicate)
        stem = entry.robot.name
        name = f"{stem}_baseline" if role == "baseline" else f"{stem}_s{replicate}"
    else:
        seed = settings.first_seed + replicate
        stem = file_stem(entry.label)
        name = f"{stem}_baseline" if role == "baseline" else f"{stem}_seed{seed}"
    return Training(name, entry.label, role, replicate, seed, confirmation)


def plan_trainings(entries: Sequence[Entry], settings: RetrainSettings) -> list[Training]:
    """``settings.seeds`` trainings per structure, then one random-learner training
    (the seed of replicate 0) per structure when ``settings.baseline``. With spawned
    seeds, a structure that two labels share is trained once."""
    trained: dict[str, Entry] = {}
    for entry in entries:
        key = entry.robot.name if settings.first_seed is None else entry.label
        trained.setdefault(key, entry)
    plan = [_training(e, settings, r) for e in trained.values() for r in range(settings.seeds)]
    if settings.baseline:
        plan += [_training(e, settings, 0, role="baseline") for e in trained.values()]
    return plan


def confirmation_plan(entries: Sequence[Entry], table: pd.DataFrame,
                      settings: RetrainSettings) -> list[Training]:
    """The confirmation: the best structure of each of :data:`CONFIRMED_ORIGINS` in
    ``table`` (the finished trainings), trained again under ``settings.confirm`` fresh
    seeds (the replicates after the others'). The best: the highest mean evaluation
    return over its seed trainings, or mean fitness without an evaluation. A folder
    that holds confirmation trainings keeps the structures it chose."""
    if not settings.confirm or table.empty:
        return []
    kept = table[table["confirmation"].astype(bool)]
    if len(kept):
        chosen = list(dict.fromkeys(kept["robot"]))
    else:
        done = table[(table["role"] == "seed") & ~table["confirmation"].astype(bool)]
        score = "eval_mean_return" if settings.evaluate else "fitness"
        means = done.groupby(["origin", "robot"], sort=False)[score].mean()
        chosen = [str(means[origin].idxmax()) for origin in CONFIRMED_ORIGINS
                  if origin in means.index.get_level_values(0)
                  and means[origin].notna().any()]
    by_label = {e.label: e for e in entries}
    return [_training(by_label[label], settings, settings.seeds + c, confirmation=True)
            for label in chosen if label in by_label for c in range(settings.confirm)]


# ---------------------------------------------------------------- the folder


WhatTrains = Callable[[str], object]
"""The typed groups of a resolved config (:attr:`RetrainSettings.config`) that decide a
training's result (``evo.edge.what_trains``): two configs alike there train alike."""


def _check_settings(out: Path, settings: RetrainSettings, what_trains: WhatTrains) -> None:
    """Refuse an output folder whose trainings ran under other settings."""
    layout = RetrainLayout(out)
    try:
        stored = read_retrain_settings(layout.settings)
    except ValueError as err:
        raise RetrainError(f"hydra.run.dir {out}: {err}") from None
    if stored is None:
        return
    mine, theirs = settings.record(), stored.record()
    differ = [k for k in RetrainSettings.COMPARED if k != "config"
              and json.dumps(theirs[k]) != json.dumps(mine[k])]
    if what_trains(stored.config) != what_trains(settings.config):
        differ.append("config")
    if differ:
        raise RetrainError(
            f"hydra.run.dir {out}: holds a noise ceiling with other settings "
            f"({', '.join(differ)} differ); give the same arguments to continue it, or "
            "another output folder")


def open_folder(out: Path, settings: RetrainSettings, what_trains: WhatTrains) -> None:
    """Create ``out`` or continue it: refuse a folder that is not one or whose trainings
    ran under other settings (``config`` compared by ``what_trains``), then store
    ``settings.json``."""
    if out.exists() and not out.is_dir():
        raise RetrainError(f"hydra.run.dir {out}: exists and is not a folder")
    out.mkdir(parents=True, exist_ok=True)
    _check_settings(out, settings, what_trains)
    write_retrain_settings(RetrainLayout(out).settings, settings)


# ---------------------------------------------------------------- the trainings


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


@dataclass(frozen=True)
class Retraining:
    """Everything the trainings of one retraining need, checked.

    Attributes:
        out: The output folder (the run directory).
        settings: What decides the numbers.
        entries: The structures, in the order planned.
        jobs: The evaluation job of each role: ``seed`` (the learner) and ``baseline``
            (the random learner: the same network, never updated).
        arena: The env's name.
    """

    out: Path
    settings: RetrainSettings
    entries: tuple[Entry, ...]
    jobs: dict[str, Job]
    arena: str

    def plan(self) -> list[Training]:
        """Every training but the confirmation's, in the order they are submitted."""
        return plan_trainings(self.entries, self.settings)


def _training_row(retraining: Retraining, training: Training, outcome: Outcome) -> TrainingRow:
    """The ``trainings.csv`` row of one finished training."""
    budget = retraining.settings.budget
    curve = read_curve(RetrainLayout(retraining.out).curve(training.name))
    entry = next(e for e in retraining.entries if e.label == training.label)
    evaluation, noisy = outcome.evaluation, outcome.stochastic
    time_to_target = None if evaluation is None else evaluation.time_to_target
    return TrainingRow(
        name=training.name, structure=entry.robot.name, role=training.role,
        learner=retraining.jobs[training.role].learner.name, replicate=training.replicate,
        seed=training.seed, budget=budget, fitness=outcome.fitness,
        fitness_late=late_fitness(curve, budget), episodes=outcome.episodes,
        env_steps=outcome.env_steps, wall_seconds=outcome.wall_seconds,
        cpu_seconds=outcome.cpu_seconds, robot=entry.label, origin=entry.origin,
        method=entry.method, run=entry.run, arena=retraining.arena,
        success_rate=math.nan if evaluation is None else evaluation.success_rate,
        eval_mean_return=math.nan if evaluation is None else evaluation.mean_return,
        eval_time_to_target=math.nan if time_to_target is None else time_to_target,
        eval_episodes=0 if evaluation is None else len(evaluation.returns),
        confirmation=training.confirmation,
        stochastic_success_rate=math.nan if noisy is None else noisy.success_rate,
        stochastic_mean_return=math.nan if noisy is None else noisy.mean_return)


class Retrainer:
    """Drives the evaluation pool through a :class:`Retraining`'s plan: the trainings
    not yet in ``trainings.csv`` are submitted in the plan's order, then, once they are
    all done, the confirmation's; each one that finishes is appended there (a failed
    one is reported through ``log`` and left out, so the next session tries it again)."""

    def __init__(self, retraining: Retraining, log: Callable[[str], None] = print) -> None:
        self.retraining, self.log = retraining, log
        self.layout = RetrainLayout(retraining.out)
        self.rows = read_trainings(self.layout.trainings)
        self.plan = retraining.plan()
        self.confirming = retraining.settings.confirm == 0 or bool(
            self.rows["confirmation"].fillna(False).astype(bool).any())
        if self.confirming:  # a confirmation begun keeps the structures it chose
            self.plan += confirmation_plan(retraining.entries, self.rows, retraining.settings)
        self.todo = [t for t in self.plan if t.name not in self._done()]
        self.entries = {e.label: e for e in retraining.entries}
        self.submitted: dict[str, Training] = {}
        self.wall_before = read_progress(self.layout.progress)
        self.started = time.perf_counter()

    def _done(self) -> set[str]:
        return set(self.rows["name"])

    def next_candidate(self, running: Sequence[Candidate]) -> tuple[Candidate, Job] | None:
        """The next planned training, or None when every one is submitted (the
        confirmation's are planned once the others are done)."""
        if not self.todo and not running and not self.confirming:
            self.confirming = True
            confirmation = confirmation_plan(self.retraining.entries, self.rows,
                                             self.retraining.settings)
            self.todo = [t for t in confirmation if t.name not in self._done()]
            self.plan += confirmation
            if confirmation:
                chosen = " and ".join(dict.fromkeys(t.label for t in confirmation))
                self.log(f"confirmation of {chosen}: {len(self.todo)} trainings to run")
        if not self.todo:
            return None
        training = self.todo.pop(0)
        robot = self.entries[training.label].robot
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
        row = _training_row(self.retraining, training, outcome)
        new = pd.DataFrame([row.record()], columns=list(TRAINING_COLUMNS))
        self.rows = new if self.rows.empty else pd.concat([self.rows, new], ignore_index=True)
        write_trainings(self.layout.trainings, self.rows)
        self.write_progress()
        evaluated = ("" if outcome.evaluation is None else
                     f", success {outcome.evaluation.success_rate:.0%}")
        self.log(f"{len(self.rows)}/{len(self.plan)} {training.name}: fitness "
                 f"{outcome.fitness:+.3f}{evaluated} ({outcome.env_steps:,} env steps, "
                 f"{outcome.wall_seconds:.0f} s)")

    def write_progress(self) -> None:
        """``progress.json``: the wall time spent training so far, over every session."""
        write_progress(self.layout.progress,
                       self.wall_before + time.perf_counter() - self.started)


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
    for entry in retraining.entries:
        store.save_robot(file_stem(entry.label), entry.robot)
    retrainer = Retrainer(retraining, log)
    log(f"{len(retrainer.plan) - len(retrainer.todo)} of {len(retrainer.plan)} trainings "
        f"already done; {len(retrainer.todo)} to run")
    try:
        pool.run(retrainer.next_candidate, retrainer.on_outcome)
    finally:
        retrainer.write_progress()
    return retrainer.rows
