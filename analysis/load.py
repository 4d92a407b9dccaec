"""The one loader: run directories into the tidy robots and curves tables of
:mod:`analysis.tables`.

:func:`load_runs` takes one or many paths. Each is a run directory (it holds
``history.csv``) or a folder holding run directories at any depth, such as a Hydra
multirun folder (``0/``, ``1/``, ... or ``E+L_seed0/``, ...). From each run directory:

* ``config.yaml``: the GA ``seed`` (the unit of replication) and the initial
  ``ga.population_size`` (to replay the population, :mod:`analysis.population`);
* ``history.csv``: one robots row per history row; ``method`` from its ``method``
  column (from ``summary.json`` or the config when the history is empty);
* ``evals/<name>.mcap``: each robot's learning curve via :func:`evo.record.read_curve`.
  The MCAP file is the source of truth. Only when it is missing is ``evals/<name>.csv``
  read instead; a warning names the files and the robots table's ``curve_source`` says
  ``"csv"`` (``"mcap"`` normally, ``""`` when neither file exists, as for a failed
  evaluation).

**Run id.** A run directory's name (``E+L_seed0``, ``3``, ``2024-05-01/12-00-00``'s
last part); where two inputs share a name, their paths relative to the inputs' common
folder.

**Budget (decision).** The robots table's ``budget`` is the env steps a robot was
actually trained for (history ``env_steps``: the scheduled budget rounded up to whole
collector batches), because that is what its learning curve spans and what its training
cost; the scheduled budget is kept as ``scheduled_budget``. A failed evaluation (no
env steps) keeps its scheduled budget.

Besides the schema columns, the robots table carries ``scheduled_budget``,
``operator``, ``replaced``, ``episodes``, ``wall_seconds``, ``error``, ``eval_seed``
(history's per-evaluation ``seed``) and ``curve_source``; the curves table carries
every column the recording holds (``episode_length``, ``reward/...``, ``loss/...``,
``wall_seconds``, ...).

**Committed copies.** A results folder commits only ``history.csv`` and
``summary.json`` per run (``docs/results/<study>/runs/<run>/``). :func:`load_histories`
reads such copies into the same :class:`Runs`, with an empty curves table (no
learning-curve figures), so every table of a report, and the figures drawn from fitness
alone, can be regenerated from what is committed:

* the GA ``seed`` from ``config.yaml`` when the copy has one, else from the directory
  name, which must end in ``seed<S>`` (``E+L_seed0``; :func:`run_setting`);
* the initial population size from ``config.yaml``, else the GA default
  (:data:`DEFAULT_POPULATION`);
* ``complete`` from ``summary.json`` (a copy holds no lock: a run that was still
  going when it was copied reads ``partial``).

:func:`load_retrained` reads retrained structures for the noise ceiling
(:func:`analysis.noise_ceiling.noise_ceiling`); :func:`launch_paths` reads the paths a
notebook is given (``EVO_RUNS``) as the shell that launched it means them.
"""

from __future__ import annotations

import os
import re
import warnings
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal, TypedDict

import numpy as np
import pandas as pd
from omegaconf import OmegaConf

from analysis.tables import CURVE_COLUMNS, ROBOT_COLUMNS
from evo.config import method_label, structure_letter
from evo.record import read_curve
from evo.run.layout import HISTORY, TRAININGS, RunLayout
from evo.run.records import RunSummary, read_run_summary, read_train_summary
from evo.run.records import read_history as read_history_file

DEFAULT_POPULATION = 20
"""``ga.population_size`` of the GA config, for a config that does not say."""
EXTRA_ROBOT_COLUMNS: tuple[str, ...] = (
    "scheduled_budget", "operator", "replaced", "episodes", "wall_seconds", "error",
    "eval_seed", "status", "predicted", "curve_source", "inherited_from",
    "eval_success_rate", "eval_mean_return",
)
"""``status``: ``trained``, ``stopped-early`` (early rejection: its fitness covers part of
its budget) or ``failed``, from history.csv (derived from ``error`` for runs recorded
before the column existed); ``predicted``: the rule's prediction for a stopped robot;
``inherited_from``: the parent whose policy its training started from (``ga.inheritance``;
"" for none and in runs recorded before the column existed); ``eval_success_rate`` and
``eval_mean_return``: the deterministic (mean action) evaluation of the policy its
training handed back (``learner.eval_interval``; NaN without one)."""
RUN_COLUMNS: tuple[str, ...] = (
    "run", "method", "seed", "population_size", "robots", "complete", "status",
    "curves_mcap", "curves_csv", "curves_missing", "path",
)
STRUCTURE = re.compile(r"^(robot-[0-9a-f]{8})")
"""A robot name's structure part: re-evaluations of one structure add ``-<birth>``."""

PathsLike = str | os.PathLike[str] | Iterable[str | os.PathLike[str]]


class RunStatus(TypedDict):
    """Whether a run has finished (the ``complete`` and ``status`` columns of ``runs``)."""

    complete: bool
    status: Literal["running", "complete", "partial"]


class RetrainedRow(TypedDict):
    """One training of a structure trained again (a row of :func:`load_retrained`)."""

    structure: str
    train_seed: float  # the replicate or the training's seed; NaN when unknown
    fitness: float
    budget: float  # env steps; NaN when the training's summary lacks them
    source: str  # the directory it came from


class RunDirectoryError(ValueError):
    """A run directory (or one of its files) is missing or not what evo writes."""


@dataclass(frozen=True)
class Runs:
    """What :func:`load_runs` read.

    Attributes:
        robots: Robots table (:mod:`analysis.tables`), in run and birth order.
        curves: Curves table, in run, robot birth and env-step order.
        runs: One row per run directory: ``run``, ``method``, ``seed``,
            ``population_size``, ``robots``, ``complete`` (the run finished: its
            ``summary.json`` says so, no process holds it and its history is whole),
            ``status`` (``complete``, ``running``: a live process holds the run's lock,
            or ``partial``: stopped before the end, or its ``history.csv`` was cut
            mid-row), ``curves_mcap``, ``curves_csv``, ``curves_missing`` (robots whose
            curve came from each source) and ``path``.
        notes: Sentences about the input a reader should know (CSV fallbacks, ...).
    """

    robots: pd.DataFrame
    curves: pd.DataFrame
    runs: pd.DataFrame
    notes: list[str] = field(default_factory=list)

    @property
    def where(self) -> str:
        """The run directories, comma-separated (for messages)."""
        return ", ".join(map(str, self.runs["path"]))

    @property
    def population_size(self) -> int:
        """The initial population size shared by the runs (the largest, if they differ)."""
        return max(self.population_sizes.values(), default=DEFAULT_POPULATION)

    @property
    def population_sizes(self) -> dict[str, int]:
        """Run id → initial population size (the GA default where the config has none)."""
        return {str(r.run): int(r.population_size) if pd.notna(r.population_size)
                else DEFAULT_POPULATION for r in self.runs.itertuples(index=False)}


# ---------------------------------------------------------------- finding runs


def find_run_dirs(paths: PathsLike) -> list[Path]:
    """Every run directory in ``paths``, each once, in the order given (then sorted).

    Args:
        paths: Run directories or folders holding them (at any depth).

    Returns:
        Resolved run directory paths.

    Raises:
        FileNotFoundError: If a path does not exist.
        RunDirectoryError: If a path is neither a run directory nor holds one.
    """
    found: dict[Path, None] = {}
    for path in _as_paths(paths):
        if not path.exists():
            raise FileNotFoundError(f"{path}: no such run directory")
        if not path.is_dir():
            raise RunDirectoryError(f"{path}: not a directory; give a run directory")
        if RunLayout(path).is_run():
            found[path.resolve()] = None
            continue
        inside = RunLayout.runs_under(path)
        if not inside:
            raise RunDirectoryError(
                f"{path}: not a run directory (no {HISTORY}) and holds none"
            )
        found.update((p.resolve(), None) for p in inside)
    return list(found)


def launch_paths(text: str, launched_from: str | os.PathLike[str] | None = None) -> list[Path]:
    """The paths in ``text`` (``os.pathsep``-separated, as in ``EVO_RUNS``), relative ones
    resolved against the directory the user launched from.

    A notebook's kernel runs in the notebook's folder (``analysis/``), not where
    ``jupyter execute`` or ``jupyter lab`` was typed, so a relative path taken as it is
    would point into ``analysis/``. The kernel inherits the launching shell's ``PWD``;
    relative paths are joined to it (to the working directory where there is none), so
    ``EVO_RUNS=outputs/x`` means what it means to the shell.

    Args:
        text: Paths separated by ``os.pathsep``; empty parts are skipped; ``~`` expands.
        launched_from: The directory relative paths start from (default: ``PWD``).

    Returns:
        The paths, absolute where they were relative.
    """
    base = Path(launched_from or os.environ.get("PWD") or os.getcwd())
    paths = [Path(part).expanduser() for part in text.split(os.pathsep) if part.strip()]
    return [path if path.is_absolute() else base / path for path in paths]


def _as_paths(paths: PathsLike) -> list[Path]:
    if isinstance(paths, str | os.PathLike):
        return [Path(paths)]
    return [Path(p) for p in paths]


def run_ids(dirs: list[Path]) -> list[str]:
    """Short unique ids: directory names, or paths relative to the common folder."""
    names = [d.name for d in dirs]
    if len(set(names)) == len(names):
        return names
    common = Path(os.path.commonpath(dirs))
    return [d.relative_to(common).as_posix() or d.name for d in dirs]


# ---------------------------------------------------------------- one run


@dataclass(frozen=True)
class RunConfig:
    """What analysis reads of a run's ``config.yaml`` (as written, unresolved).

    Attributes:
        seed: The ``seed`` key as written (None when missing).
        ga: The ``ga`` group (empty when missing or not a mapping).
        learner: The ``learner`` group (empty when missing or not a mapping).
        env: The ``env`` group (empty when missing or not a mapping).
    """

    seed: object = None
    ga: Mapping[str, object] = field(default_factory=dict)
    learner: Mapping[str, object] = field(default_factory=dict)
    env: Mapping[str, object] = field(default_factory=dict)

    @property
    def t_max(self) -> int:
        """``env.task.t_max``: the task's control steps per episode (the task default,
        1,000, where the config does not say)."""
        task = self.env.get("task")
        return int(task.get("t_max", 1000)) if isinstance(task, dict) else 1000

    @classmethod
    def of(cls, document: Mapping[str, object]) -> RunConfig:
        """The settings of a config document (``config.yaml`` as plain containers)."""

        def group(name: str) -> Mapping[str, object]:
            node = document.get(name)
            return {str(k): v for k, v in node.items()} if isinstance(node, dict) else {}

        return cls(seed=document.get("seed"), ga=group("ga"), learner=group("learner"),
                   env=group("env"))


def read_config(run_dir: Path) -> RunConfig:
    """The resolved ``config.yaml`` of a run, the settings analysis reads of it.

    Raises:
        RunDirectoryError: If the file is missing or not a YAML mapping.
    """
    path = RunLayout(run_dir).config
    if not path.is_file():
        raise RunDirectoryError(f"{path}: missing; every run directory holds its config")
    try:
        config = OmegaConf.to_container(OmegaConf.load(path), resolve=False)
    except Exception as err:  # noqa: BLE001 - any parse error is the file's fault
        raise RunDirectoryError(f"{path}: not a readable YAML config ({err})") from None
    if not isinstance(config, dict):
        raise RunDirectoryError(f"{path}: expected a YAML mapping")
    return RunConfig.of({str(k): v for k, v in config.items()})


def read_history(run_dir: Path) -> pd.DataFrame:
    """``history.csv`` with the columns the robots table needs checked.

    Raises:
        RunDirectoryError: If it cannot be parsed or lacks a needed column.
    """
    path = RunLayout(run_dir).history
    try:
        history = read_history_file(path)
    except (OSError, ValueError, pd.errors.ParserError) as err:
        raise RunDirectoryError(f"{path}: not a readable history ({err})") from None
    needed = ("birth", "name", "budget", "fitness", "accepted")
    missing = [c for c in needed if c not in history.columns]
    if missing:
        raise RunDirectoryError(
            f"{path}: lacks column(s) {missing}; it has {list(history.columns)}"
        )
    return history


def run_method(run_dir: Path, history: pd.DataFrame, config: RunConfig) -> str:
    """The run's method: history's ``method`` column, else summary.json, else the config.

    Raises:
        RunDirectoryError: If the history names more than one method.
    """
    if "method" in history.columns and history["method"].notna().any():
        methods = history["method"].dropna().unique()
        if len(methods) > 1:
            raise RunDirectoryError(
                f"{RunLayout(run_dir).history}: one run holds one method, found "
                f"{sorted(methods)}"
            )
        return str(methods[0])
    summary = _summary(run_dir)
    if summary is not None:
        return summary.method
    return method_label(structure_letter(config.ga.get("structure", "E")),
                        bool(config.learner.get("update", True)),
                        config.ga.get("inheritance", "off"))


def _summary(run_dir: Path) -> RunSummary | None:
    try:
        return read_run_summary(RunLayout(run_dir).summary)
    except ValueError as err:
        raise RunDirectoryError(str(err)) from None


def robots_of_run(run: str, method: str, seed: int, history: pd.DataFrame) -> pd.DataFrame:
    """The robots table rows of one run, from its history (one row per history row)."""

    def text(column: str) -> pd.Series:
        values = history[column] if column in history.columns else pd.Series("", history.index)
        return values.fillna("").astype(str)

    def number(column: str) -> pd.Series:
        values = history[column] if column in history.columns else pd.Series(np.nan, history.index)
        return pd.to_numeric(values, errors="coerce")

    scheduled, steps = number("budget"), number("env_steps")
    table = pd.DataFrame({
        "run": run,
        "method": method,
        "seed": seed,
        "birth": history["birth"].astype(int),
        "name": history["name"].astype(str),
        "budget": steps.where(steps > 0, scheduled).fillna(0).astype(int),
        "fitness": number("fitness").astype(float),
        "accepted": text("accepted").str.lower().eq("true"),
        "parents": text("parents"),
        "scheduled_budget": scheduled.fillna(0).astype(int),
        "operator": text("operator"),
        "replaced": text("replaced"),
        "episodes": number("episodes"),
        "wall_seconds": number("wall_seconds"),
        "error": text("error"),
        "eval_seed": number("seed"),
        "status": text("status").where(text("status") != "", np.where(
            text("error") != "", "failed", "trained")),
        "predicted": number("predicted"),
        "inherited_from": text("inherited_from"),
        "eval_success_rate": number("eval_success_rate"),
        "eval_mean_return": number("eval_mean_return"),
    })
    return table.sort_values("birth").reset_index(drop=True)


def read_robot_curve(run_dir: Path, name: str) -> tuple[pd.DataFrame | None, str]:
    """One robot's learning curve: from its MCAP file, or its CSV when the MCAP is missing.

    Args:
        run_dir: The run directory.
        name: The robot's name.

    Returns:
        The curve as :func:`evo.record.read_curve` gives it (None when neither file
        exists) and its source, ``"mcap"``, ``"csv"`` or ``""``.

    Raises:
        RunDirectoryError: If the file that exists cannot be read.
    """
    layout = RunLayout(run_dir)
    mcap, csv = layout.mcap(name), layout.curve(name)
    try:
        if mcap.is_file():
            return read_curve(mcap), "mcap"
        if csv.is_file():
            return read_curve(csv), "csv"
    except Exception as err:  # noqa: BLE001 - reader errors name no run; add it
        bad = mcap if mcap.is_file() else csv
        raise RunDirectoryError(f"{bad}: cannot read the learning curve ({err})") from None
    return None, ""


def curves_of_run(run: str, run_dir: Path, names: Iterable[str]) -> tuple[pd.DataFrame, list[str]]:
    """The curves table rows of one run and each robot's curve source."""
    parts, sources = [], []
    for name in names:
        curve, source = read_robot_curve(run_dir, name)
        sources.append(source)
        if curve is None or curve.empty:
            continue
        curve = curve.copy()
        for column in CURVE_COLUMNS[2:]:
            if column not in curve.columns:
                curve[column] = np.nan
        curve.insert(0, "name", name)
        curve.insert(0, "run", run)
        parts.append(curve)
    if not parts:
        return pd.DataFrame(columns=list(CURVE_COLUMNS)), sources
    return pd.concat(parts, ignore_index=True), sources


# ---------------------------------------------------------------- many runs


def load_runs(paths: PathsLike, first: int | None = None) -> Runs:
    """Read run directories into the robots and curves tables.

    Args:
        paths: Run directories, or folders holding them (a Hydra multirun folder).
        first: Keep only each run's first ``first`` robots (births below it), to compare
            runs of different lengths over the same robots; None keeps them all.

    Returns:
        The tables, one row per run, and notes on the input.

    Raises:
        FileNotFoundError: If a path does not exist.
        RunDirectoryError: Naming the directory or file that is not as evo writes it.
    """
    dirs = find_run_dirs(paths)
    robots, curves, runs, notes = [], [], [], []
    for run, run_dir in zip(run_ids(dirs), dirs, strict=True):
        config = read_config(run_dir)
        history_path = RunLayout(run_dir).history
        history, broken = _whole_rows(read_history(run_dir), history_path)
        if broken:
            notes.append(f"run {run}: {broken} row(s) of {history_path} cut mid-row "
                         "(a copy taken while it was written?) left out")
        method = run_method(run_dir, history, config)
        seed = _seed(config, run_dir)
        table = robots_of_run(run, method, seed, history)
        if first is not None:
            notes.append(_first_note(run, table, first))
            table = table[table["birth"] < first].reset_index(drop=True)
        run_curves, sources = curves_of_run(run, run_dir, table["name"])
        table["curve_source"] = sources
        csv_names = table.loc[table["curve_source"] == "csv", "name"].tolist()
        if csv_names:
            note = (f"run {run}: {len(csv_names)} curve(s) read from evals/<name>.csv because "
                    f"the MCAP file is missing ({', '.join(csv_names)}) in {run_dir}")
            warnings.warn(note, stacklevel=2)
            notes.append(note)
        status = _status(run_dir, broken)
        if status["status"] != "complete":
            notes.append(f"run {run}: {status['status']}, {len(table)} robot(s) so far "
                         f"({run_dir}); its numbers may still change")
        robots.append(table)
        curves.append(run_curves)
        runs.append(dict(
            run=run, method=method, seed=seed,
            population_size=config.ga.get("population_size"),
            robots=len(table), **status,
            curves_mcap=int((table["curve_source"] == "mcap").sum()),
            curves_csv=len(csv_names),
            curves_missing=int((table["curve_source"] == "").sum()),
            path=str(run_dir),
        ))
    robots_table = pd.concat(robots, ignore_index=True)
    robots_table = robots_table[[*ROBOT_COLUMNS, *EXTRA_ROBOT_COLUMNS]]
    curves_table = _tidy_curves(pd.concat(curves, ignore_index=True), robots_table)
    return Runs(robots_table, curves_table, pd.DataFrame(runs, columns=list(RUN_COLUMNS)), notes)


def _first_note(run: str, table: pd.DataFrame, first: int) -> str:
    """What ``load_runs(first=...)`` kept of one run."""
    kept = int((table["birth"] < first).sum())
    if kept < first:
        return (f"run {run}: {kept} robot(s) born before {first} (fewer than the "
                f"{first} asked for)")
    return f"run {run}: its first {first} robots of {len(table)}"


def _whole_rows(history: pd.DataFrame, path: Path) -> tuple[pd.DataFrame, int]:
    """The history without rows cut mid-write, and how many were cut.

    evo writes ``history.csv`` whole (atomically) and ending in a newline, so a last
    line without one was cut (a copy taken while it was written); so is a row missing a
    needed cell or with a half-written ``accepted``.
    """
    accepted = history["accepted"].astype(str).str.lower()
    cut = history[["birth", "name", "budget"]].isna().any(axis=1) | ~accepted.isin(
        ["true", "false"])
    text = path.read_bytes()
    if len(history) and text and not text.endswith(b"\n"):
        cut.iloc[-1] = True
    return history[~cut].reset_index(drop=True), int(cut.sum())


def _status(run_dir: Path, broken: int) -> RunStatus:
    """``complete`` and ``status`` of a run (see :class:`Runs`)."""
    from evo.run.files import is_locked

    if is_locked(run_dir):
        return RunStatus(complete=False, status="running")
    summary = _summary(run_dir)
    complete = summary is not None and bool(summary.complete) and not broken
    return RunStatus(complete=complete, status="complete" if complete else "partial")


def as_int(value: object) -> int:
    """``int(value)`` of a value read from a config (TypeError for one that is neither a
    number nor text, as ``int`` raises)."""
    if isinstance(value, int | float | str):
        return int(value)
    raise TypeError(f"int() of {type(value).__name__}: {value!r}")


def _seed(config: RunConfig, run_dir: Path) -> int:
    try:
        return as_int(config.seed)
    except (TypeError, ValueError):
        raise RunDirectoryError(
            f"{RunLayout(run_dir).config}: needs an integer 'seed', got {config.seed!r}"
        ) from None


def _tidy_curves(curves: pd.DataFrame, robots: pd.DataFrame) -> pd.DataFrame:
    """Schema columns first, integer step and episode counts, run and birth order."""
    for column in ("env_steps", "train/episodes"):
        values = pd.to_numeric(curves[column], errors="coerce")
        curves[column] = values.astype(np.int64) if values.notna().all() else values
    order = robots[["run", "name", "birth"]]
    curves = curves.merge(order, on=["run", "name"], how="left", sort=False)
    curves = curves.sort_values(["run", "birth", "env_steps"], kind="stable")
    rest = [c for c in curves.columns if c not in CURVE_COLUMNS and c != "birth"]
    return curves[[*CURVE_COLUMNS, *rest]].reset_index(drop=True)


# ---------------------------------------------------------------- committed copies


SEED_IN_NAME = re.compile(r"seed(\d+)$")


def run_setting(run_dir: Path) -> tuple[int, int]:
    """The GA seed and initial population size of a run copy.

    Raises:
        RunDirectoryError: If there is no ``config.yaml`` and the name gives no seed.
    """
    if RunLayout(run_dir).config.is_file():
        config = read_config(run_dir)
        seed = 0 if config.seed is None else config.seed
        population = config.ga.get("population_size", DEFAULT_POPULATION)
        return as_int(seed), as_int(population)
    match = SEED_IN_NAME.search(run_dir.name)
    if match is None:
        raise RunDirectoryError(f"{run_dir}: no config.yaml and the name does not end in "
                                "seed<S>; name the copy <method>_seed<S>")
    return int(match.group(1)), DEFAULT_POPULATION


def _complete(run_dir: Path) -> bool:
    summary = _summary(run_dir)
    return summary is not None and summary.complete


def load_histories(paths: PathsLike, first: int | None = None) -> Runs:
    """Read run copies' ``history.csv`` and ``summary.json`` (see the module docstring).

    Args:
        paths: Run directories, or folders holding them.
        first: Keep only each run's first ``first`` robots; None keeps them all.

    Returns:
        The robots table, an empty curves table, one row per run and notes.

    Raises:
        FileNotFoundError: If a path does not exist.
        RunDirectoryError: Naming the directory or file that cannot be read.
    """
    robots, runs = [], []
    notes = ["Read from history.csv and summary.json only: no learning curves."]
    dirs = find_run_dirs(paths)
    for run, run_dir in zip(run_ids(dirs), dirs, strict=True):
        seed, population = run_setting(run_dir)
        history = read_history(run_dir)
        table = robots_of_run(run, run_method(run_dir, history, RunConfig()), seed, history)
        if first is not None:
            kept = table[table["birth"] < first].reset_index(drop=True)
            notes.append(f"run {run}: its first {len(kept)} robots of {len(table)}")
            table = kept
        table["curve_source"] = ""
        complete = _complete(run_dir)
        if not complete:
            notes.append(f"run {run}: not complete when copied (summary.json), "
                         f"{len(table)} robot(s) here")
        robots.append(table)
        runs.append(dict(run=run, method=table["method"].iloc[0] if len(table) else "",
                         seed=seed, population_size=population, robots=len(table),
                         complete=complete, status="complete" if complete else "partial",
                         curves_mcap=0, curves_csv=0, curves_missing=len(table),
                         path=str(run_dir)))
    robots_table = pd.concat(robots, ignore_index=True)[[*ROBOT_COLUMNS, *EXTRA_ROBOT_COLUMNS]]
    return Runs(robots_table, pd.DataFrame(columns=list(CURVE_COLUMNS)),
                pd.DataFrame(runs, columns=list(RUN_COLUMNS)), notes)


# ---------------------------------------------------------------- retrained structures


def _retrained_in(path: Path) -> tuple[list[RetrainedRow], bool]:
    """The :func:`load_retrained` rows of everything under ``path``, and whether it
    holds any noise-ceiling folder, evolution run or training run."""
    rows: list[RetrainedRow] = []
    tables = sorted({p for p in (path / TRAININGS, *path.rglob(TRAININGS))
                     if p.is_file()})
    found = bool(tables)
    for table_path in tables:
        trainings = pd.read_csv(table_path)
        for row in trainings[trainings["role"] == "seed"].itertuples(index=False):
            # The replicate, not the derived seed: replicate k of every structure is one
            # column of the seed-to-seed comparison, as the tool itself pivots it.
            rows.append(RetrainedRow(structure=str(row.structure), train_seed=row.replicate,
                                     fitness=float(row.fitness), budget=row.env_steps,
                                     source=str(table_path.parent)))
    for summary_path in RunLayout.summaries_under(path):
        run_dir = summary_path.parent
        if RunLayout(run_dir).is_run():
            for row in read_history(run_dir).itertuples(index=False):
                rows.append(RetrainedRow(structure=_structure(str(row.name)),
                                         train_seed=getattr(row, "seed", np.nan),
                                         fitness=float(row.fitness),
                                         budget=getattr(row, "env_steps", row.budget),
                                         source=str(run_dir)))
            found = True
            continue
        try:
            training = read_train_summary(summary_path)
        except ValueError as err:
            raise RunDirectoryError(str(err)) from None
        if training is not None:
            rows.append(RetrainedRow(structure=_structure(str(training.robot)),
                                     train_seed=training.seed, fitness=float(training.fitness),
                                     budget=training.env_steps, source=str(run_dir)))
            found = True
    return rows, found


def load_retrained(paths: PathsLike) -> pd.DataFrame:
    """Fitness of structures trained again, for :func:`analysis.noise_ceiling.noise_ceiling`.

    Each path is, or holds at any depth, a training run (``+exp=train``: its
    ``summary.json`` names the ``robot``, the ``seed`` and the ``fitness``), an
    evolution run whose robots were retrained (every history row counts, its ``seed``
    being the training seed) or a folder of ``python -m analysis.noise_ceiling`` (its
    ``trainings.csv``: every seed training counts, under its replicate number, the
    random learner's do not). A
    structure is the robot name without a ``-<birth>`` suffix.

    Args:
        paths: Directories as above.

    Returns:
        ``structure``, ``train_seed``, ``fitness``, ``budget`` and ``source`` (the
        directory), one row per training.

    Raises:
        FileNotFoundError: If a path does not exist.
        RunDirectoryError: If a path holds no training or evolution run.
    """
    rows: list[RetrainedRow] = []
    for path in _as_paths(paths):
        if not path.exists():
            raise FileNotFoundError(f"{path}: no such directory of retrained robots")
        retrained, found = _retrained_in(path)
        if not found:
            raise RunDirectoryError(
                f"{path}: holds no training run (summary.json with robot, seed, fitness), "
                f"no evolution run ({HISTORY}) and no noise ceiling (trainings.csv)"
            )
        rows += retrained
    table = pd.DataFrame(rows).drop_duplicates()
    return table.reset_index(drop=True)


def _structure(name: str) -> str:
    match = STRUCTURE.match(name)
    return match.group(1) if match else name
