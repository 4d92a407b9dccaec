"""Where every file of a run lives: the one place that names them.

An evolution run directory (``task=evolve``)::

    config.yaml            the resolved config it was started with
    lock.json              who holds (or last held) the directory's lock
    state.json             the resumable state (``evo.run.store``)
    history.csv            one row per evaluated robot (``evo.run.records.HistoryRow``)
    population.json        the population's names and fitness
    summary.json           the run so far (``evo.run.records.RunSummary``)
    run.mcap, run.rrd      the run's recordings (``evo.record.run``)
    robots/<name>.json     every robot it bred or drew (``evo.robot/1``)
    evals/<name>.pt        its trained policy
    evals/<name>.csv       its learning curve
    evals/<name>.mcap/.rrd its recordings
    evals/<name>.log       the traceback of its evaluation, when an exception ended it

A retraining of fixed structures (``+exp=retrain``, ``+exp=designer``: ``evo.retrain``)
keeps ``config.yaml``, ``lock.json``, ``robots/`` and ``evals/`` and writes, instead of
the state and history::

    settings.json          what decides its numbers (``evo.run.records.RetrainSettings``)
    trainings.csv          one row per finished training (``evo.run.records.TrainingRow``)
    progress.json          the wall time spent training, over every session
    trial.json             a noise sweep's trial: its objectives (``evo.sweep``)

and the reports ``analysis`` writes from them: ``noise_ceiling.md/.csv/.png`` and
``summary.json`` (``analysis.noise_ceiling``), ``comparison.md`` and its tables and
figures (``analysis.designer``).

A one-robot training (``+exp=train``) writes ``robot.json``, ``policy.pt``, ``curve.csv``
and ``summary.json`` (``evo.run.records.TrainSummary``) instead. Code outside
``evo/run/`` asks a :class:`RunLayout` or a :class:`TrainLayout` for a path; it never
spells a file name.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

CONFIG = "config.yaml"
LOCK = "lock.json"
STATE = "state.json"
HISTORY = "history.csv"
POPULATION = "population.json"
SUMMARY = "summary.json"
RUN_MCAP = "run.mcap"
RUN_RRD = "run.rrd"
ROBOTS = "robots"
EVALS = "evals"
ROBOT_SUFFIX = ".json"
POLICY_SUFFIX = ".pt"
CURVE_SUFFIX = ".csv"
MCAP_SUFFIX = ".mcap"
RRD_SUFFIX = ".rrd"
ERROR_LOG_SUFFIX = ".log"
TRAININGS = "trainings.csv"
RETRAIN_SETTINGS = "settings.json"
PROGRESS = "progress.json"
CEILING_REPORT = "noise_ceiling.md"
CEILING_METRICS = "noise_ceiling.csv"
CEILING_FIGURE = "noise_ceiling.png"
TRIAL = "trial.json"


def file_stem(label: str) -> str:
    """``label`` as a file name's stem: characters other than letters, digits and
    ``+-_.`` become ``_`` (a GA run's label may hold a ``/``)."""
    return re.sub(r"[^A-Za-z0-9+_.-]", "_", label)
TRAIN_ROBOT = "robot.json"
TRAIN_POLICY = "policy.pt"
TRAIN_CURVE = "curve.csv"


@dataclass(frozen=True)
class RunLayout:
    """The paths of an evolution run directory (see the module docstring)."""

    root: Path

    @property
    def config(self) -> Path:
        """``config.yaml``: the resolved config."""
        return self.root / CONFIG

    @property
    def lock(self) -> Path:
        """``lock.json``: the lock's holder."""
        return self.root / LOCK

    @property
    def state(self) -> Path:
        """``state.json``: the resumable state."""
        return self.root / STATE

    @property
    def history(self) -> Path:
        """``history.csv``: one row per evaluated robot."""
        return self.root / HISTORY

    @property
    def population(self) -> Path:
        """``population.json``: the population's names and fitness."""
        return self.root / POPULATION

    @property
    def summary(self) -> Path:
        """``summary.json``: the run so far."""
        return self.root / SUMMARY

    @property
    def run_mcap(self) -> Path:
        """``run.mcap``: the run's MCAP recording."""
        return self.root / RUN_MCAP

    @property
    def run_rrd(self) -> Path:
        """``run.rrd``: the run's rerun recording."""
        return self.root / RUN_RRD

    @property
    def robots(self) -> Path:
        """``robots/``: one ``evo.robot/1`` file per robot."""
        return self.root / ROBOTS

    @property
    def evals(self) -> Path:
        """``evals/``: the files of every evaluation."""
        return self.root / EVALS

    def robot(self, name: str) -> Path:
        """``robots/<name>.json``."""
        return self.robots / f"{name}{ROBOT_SUFFIX}"

    def policy(self, name: str) -> Path:
        """``evals/<name>.pt``: the trained policy."""
        return self.evals / f"{name}{POLICY_SUFFIX}"

    def curve(self, name: str) -> Path:
        """``evals/<name>.csv``: the learning curve."""
        return self.evals / f"{name}{CURVE_SUFFIX}"

    def mcap(self, name: str) -> Path:
        """``evals/<name>.mcap``: the evaluation's MCAP recording."""
        return self.evals / f"{name}{MCAP_SUFFIX}"

    def rrd(self, name: str) -> Path:
        """``evals/<name>.rrd``: the evaluation's rerun recording."""
        return self.evals / f"{name}{RRD_SUFFIX}"

    def error_log(self, name: str) -> Path:
        """``evals/<name>.log``: the traceback of an evaluation that an exception ended."""
        return self.evals / f"{name}{ERROR_LOG_SUFFIX}"

    def relative(self, path: Path) -> str:
        """``path`` as named inside the run directory (``evals/<name>.log``)."""
        return str(path.relative_to(self.root))

    def robot_names(self) -> list[str]:
        """The names of the robots in ``robots/``, sorted."""
        return sorted(p.stem for p in self.robots.glob(f"*{ROBOT_SUFFIX}"))

    def policy_count(self) -> int:
        """How many policies ``evals/`` holds."""
        return len(list(self.evals.glob(f"*{POLICY_SUFFIX}")))

    def is_run(self) -> bool:
        """Whether the directory holds an evolution's history."""
        return self.history.is_file()

    @staticmethod
    def runs_under(folder: Path) -> list[Path]:
        """Every evolution run directory under ``folder`` (at any depth), sorted."""
        return sorted(h.parent for h in folder.rglob(HISTORY) if h.is_file())

    @staticmethod
    def summaries_under(folder: Path) -> list[Path]:
        """Every ``summary.json`` in ``folder`` or under it, sorted, without evaluations'."""
        found = {p for p in (folder / SUMMARY, *folder.rglob(SUMMARY))
                 if p.is_file() and p.parent.name != EVALS}
        return sorted(found)


@dataclass(frozen=True)
class RetrainLayout(RunLayout):
    """The paths of a retraining's directory (``+exp=retrain``; see the module docstring)."""

    @property
    def settings(self) -> Path:
        """``settings.json``: what decides the noise ceiling's numbers."""
        return self.root / RETRAIN_SETTINGS

    @property
    def trainings(self) -> Path:
        """``trainings.csv``: one row per finished training."""
        return self.root / TRAININGS

    @property
    def progress(self) -> Path:
        """``progress.json``: the wall time spent training so far."""
        return self.root / PROGRESS

    @property
    def report(self) -> Path:
        """``noise_ceiling.md``: the report."""
        return self.root / CEILING_REPORT

    @property
    def metrics(self) -> Path:
        """``noise_ceiling.csv``: the noise ceiling of every fitness estimator."""
        return self.root / CEILING_METRICS

    @property
    def figure(self) -> Path:
        """``noise_ceiling.png``: fitness under one seed against another."""
        return self.root / CEILING_FIGURE

    @property
    def trial(self) -> Path:
        """``trial.json``: a noise sweep trial's objectives and settings."""
        return self.root / TRIAL


@dataclass(frozen=True)
class TrainLayout:
    """The paths of a one-robot training's directory (``+exp=train``/``evaluate``)."""

    root: Path

    @property
    def robot(self) -> Path:
        """``robot.json``: the robot trained."""
        return self.root / TRAIN_ROBOT

    @property
    def policy(self) -> Path:
        """``policy.pt``: its trained policy."""
        return self.root / TRAIN_POLICY

    @property
    def curve(self) -> Path:
        """``curve.csv``: its learning curve."""
        return self.root / TRAIN_CURVE

    @property
    def summary(self) -> Path:
        """``summary.json``: the training's (or evaluation's) summary."""
        return self.root / SUMMARY
