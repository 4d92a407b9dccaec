"""The noise ceiling as a sweep objective: Hydra's Optuna sweeper searches learner and
physics settings for a fitness that ranks structures the same under another seed, at a
lower cost (SPEC §10).

    python evo/main.py +exp=noise_sweep                       # the study of conf/exp
    python evo/main.py +exp=noise_sweep hydra.sweeper.n_trials=3

One trial (``task=noise_sweep``) is the noise ceiling (``evo.retrain``'s trainings,
:mod:`analysis.noise_ceiling`'s report) run on the trial's config: the same fixed
sample of random robots (``noise_sweep.robots``, drawn with
``noise_sweep.robot_seed``), each trained ``noise_sweep.seeds`` times at
``noise_sweep.budget`` env steps, without the random-learner baseline. It returns two
objectives to Optuna: the seed-to-seed agreement ``noise_sweep.objective`` of Eq. 8
fitness (maximised) and the cost, core-seconds per robot (minimised: the mean CPU
time of one training's process, which other load on the machine hardly changes).

The study lives in ``<hydra.sweep.dir>/optuna.db`` (SQLite). :class:`SweepCheck`, a
Hydra callback run before the sweeper starts, stops a bad sweep at once with one line
naming the key (an unknown parameter, an empty range; exit 2) and continues a stored
study: ``hydra.sweeper.n_trials`` is the study's total, so the same command run again
runs only the trials still missing; a trial that a stop left running is marked failed
and asked again with its settings, and its finished trainings are reused. Each trial's
folder is ``<sweep dir>/trials/<digest of its overrides>/`` (the executor's left
out: it does not change the numbers): a noise-ceiling folder
(``trainings.csv``, ``noise_ceiling.md``, ``summary.json``) with ``trial.json``.
``python -m analysis.noise_sweep table DIR`` writes the trials' table
(``trials.csv``, ``trials.md``) and the frontier figure (``frontier.png``).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from hydra.experimental.callback import Callback
from omegaconf import DictConfig, OmegaConf, open_dict, read_write

if TYPE_CHECKING:
    import pandas as pd
    from hydra.core.override_parser.types import Override

STORAGE = "optuna.db"
"""The study's SQLite file in the sweep folder."""
TRIAL = "trial.json"
"""A trial's objectives and settings, in its folder."""
OBJECTIVES = ("spearman", "kendall", "icc", "top_quarter")
"""Agreement metrics of :mod:`analysis.noise_ceiling` a sweep may maximise."""


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
        resamples: Bootstrap resamples of the trial's confidence intervals.
    """

    robots: int = 16
    robot_seed: int = 0
    seeds: int = 2
    budget: int = 50_000
    objective: str = "spearman"
    resamples: int = 1000

    def __post_init__(self) -> None:
        from evo.checks import at_least

        at_least(self, 3, "robots")
        at_least(self, 2, "seeds")
        at_least(self, 1, "budget", "resamples")
        at_least(self, 0, "robot_seed")
        if self.objective not in OBJECTIVES:
            raise ValueError(f"objective must be one of {', '.join(OBJECTIVES)}, "
                             f"got {self.objective!r}")


@dataclass(frozen=True, slots=True)
class TrialResult:
    """What one trial measured (``trial.json``)."""

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


# ---------------------------------------------------------------- one trial


def trial_overrides() -> tuple[str, ...]:
    """The overrides of the running Hydra job: the command's and the trial's."""
    from hydra.core.hydra_config import HydraConfig

    return tuple(str(o) for o in HydraConfig.get().overrides.task)


def run_trial(cfg: DictConfig, out: Path, overrides: Sequence[str] = ()) -> TrialResult:
    """The noise ceiling of ``cfg``'s learner and physics on the sweep's fixed sample,
    trained into ``out`` (finished trainings there are reused).

    Raises:
        evo.config.ConfigError: For a bad ``noise_sweep`` key or a config that cannot
            train (named).
        SweepError: When fewer than 3 robots have every training finished.
    """
    import pandas as pd

    from analysis.noise_ceiling import report_trainings
    from evo.config import ConfigError, typed
    from evo.edge import retraining
    from evo.retrain import RetrainConfig, RetrainError

    sweep = typed(SweepSettings, cfg.get("noise_sweep"), "noise_sweep")
    config = RetrainConfig(random=sweep.robots, seeds=sweep.seeds, budget=sweep.budget,
                           baseline=False, resamples=sweep.resamples)
    try:
        retrain = retraining(cfg, out, config, root_seed=sweep.robot_seed, overrides=overrides)
    except RetrainError as err:
        raise ConfigError(f"noise_sweep: {err}") from None
    trainings, summary = report_trainings(
        cfg, out, retrain, replicates=sweep.seeds,
        command="python evo/main.py " + " ".join(overrides), resamples=sweep.resamples,
        too_few=lambda: SweepError(f"{out}: fewer than 3 robots have all {sweep.seeds} "
                                   "trainings finished; the trial failed"))
    metrics = summary["metrics"]["fitness"]
    result = TrialResult(
        objective=sweep.objective, value=float(metrics[sweep.objective]),
        core_seconds_per_robot=float(pd.to_numeric(trainings["cpu_seconds"]).mean()),
        spearman=float(metrics["spearman"]), icc=float(metrics["icc"]),
        top_quarter=float(metrics["top_quarter"]),
        env_steps_per_second=float(trainings["env_steps"].sum()
                                   / trainings["wall_seconds"].sum()),
        overrides=tuple(overrides))
    (out / TRIAL).write_text(json.dumps(asdict(result), indent=2) + "\n")
    print(f"trial: {sweep.objective} {result.value:.3f}, "
          f"{result.core_seconds_per_robot:.1f} core-seconds per robot ({out})")
    return result


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
        from evo.edge import CONF_DIR

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


# ---------------------------------------------------------------- the trials' table


def trials_table(sweep_dir: Path, study_name: str = "noise_sweep") -> pd.DataFrame:
    """One row per trial of the study in ``sweep_dir``: number, state, the measured
    agreement and cost (from the ``trial.json`` of a complete trial), its parameters,
    its folder, and whether it is on the Pareto front (no other trial is as good on
    both)."""
    import optuna
    import pandas as pd

    study = optuna.load_study(study_name=study_name, storage=f"sqlite:///{sweep_dir / STORAGE}")
    measured = {}
    for path in sorted(sweep_dir.glob(f"trials/*/{TRIAL}")):
        found = json.loads(path.read_text())
        measured[frozenset(found["overrides"])] = {**found, "folder": path.parent.name}
    rows = []
    for trial in study.get_trials(deepcopy=False):
        params = {k: v for k, v in trial.params.items()}
        wanted = {f"{k}={v}" for k, v in params.items()}
        match = next((m for key, m in measured.items() if wanted <= key), {}
                     ) if trial.state.name == "COMPLETE" else {}
        rows.append({"trial": trial.number, "state": trial.state.name,
                     **{k: match.get(k, float("nan")) for k in (
                         "spearman", "icc", "top_quarter", "core_seconds_per_robot",
                         "env_steps_per_second")},
                     **params, "folder": match.get("folder", "")})
    table = pd.DataFrame(rows)
    if table.empty:
        return table
    value = table["spearman"].to_numpy()
    cost = table["core_seconds_per_robot"].to_numpy()
    table["pareto"] = [bool(v == v) and not ((value >= v) & (cost <= c) & (
        (value > v) | (cost < c))).any() for v, c in zip(value, cost, strict=True)]
    return table


def write_table(sweep_dir: Path, table: pd.DataFrame) -> Path:
    """``trials.csv``, ``trials.md`` and ``frontier.png`` (agreement against cost) in
    ``sweep_dir``; returns the Markdown file."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from analysis.markdown import markdown_table

    table.to_csv(sweep_dir / "trials.csv", index=False)
    fig, ax = plt.subplots(figsize=(6, 4))
    done = table.dropna(subset=["spearman"])
    ax.scatter(done["core_seconds_per_robot"], done["spearman"], c="0.6", label="trial")
    front = done[done["pareto"]].sort_values("core_seconds_per_robot")
    ax.plot(front["core_seconds_per_robot"], front["spearman"], "o-", c="C3", label="frontier")
    for row in done.itertuples():
        ax.annotate(str(row.trial), (row.core_seconds_per_robot, row.spearman), fontsize=7)
    ax.set(xlabel="core-seconds per robot", ylabel="Spearman rho between seeds (Eq. 8)")
    ax.legend()
    fig.tight_layout()
    fig.savefig(sweep_dir / "frontier.png", dpi=120)
    plt.close(fig)
    path = sweep_dir / "trials.md"
    path.write_text("# Noise sweep: trials\n\n" + markdown_table(table.drop(columns="folder"))
                    + "\n![agreement against cost](frontier.png)\n", encoding="utf-8")
    return path


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m analysis.noise_sweep table DIR``: the trials' table of a sweep folder."""
    cli = argparse.ArgumentParser(prog="python -m analysis.noise_sweep",
                                  description="The trials' table of a noise sweep.")
    verbs = cli.add_subparsers(dest="verb", required=True)
    tab = verbs.add_parser("table", help="trials.csv, trials.md and frontier.png")
    tab.add_argument("sweep_dir", type=Path, help="the sweep folder (hydra.sweep.dir)")
    tab.add_argument("--study", default="noise_sweep", help="hydra.sweeper.study_name")
    args = cli.parse_args(argv)
    if not (args.sweep_dir / STORAGE).is_file():
        print(f"error: {args.sweep_dir}: no {STORAGE}; is it a noise sweep folder?",
              file=sys.stderr)
        return 2
    table = trials_table(args.sweep_dir, args.study)
    if table.empty:
        print(f"error: {args.sweep_dir}: the study has no trials yet", file=sys.stderr)
        return 2
    print(f"table: {write_table(args.sweep_dir, table)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
