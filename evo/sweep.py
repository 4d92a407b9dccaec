"""The noise sweep (``+exp=noise_sweep``): Hydra's Optuna sweeper searches learner and
physics settings for a fitness that ranks structures the same under another seed, at a
lower cost (SPEC section 10).

    python evo/main.py +exp=noise_sweep                       # the study of conf/exp
    python evo/main.py +exp=noise_sweep hydra.sweeper.n_trials=3

One trial (``task=noise_sweep``) is a retraining (:mod:`evo.retrain`) of the trial's
config: the same fixed sample of random robots (``noise_sweep.robots``, drawn with
``noise_sweep.robot_seed``), each trained ``noise_sweep.seeds`` times at
``noise_sweep.budget`` env steps, without the random-learner baseline. It returns two
objectives to Optuna: the seed-to-seed agreement ``noise_sweep.objective`` of Eq. 8
fitness (maximised; :func:`evo.fidelity.agreement`) and the cost, core-seconds per robot
(minimised: the mean CPU time of one training's process, which other load on the
machine hardly changes).

The study lives in ``<hydra.sweep.dir>/optuna.db`` (SQLite). :class:`SweepCheck`, a
Hydra callback run before the sweeper starts, stops a bad sweep at once with one line
naming the key (an unknown parameter, an empty range; exit 2) and continues a stored
study: ``hydra.sweeper.n_trials`` is the study's total, so the same command run again
runs only the trials still missing; a trial that a stop left running is marked failed
and asked again with its settings, and its finished trainings are reused. Each trial's
folder is ``<sweep dir>/trials/<digest of its overrides>/`` (the executor's left
out: it does not change the numbers): a retraining folder (``trainings.csv``,
``settings.json``) with ``trial.json`` (:class:`evo.run.records.SweepTrial`).
``python -m analysis.noise_sweep table DIR`` writes the trials' table, and
``python -m analysis.noise_ceiling DIR`` a trial's noise-ceiling report.
"""

from __future__ import annotations

import hashlib
import sys
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from hydra.experimental.callback import Callback
from omegaconf import DictConfig, OmegaConf, open_dict, read_write

from evo.checks import at_least
from evo.config import CONF_DIR
from evo.fidelity import agreement, ceiling_line
from evo.run.layout import RetrainLayout
from evo.run.records import SweepTrial, write_sweep_trial

if TYPE_CHECKING:
    from hydra.core.override_parser.types import Override

OBJECTIVES = ("spearman", "kendall", "icc", "top_quarter")
"""Agreement metrics of :mod:`evo.fidelity` a sweep may maximise."""


def trial_digest(overrides: str) -> str:
    """A short, stable folder name for a trial's overrides
    (``${evo_trial:${hydra.job.override_dirname}}`` in ``hydra.sweep.subdir``)."""
    return hashlib.sha256(overrides.encode()).hexdigest()[:12]


if not OmegaConf.has_resolver("evo_trial"):
    OmegaConf.register_new_resolver("evo_trial", trial_digest)


class SweepError(ValueError):
    """A bad sweep setting; the message names the key."""


@dataclass(frozen=True, slots=True)
class SweepSettings:
    """``noise_sweep``: what one trial measures.

    Attributes:
        robots: Random robots of the fixed sample (at least 3).
        robot_seed: Seed of the sample, and root of the training seeds.
        seeds: Trainings per robot, each with its own seed (at least 2).
        budget: Env steps per training.
        objective: Agreement metric maximised, one of :data:`OBJECTIVES`.
        resamples: Bootstrap resamples of the intervals of a trial's report
            (``python -m analysis.noise_ceiling <trial folder>``).
    """

    robots: int = 16
    robot_seed: int = 0
    seeds: int = 2
    budget: int = 50_000
    objective: str = "spearman"
    resamples: int = 1000

    def __post_init__(self) -> None:
        at_least(self, 3, "robots")
        at_least(self, 2, "seeds")
        at_least(self, 1, "budget", "resamples")
        at_least(self, 0, "robot_seed")
        if self.objective not in OBJECTIVES:
            raise ValueError(f"objective must be one of {', '.join(OBJECTIVES)}, "
                             f"got {self.objective!r}")


# ---------------------------------------------------------------- one trial


def trial_overrides() -> tuple[str, ...]:
    """The overrides of the running Hydra job: the command's and the trial's (none when
    no Hydra job runs: a config composed by a caller)."""
    from hydra.core.hydra_config import HydraConfig

    if not HydraConfig.initialized():
        return ()
    return tuple(str(o) for o in HydraConfig.get().overrides.task)


def trial_result(trainings: Any, sweep: SweepSettings, overrides: Sequence[str], out: Path
                 ) -> SweepTrial:
    """The objectives of a trial's finished ``trainings`` (a ``trainings.csv`` table).

    Raises:
        SweepError: When fewer than 3 robots have all their trainings finished.
    """
    import pandas as pd

    finished = trainings[trainings["role"] == "seed"].groupby("structure").size()
    if (finished >= sweep.seeds).sum() < 3:
        raise SweepError(f"{out}: fewer than 3 robots have all {sweep.seeds} trainings "
                         "finished; the trial failed")
    metrics = agreement(trainings)
    print(ceiling_line(metrics))
    return SweepTrial(
        objective=sweep.objective, value=float(metrics[sweep.objective]),
        core_seconds_per_robot=float(pd.to_numeric(trainings["cpu_seconds"]).mean()),
        spearman=metrics["spearman"], icc=metrics["icc"], top_quarter=metrics["top_quarter"],
        env_steps_per_second=float(trainings["env_steps"].sum()
                                   / trainings["wall_seconds"].sum()),
        overrides=tuple(overrides))


def record_trial(out: Path, trial: SweepTrial) -> SweepTrial:
    """Write ``trial.json`` and say what the trial measured."""
    write_sweep_trial(RetrainLayout(out).trial, trial)
    print(f"trial: {trial.objective} {trial.value:.3f}, "
          f"{trial.core_seconds_per_robot:.1f} core-seconds per robot ({out})")
    return trial


# ---------------------------------------------------------------- checks and resumption


def _sweep_of(text: str, key: str) -> Override:
    """The parsed override ``key=text``; a parse error names the key."""
    from hydra.core.override_parser.overrides_parser import OverridesParser
    from hydra.errors import HydraException

    try:
        return OverridesParser.create().parse_overrides([f"{key}={text}"])[0]
    except HydraException as err:
        reason = str(err).strip().splitlines()[0]
        raise SweepError(f"hydra.sweeper.params.{key}: cannot parse {text!r} ({reason})") from None


def _check_range(override: Override, key: str, text: str) -> None:
    """Refuse a choice with no option, a range or interval with nothing in it."""
    from hydra.core.override_parser.types import ChoiceSweep, IntervalSweep, RangeSweep

    value = override.value()
    empty = ((isinstance(value, ChoiceSweep) and not value.list)
             or (isinstance(value, RangeSweep) and value.start is not None
                 and value.stop is not None and (value.stop - value.start) * value.step < 0)
             or (isinstance(value, IntervalSweep) and value.start is not None
                 and value.end is not None and not value.start < value.end))
    if empty:
        raise SweepError(f"hydra.sweeper.params.{key}: {text} is empty; give at least one "
                         "value (a range needs start <= stop, an interval start < end)")


def _check_key(override: Override, key: str, config: DictConfig, conf_dir: Path) -> None:
    """Refuse a parameter that names no config key and no config group option."""
    name = override.key_or_group
    group = conf_dir / name.replace(".", "/")
    if group.is_dir():
        options = (list(override.sweep_iterator()) if override.is_sweep_override()
                   else [override.value()])
        missing = [str(o) for o in options if not (group / f"{o}.yaml").is_file()]
        if missing:
            raise SweepError(f"hydra.sweeper.params.{key}: no option {', '.join(missing)} "
                             f"in the config group {name} (conf/{name.replace('.', '/')}/)")
        return
    if key.startswith(("+", "~")) or OmegaConf.select(config, name, default=_ABSENT) is _ABSENT:
        raise SweepError(f"hydra.sweeper.params.{key}: unknown parameter; expected a key of "
                         "the config (learner.gamma, env.task.frame_skip, ...) or a config "
                         "group")


_ABSENT = object()


def sweep_params(config: DictConfig) -> dict[str, str]:
    """The sweep's parameters: ``hydra.sweeper.params`` and the command line's sweeps
    (``learner.epochs=range(2,8)``), which take their place."""
    params = {str(k): str(v) for k, v in (config.hydra.sweeper.get("params") or {}).items()}
    for text in config.hydra.overrides.task:
        key, _, value = str(text).partition("=")
        if any(value.startswith(f"{kind}(") for kind in ("choice", "range", "interval")):
            params[key] = value
    return params


def check_params(params: Mapping[str, str], config: DictConfig, conf_dir: Path) -> None:
    """Check every sweep parameter before a trial runs (unknown key, empty range).

    Raises:
        SweepError: Naming the first bad ``hydra.sweeper.params`` key.
    """
    from hydra_plugins.hydra_optuna_sweeper._impl import create_params_from_overrides

    for key, text in params.items():
        override = _sweep_of(str(text), str(key))
        _check_key(override, str(key), config, conf_dir)
        if override.is_sweep_override():
            _check_range(override, str(key), str(text))
        try:
            create_params_from_overrides([f"{key}={text}"])
        except (ValueError, AssertionError, NotImplementedError) as err:
            raise SweepError(f"hydra.sweeper.params.{key}: {err}") from None


def continue_study(storage: str, study_name: str, n_trials: int) -> tuple[int, int]:
    """Prepare a stored study to go on: trials a stop left running are marked failed and
    asked again with the same settings (their finished trainings are reused).

    Returns:
        (trials in the storage, complete trials): the sweep runs the ``n_trials`` minus
        the complete ones, and the sampler's seed moves on by the stored count so that
        its first random points are not those of the earlier runs.
    """
    import optuna
    from optuna.trial import TrialState

    try:
        study = optuna.load_study(study_name=study_name, storage=storage)
    except KeyError:  # no such study yet: the sweeper creates it
        return 0, 0
    trials = study.get_trials(deepcopy=False)
    for trial in trials:
        if trial.state == TrialState.RUNNING:
            study.tell(trial.number, state=TrialState.FAIL)
            study.enqueue_trial(trial.params)
            print(f"noise sweep: trial {trial.number} was stopped; it runs again",
                  file=sys.stderr)
    complete = sum(t.state == TrialState.COMPLETE for t in trials)
    return len(trials), complete


class SweepCheck(Callback):
    """Hydra callback of ``+exp=noise_sweep`` (``hydra.callbacks``): before the sweeper
    starts, check its parameters (exit 2 with one line naming a bad key), create the
    sweep folder for the study's storage, and continue a stored study (module
    docstring)."""

    def on_multirun_start(self, config: DictConfig, **kwargs: Any) -> None:
        sweeper = config.hydra.sweeper
        try:
            check_params(sweep_params(config), config, CONF_DIR)
        except SweepError as err:
            print(f"error: bad config: {err}", file=sys.stderr)
            sys.exit(2)
        Path(str(config.hydra.sweep.dir)).mkdir(parents=True, exist_ok=True)
        stored, complete = continue_study(str(sweeper.storage), str(sweeper.study_name),
                                          int(sweeper.n_trials))
        todo = max(0, int(sweeper.n_trials) - complete)
        print(f"noise sweep: {complete} of {sweeper.n_trials} trials complete in "
              f"{sweeper.storage}; {todo} to run", file=sys.stderr)
        with read_write(config), open_dict(config):
            sweeper.n_trials = todo
            if sweeper.sampler.get("seed") is not None:
                sweeper.sampler.seed = int(sweeper.sampler.seed) + stored


