"""The noise ceiling: how much of a structure's fitness is the structure, not the seed.

Fitness is the GA's only signal (SPEC §10). Train every structure of a sample K ≥ 2
times with independent seeds under one config, and ask how well one training ranks
the structures as another does:

* Spearman ρ and Kendall τ-b between the seeds (the mean over seed pairs when K > 2);
* the intraclass correlation ICC(1) of a one-way random-effects model: the share of
  fitness variance that lies between structures rather than between seeds;
* top-quarter agreement: the share of one seed's top 25 % that is also in the other's;
* the share of structures whose fitness (mean over seeds) clears the random learner's
  on the same structure (the untrained policy for the same env steps) by more than
  :data:`CLEAR_MARGIN`: structures for which training did anything at all;

each with a bootstrap CI over structures, for every fitness estimator:

* ``fitness``: the paper's Eq. 8, the mean return of every episode completed during
  training (the GA's default);
* ``fitness_late``: the mean return of the episodes completed in the second half of
  the budget, an alternative that drops the untrained start.

No early predictor can rank structures by fitness better than a second training does,
so the same numbers bound the early-slope study (``analysis.early_slope_report``).

``python -m analysis.noise_ceiling --robots DIR | --random N --seed S [--seeds K]
--out DIR [--budget B] [--no-baseline] [overrides...]`` trains through the config's
executor (both cores locally, a cluster with ``executor=ray``), with the learner and
env groups composed exactly as ``python evo/main.py <overrides>`` composes them. It is
resumable: run it again with the same arguments and finished trainings are reused.
It writes into DIR ``trainings.csv`` (one row per training), ``noise_ceiling.md``,
``noise_ceiling.csv`` (the metrics), ``noise_ceiling.png`` (fitness under one seed
against another, one point per structure) and ``summary.json`` (settings, command,
env steps, wall time, metrics), beside ``robots/`` and ``evals/`` (each training's
learning curve and policy, and recordings if ``record`` asks for them).
"""

from __future__ import annotations

import argparse
import dataclasses
import itertools
import json
import shlex
import sys
import time
import warnings
from collections.abc import Callable, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, wait
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypedDict

import numpy as np
import pandas as pd
import scipy.stats
from numpy.typing import ArrayLike, NDArray
from omegaconf import DictConfig, OmegaConf

from analysis.bootstrap import Resampling, Statistic, bootstrap_ci
from analysis.early_slope import kendall, spearman, top_recall
from analysis.markdown import fmt_ci, markdown_table
from analysis.tables import require_columns
from evo.record import read_curve

if TYPE_CHECKING:
    from evo.edge import TrainingParts
    from evo.envs.params import EnvConfig
    from evo.evaluation import Job, Outcome
    from evo.learners.common import LearnerConfig
    from evo.robot import GeneratorParams, Limits, Robot
    from evo.robot.builder import PhysicsParams

ESTIMATORS: dict[str, str] = {
    "fitness": "Eq. 8: mean return of every episode completed in training",
    "fitness_late": "mean return of the episodes completed in the second half of the budget",
}
METRICS: tuple[str, ...] = ("spearman", "kendall", "icc", "top_quarter", "clears_baseline")
TOP_SHARE = 0.25
"""Top-quarter agreement compares each seed's top 25 %."""
CLEAR_MARGIN = 0.01
"""Fitness by which a structure must beat the random learner to count as learning: a
hundredth of the time penalty's range, well above the float noise of a robot that
cannot move (its fitness is −1 to about 1e-6)."""
REPORT = "noise_ceiling.md"
TRAININGS = "trainings.csv"
SETTINGS = "settings.json"
PROGRESS = "progress.json"
TRAINING_COLUMNS = ("name", "structure", "role", "learner", "replicate", "seed", "budget",
                    "fitness", "fitness_late", "episodes", "env_steps", "wall_seconds",
                    "cpu_seconds")
"""``role``: ``seed`` (one of the K trainings) or ``baseline`` (the random learner);
``cpu_seconds``: the training's CPU time (its cost, whatever else the machine ran)."""


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


class Summary(TypedDict):
    """``summary.json`` of a noise-ceiling folder."""

    settings: dict[str, object]  # Settings.to_json() without the resolved config
    command: str
    trainings: int
    env_steps: int
    wall_seconds: float
    training_seconds: float
    steps_per_second: float
    metrics: dict[str, dict[str, float]]  # estimator -> metric (and CI bound) -> value


# ---------------------------------------------------------------- metrics


def icc(*columns: ArrayLike, axis: int = -1) -> Any:
    """ICC(1) of a one-way random-effects model: each column one seed, each row
    (along ``axis``) one structure.

    ``(MSB − MSW) / (MSB + (K − 1)·MSW)``, with MSB the between-structure and MSW the
    within-structure mean square: the share of fitness variance due to the structure
    (1 when seeds agree exactly, about 0 when structure explains nothing; it can dip
    below 0 by chance).
    """
    x = np.stack([np.moveaxis(np.asarray(c, dtype=float), axis, -1) for c in columns])
    k, n = x.shape[0], x.shape[-1]
    means = x.mean(axis=0)
    grand = means.mean(axis=-1, keepdims=True)
    msb = k * ((means - grand) ** 2).sum(axis=-1) / (n - 1)
    msw = ((x - means) ** 2).sum(axis=0).sum(axis=-1) / (n * (k - 1))
    with np.errstate(divide="ignore", invalid="ignore"):
        return (msb - msw) / (msb + (k - 1) * msw)


def top_quarter(a: ArrayLike, b: ArrayLike, axis: int = -1) -> Any:
    """Share of ``a``'s top quarter that is also in ``b``'s (ties broken by position)."""
    return top_recall(a, b, share=TOP_SHARE, axis=axis)


def _pairwise_mean(metric: Statistic, k: int) -> Statistic:
    """``metric`` of two seed columns, averaged over all pairs of ``k`` columns."""
    pairs = list(itertools.combinations(range(k), 2))

    def mean(*cols: NDArray[np.float64], axis: int = -1) -> Any:
        return np.mean([metric(cols[i], cols[j], axis=axis) for i, j in pairs], axis=0)

    return mean


def _clears(k: int) -> Statistic:
    """Share of rows whose mean over the first ``k`` columns exceeds the last column by
    more than :data:`CLEAR_MARGIN`."""

    def share(*cols: NDArray[np.float64], axis: int = -1) -> Any:
        mean = np.mean(np.stack(cols[:k]), axis=0)
        return np.mean(mean > cols[k] + CLEAR_MARGIN, axis=axis)

    return share


def noise_ceiling(
    trainings: pd.DataFrame,
    resampling: Resampling,
    *,
    structure: str = "structure",
    seed: str = "train_seed",
    value: str = "fitness",
    baseline: pd.Series | None = None,
) -> pd.Series:
    """Seed-to-seed agreement of the fitness of the same structures (module docstring).

    Args:
        trainings: One row per (structure, training seed) with its ``value``; a
            structure trained under only some seeds is left out.
        resampling: How the intervals are drawn (structures are the resampled unit).
        structure: Column naming the structure.
        seed: Column naming the training seed (or replicate).
        value: Fitness column.
        baseline: The random learner's fitness per structure (indexed by structure),
            or None: then ``clears_baseline`` is NaN.

    Returns:
        Every metric of :data:`METRICS` with ``<metric>_low`` and ``<metric>_high``,
        ``n_structures`` (those with every seed present) and ``n_seeds``.

    Raises:
        ValueError: With fewer than two training seeds.
    """
    require_columns(trainings, (structure, seed, value), "trainings table")
    wide = trainings.pivot_table(index=structure, columns=seed, values=value,
                                 aggfunc="mean").dropna()
    k = wide.shape[1]
    if k < 2:
        raise ValueError(f"noise ceiling needs at least two values of {seed!r}, got {k}")
    columns = [wide[c].to_numpy(dtype=float) for c in wide.columns]
    statistics: dict[str, Statistic] = {
        "spearman": _pairwise_mean(spearman, k), "kendall": _pairwise_mean(kendall, k),
        "icc": icc, "top_quarter": _pairwise_mean(top_quarter, k),
    }
    out: dict[str, float] = {}
    for name, statistic in statistics.items():
        out.update(_with_ci(name, columns, statistic, resampling))
    base = None if baseline is None else baseline.reindex(wide.index).to_numpy(dtype=float)
    if base is None or not np.isfinite(base).all():
        out.update(clears_baseline=np.nan, clears_baseline_low=np.nan,
                   clears_baseline_high=np.nan)
    else:
        out.update(_with_ci("clears_baseline", [*columns, base], _clears(k), resampling))
    return pd.Series(dict(**out, n_structures=len(wide), n_seeds=k))


def _with_ci(name: str, columns: list[NDArray[np.float64]], statistic: Statistic,
             resampling: Resampling) -> dict[str, float]:
    if len(columns[0]) < 3:
        return {name: np.nan, f"{name}_low": np.nan, f"{name}_high": np.nan}
    with warnings.catch_warnings():  # constant resamples: the statistic is NaN there
        warnings.simplefilter("ignore", scipy.stats.ConstantInputWarning)
        warnings.simplefilter("ignore", scipy.stats.DegenerateDataWarning)
        estimate = float(statistic(*columns))
        low, high = bootstrap_ci(columns, statistic, resampling, paired=True)
    return {name: estimate, f"{name}_low": low, f"{name}_high": high}


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


def ceiling_table(trainings: pd.DataFrame, resampling: Resampling) -> pd.DataFrame:
    """Every estimator's noise ceiling from a ``trainings.csv`` table.

    The ``seed`` trainings give the seeds; the ``baseline`` trainings (the random
    learner), when present, give the baseline.

    Returns:
        One row per estimator of :data:`ESTIMATORS`: its metrics as
        :func:`noise_ceiling` returns them.
    """
    require_columns(trainings, ("structure", "role", "replicate", *ESTIMATORS),
                    "trainings table")
    seeds, base = _by_role(trainings)
    rows = []
    for estimator in ESTIMATORS:
        baseline = base.groupby("structure")[estimator].mean() if len(base) else None
        ceiling = noise_ceiling(seeds, resampling, seed="replicate", value=estimator,
                                baseline=baseline)
        rows.append(dict(estimator=estimator, **ceiling))
    return pd.DataFrame(rows)


def _by_role(trainings: pd.DataFrame) -> tuple[pd.DataFrame, pd.DataFrame]:
    """The seed trainings and the baseline trainings."""
    return (trainings[trainings["role"] == "seed"], trainings[trainings["role"] == "baseline"])


# ---------------------------------------------------------------- trainings


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


# ---------------------------------------------------------------- the tool


class NoiseCeilingError(ValueError):
    """A bad argument or output folder; the message names it."""


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

    def to_json(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def of(cls, cfg: DictConfig, overrides: Sequence[str], *, budget: int, seeds: int,
           root_seed: int, baseline: bool, robots: Sequence[Robot]) -> Settings:
        """The settings of a noise ceiling of ``robots`` under the composed ``cfg``."""
        kept = OmegaConf.to_container(cfg, resolve=True)
        assert isinstance(kept, dict)
        kept.pop("executor", None)
        return cls(tuple(overrides), budget, seeds, root_seed, baseline,
                   tuple(r.name for r in robots), OmegaConf.to_yaml(OmegaConf.create(kept)))

    COMPARED = ("budget", "seeds", "root_seed", "baseline", "structures", "config")
    """What must match to continue a folder (the overrides may differ, e.g. the
    executor, as long as the resolved config without it is the same)."""


def load_structures(robots: Path | None, random_count: int | None, seed: int,
                    cfg: DictConfig) -> list[Robot]:
    """The robots to train: every ``*.json`` of ``robots``, or ``random_count`` random
    robots of distinct structure drawn with ``seed`` (as ``task=robots`` draws them).

    Raises:
        NoiseCeilingError: For an empty or missing folder, a file that is not a valid
            robot (named), or fewer than three robots.
    """
    from evo.edge import generator_of, limits_of
    from evo.robot import InvalidRobotError, RobotFileError, load_robot, random_robots

    if robots is not None:
        if not robots.is_dir():
            raise NoiseCeilingError(f"--robots {robots}: no such folder")
        files = sorted(robots.glob("*.json"))
        if not files:
            raise NoiseCeilingError(f"--robots {robots}: no robot files (*.json) in it")
        found: dict[str, Robot] = {}
        for path in files:
            try:
                robot = load_robot(path, limits_of(cfg))
            except (RobotFileError, InvalidRobotError) as err:
                raise NoiseCeilingError(f"--robots: {err}") from None
            found.setdefault(robot.name, robot)
        chosen = list(found.values())
        what = f"--robots {robots}: {len(chosen)} distinct structure(s)"
    else:
        assert random_count is not None
        if random_count < 3:
            raise NoiseCeilingError(f"--random: expected at least 3 robots, got {random_count}")
        rng = np.random.default_rng(seed)
        try:
            chosen = random_robots(rng, random_count, generator_of(cfg), limits_of(cfg))
        except ValueError as err:
            raise NoiseCeilingError(f"--random {random_count}: {err}") from None
        what = f"--random {random_count}"
    if len(chosen) < 3:
        raise NoiseCeilingError(f"{what}; a rank correlation needs at least 3")
    return chosen


def _what_trains(config: str) -> tuple[PhysicsParams, EnvConfig, LearnerConfig,
                                      GeneratorParams, Limits] | None:
    """The typed groups of a resolved config that decide a training's result (physics,
    env, learner, robot generation and limits), defaults filled in; None if it does not
    parse. Other groups (the GA's, recording) leave the numbers as they are."""
    from evo.edge import generator_of, limits_of, training_parts

    try:
        cfg = OmegaConf.create(config)
        assert isinstance(cfg, DictConfig)
        parts = training_parts(cfg)
        return parts.physics, parts.env, parts.learner, generator_of(cfg), limits_of(cfg)
    except Exception:  # noqa: BLE001 - any unreadable config differs from a readable one
        return None


def _check_settings(out: Path, settings: Settings) -> None:
    """Refuse an output folder that holds a noise ceiling of other settings."""
    path = out / SETTINGS
    if not path.is_file():
        return
    try:
        stored = json.loads(path.read_text())
    except json.JSONDecodeError as err:
        raise NoiseCeilingError(f"{path}: unreadable ({err})") from None
    mine = settings.to_json()
    differ = [k for k in Settings.COMPARED if k != "config"
              and json.dumps(stored.get(k)) != json.dumps(mine[k])]
    if _what_trains(str(stored.get("config"))) != _what_trains(settings.config):
        differ.append("config")
    if differ:
        raise NoiseCeilingError(
            f"--out {out}: holds a noise ceiling with other settings ({', '.join(differ)} "
            "differ); give the same arguments to continue it, or another --out")


def open_folder(out: Path, settings: Settings) -> None:
    """Create ``out`` or continue it: refuse a folder that is not one or that holds a
    noise ceiling of other settings, then store ``settings.json``."""
    if out.exists() and not out.is_dir():
        raise NoiseCeilingError(f"--out {out}: exists and is not a folder")
    out.mkdir(parents=True, exist_ok=True)
    _check_settings(out, settings)
    (out / SETTINGS).write_text(json.dumps(settings.to_json(), indent=2) + "\n")


def read_trainings(out: Path) -> pd.DataFrame:
    """``trainings.csv`` of a noise-ceiling folder (empty when it has none yet); a
    column that an older folder lacks (``cpu_seconds``) reads as missing values."""
    path = out / TRAININGS
    if not path.is_file():
        return pd.DataFrame(columns=list(TRAINING_COLUMNS))
    table = pd.read_csv(path)
    return table.reindex(columns=[*table.columns, *(c for c in TRAINING_COLUMNS
                                                    if c not in table.columns)])


def _jobs(out: Path, parts: TrainingParts, settings: Settings) -> dict[str, Job]:
    """The evaluation job of each role: ``seed`` (the learner) and ``baseline`` (the
    random learner: the same network, never updated)."""
    from evo.evaluation import Job

    learner = parts.learner
    random_learner = dataclasses.replace(learner, update=False)  # named "random"
    return {role: Job(parts.physics, parts.env, config, str(out), config.name,
                      record=parts.record, config_yaml=settings.config)
            for role, config in (("seed", learner), ("baseline", random_learner))}


def _training_row(out: Path, training: Training, learner: str, settings: Settings,
                  outcome: Outcome) -> TrainingRow:
    """The ``trainings.csv`` row of one finished training."""
    from evo.run.layout import RunLayout

    curve = read_curve(RunLayout(out).curve(training.name))
    return TrainingRow(
        name=training.name, structure=training.structure, role=training.role, learner=learner,
        replicate=training.replicate, seed=training.seed, budget=settings.budget,
        fitness=outcome.fitness, fitness_late=late_fitness(curve, settings.budget),
        episodes=outcome.episodes, env_steps=outcome.env_steps,
        wall_seconds=outcome.wall_seconds, cpu_seconds=outcome.cpu_seconds)


def run_trainings(out: Path, cfg: DictConfig, settings: Settings, robots: Sequence[Robot],
                  log: Callable[[str], None] = print) -> pd.DataFrame:
    """Train every planned training not yet in ``trainings.csv``, through the config's
    executor, appending each result as it arrives (and the wall time so far, over every
    session, to ``progress.json``).

    Returns:
        The whole trainings table. Failed trainings are reported through ``log`` and
        left out, so the next call tries them again.
    """
    from evo.edge import executor_of, training_parts, warn_if_failures_cannot_end
    from evo.evaluation import Candidate, evaluate, outcome_of
    from evo.run.files import write_csv
    from evo.run.store import RunStore

    parts = training_parts(cfg)
    warn_if_failures_cannot_end(settings.budget, "--budget", parts.learner, parts.env)
    jobs = _jobs(out, parts, settings)
    by_name = {r.name: r for r in robots}
    store = RunStore(out)
    store.prepare()
    for robot in robots:
        store.save_robot(robot.name, robot)
    rows: list[TrainingRow] = read_trainings(out).to_dict("records")
    done = {row["name"] for row in rows}
    plan = plan_trainings(settings.structures, seeds=settings.seeds, root=settings.root_seed,
                          baseline=settings.baseline and parts.learner.update)
    todo = [t for t in plan if t.name not in done]
    log(f"{len(plan) - len(todo)} of {len(plan)} trainings already done; {len(todo)} to run")
    wall_before, start = wall_seconds(out), time.perf_counter()
    executor = executor_of(cfg)
    running: dict[Future[Outcome], tuple[Training, Candidate]] = {}
    try:
        while todo or running:
            while todo and len(running) < executor.workers:
                training = todo.pop(0)
                candidate = Candidate(len(rows) + len(running), training.name,
                            by_name[training.structure].canonical_json(), settings.budget,
                            training.seed, (), "noise-ceiling")
                running[executor.submit(evaluate, candidate, jobs[training.role])] = (
                    training, candidate)
            for future in wait(running, return_when=FIRST_COMPLETED).done:
                training, candidate = running.pop(future)
                outcome = outcome_of(future, candidate, executor)
                if outcome.error is not None:
                    log(f"{training.name}: failed ({outcome.error.strip().splitlines()[-1]})")
                    continue
                rows.append(_training_row(out, training, jobs[training.role].learner.name,
                                          settings, outcome))
                write_csv(out / TRAININGS, pd.DataFrame(rows, columns=list(TRAINING_COLUMNS)))
                _write_progress(out, wall_before + time.perf_counter() - start)
                log(f"{len(rows)}/{len(plan)} {training.name}: fitness {outcome.fitness:+.3f} "
                    f"({outcome.env_steps:,} env steps, {outcome.wall_seconds:.0f} s)")
    except BaseException:  # a signal or an error: stop the trainings now, not at their end
        executor.terminate()
        raise
    finally:
        _write_progress(out, wall_before + time.perf_counter() - start)
    executor.shutdown()
    return pd.DataFrame(rows, columns=list(TRAINING_COLUMNS))


def wall_seconds(out: Path) -> float:
    """Wall seconds spent training into ``out`` so far, over every session."""
    path = out / PROGRESS
    return float(json.loads(path.read_text())["wall_seconds"]) if path.is_file() else 0.0


def _write_progress(out: Path, seconds: float) -> None:
    from evo.run.files import write_json

    write_json(out / PROGRESS, {"wall_seconds": seconds})


# ---------------------------------------------------------------- report


def write_report(out: Path, trainings: pd.DataFrame, settings: Settings, *,
                 wall_seconds: float, command: str, resampling: Resampling | None = None
                 ) -> Path:
    """``noise_ceiling.md``, ``.csv``, ``.png`` and ``summary.json`` from the trainings."""
    from analysis.plots import plot_seed_scatter

    table = ceiling_table(trainings, resampling or Resampling.seeded(0))
    table.to_csv(out / "noise_ceiling.csv", index=False)
    seeds, base = _by_role(trainings)
    plot_seed_scatter(seeds, base, estimators=list(ESTIMATORS), ceiling=table,
                      margin=CLEAR_MARGIN, path=out / "noise_ceiling.png")
    steps = int(trainings["env_steps"].sum())
    summary = Summary(
        settings=settings.to_json() | {"config": None}, command=command,
        trainings=len(trainings), env_steps=steps, wall_seconds=wall_seconds,
        training_seconds=float(trainings["wall_seconds"].sum()),
        steps_per_second=steps / max(wall_seconds, 1e-9),
        metrics={row["estimator"]: {k: v for k, v in row.items() if k != "estimator"}
                 for row in table.to_dict("records")},
    )
    (out / "summary.json").write_text(json.dumps(summary, indent=2, default=float) + "\n")
    report = out / REPORT
    report.write_text(_markdown(table, trainings, settings, summary), encoding="utf-8")
    return report


def _markdown(table: pd.DataFrame, trainings: pd.DataFrame, settings: Settings,
              summary: Summary) -> str:
    cells = pd.DataFrame({
        "estimator": table["estimator"],
        **{metric: [fmt_ci(r[metric], r[f"{metric}_low"], r[f"{metric}_high"])
                    for r in table.to_dict("records")] for metric in METRICS},
        "structures": table["n_structures"].astype(int),
    })
    seeds, base = _by_role(trainings)
    per_structure = seeds.pivot_table(index="structure", columns="replicate",
                                      values="fitness").add_prefix("seed ")
    if len(base):
        per_structure["random learner"] = base.groupby("structure")["fitness"].mean()
    per_structure = per_structure.sort_values(per_structure.columns[0], ascending=False)
    overrides = " ".join(settings.overrides) or "(none)"
    return "".join([
        "# Noise ceiling: fitness of the same structures under independent seeds\n\n",
        f"{int(table['n_structures'].max())} structures × {settings.seeds} seeds, "
        f"{settings.budget:,} env steps per training; overrides: `{overrides}`.\n\n",
        f"Command: `{summary['command']}`\n\n",
        f"{summary['trainings']} trainings, {summary['env_steps']:,} env steps in "
        f"{summary['wall_seconds']:,.0f} s wall ({summary['steps_per_second']:,.0f} env "
        "steps/s over all workers).\n\n",
        "## Agreement between seeds\n\n",
        "Bootstrap 95 % CIs over structures. `spearman`, `kendall`, `top_quarter`: mean over "
        "seed pairs; `icc`: ICC(1), the share of fitness variance due to structure; "
        "`clears_baseline`: share of structures whose mean fitness beats the random "
        f"learner's on the same structure by more than {CLEAR_MARGIN:g}.\n\n",
        markdown_table(cells),
        "\nEstimators:\n\n", *[f"- `{k}`: {v}\n" for k, v in ESTIMATORS.items()],
        "\n## Fitness per structure (Eq. 8)\n\n",
        markdown_table(per_structure, index=True),
        "\n![fitness under one seed against another](noise_ceiling.png)\n",
    ])


# ---------------------------------------------------------------- CLI


def parse_args(argv: Sequence[str] | None) -> argparse.Namespace:
    cli = argparse.ArgumentParser(
        prog="python -m analysis.noise_ceiling",
        description="Train structures under independent seeds and measure how well one "
                    "seed's fitness ranks them as another's does.")
    source = cli.add_mutually_exclusive_group(required=True)
    source.add_argument("--robots", type=Path, help="folder of evo.robot/1 files")
    source.add_argument("--random", type=int, metavar="N", help="N random robots")
    cli.add_argument("--seed", type=int, default=0,
                     help="seed of the random robots and root of the training seeds")
    cli.add_argument("--seeds", type=int, default=2, metavar="K",
                     help="trainings per structure, each with its own seed (>= 2)")
    cli.add_argument("--budget", type=int, default=None,
                     help="env steps per training (default: learner.total_steps)")
    cli.add_argument("--no-baseline", action="store_true",
                     help="skip the random learner's training of each structure")
    cli.add_argument("--out", type=Path, required=True, help="output folder")
    cli.add_argument("--resamples", type=int, default=2000, help="bootstrap resamples")
    cli.add_argument("overrides", nargs="*",
                     help="config overrides as for python evo/main.py (learner.num_envs=32)")
    return cli.parse_args(argv)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the tool; exit 0, or 2 with one line naming a bad argument or config key."""
    from evo.config import ConfigError
    from evo.edge import compose_config, training_parts

    args = parse_args(argv)
    command = "python -m analysis.noise_ceiling " + shlex.join(
        sys.argv[1:] if argv is None else list(argv))
    try:
        if args.seeds < 2:
            raise NoiseCeilingError(f"--seeds: expected at least 2, got {args.seeds}")
        cfg = compose_config(args.overrides)
        learner = training_parts(cfg).learner
        budget = learner.total_steps if args.budget is None else args.budget
        if budget < 1:
            raise NoiseCeilingError(f"--budget: expected a positive env-step count, got {budget}")
        robots = load_structures(args.robots, args.random, args.seed, cfg)
        settings = Settings.of(cfg, args.overrides, budget=budget, seeds=args.seeds,
                               root_seed=args.seed, baseline=not args.no_baseline,
                               robots=robots)
        open_folder(args.out, settings)
        trainings = run_trainings(args.out, cfg, settings, robots)
    except (NoiseCeilingError, ConfigError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    replicates = _by_role(trainings)[0].groupby("structure").size()
    if (replicates >= 2).sum() < 3:
        print(f"error: {args.out}: fewer than 3 structures have two finished trainings; "
              "run the same command again", file=sys.stderr)
        return 1
    report = write_report(args.out, trainings, settings, wall_seconds=wall_seconds(args.out),
                          command=command, resampling=Resampling.seeded(0, args.resamples))
    print(f"report: {report}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
