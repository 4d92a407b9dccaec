"""The config edge: Hydra's config in, one typed root out (STYLE rule 1).

``python evo/main.py`` composes its config through ``@hydra.main``; a tool that trains
robots the way a run does (the benchmarks, tests) composes the same ``conf/`` tree with
the same overrides through :func:`compose_config`. Either way :func:`typed_config` turns
it, once, into an :class:`EvoConfig`: every group typed (``evo.config.typed``), its older
forms converted first (``evo.config.current``), so a key is checked, and named in
errors, the same way everywhere. Below ``evo/main.py`` code takes the typed parts it
needs; nothing there sees a ``DictConfig``.
"""

from __future__ import annotations

import dataclasses
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from omegaconf import DictConfig, OmegaConf

from evo.checks import at_least
from evo.components.executors import EvalExecutor
from evo.components.ga import GAConfig
from evo.config import CONF_DIR, ConfigError, current, instantiate, typed
from evo.envs.params import EnvConfig
from evo.evaluation import Job
from evo.learners.common import LearnerConfig
from evo.record import RecordConfig
from evo.retrain import RetrainConfig, Retraining, load_entries, open_folder
from evo.robot import GeneratorParams, Limits
from evo.robot.builder import PhysicsParams
from evo.run.layout import RunLayout
from evo.run.records import RetrainSettings
from evo.sweep import SweepSettings


def compose_config(overrides: Sequence[str]) -> DictConfig:
    """The config ``python evo/main.py <overrides>`` runs with (Hydra's compose API).

    Raises:
        ConfigError: For an override Hydra cannot parse or apply (an unknown group or
            option, a key that is not in the config), with Hydra's own message.
    """
    from hydra import compose, initialize_config_dir
    from hydra.errors import HydraException

    from evo.schemas import register_schemas

    register_schemas()
    try:
        with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
            return compose("config", overrides=list(overrides))
    except HydraException as err:
        raise ConfigError(f"overrides {' '.join(overrides)}: {err}") from None


@dataclass(frozen=True, slots=True)
class TrainingParts:
    """What training one robot needs from the config, typed."""

    physics: PhysicsParams
    env: EnvConfig
    learner: LearnerConfig
    record: RecordConfig


@dataclass(frozen=True, slots=True)
class RobotsTask:
    """``robots``: what ``task=robots`` draws.

    Attributes:
        count: How many random robots to generate.
        render: Also write a picture of each (needs ``MUJOCO_GL=egl`` or ``osmesa``).
    """

    count: int = 12
    render: bool = True

    def __post_init__(self) -> None:
        at_least(self, 1, "count")


@dataclass(frozen=True)
class EvoConfig:
    """The whole config of ``evo/main.py``, typed: what a task is given.

    Attributes:
        task: What ``evo/main.py`` does (``evolve``, ``train``, ``retrain``, ...).
        seed: The root seed; every random stream of the run is spawned from it.
        torch_threads: Torch's intra-op threads of this process.
        robot: ``task=train``/``evaluate``: the robot file.
        checkpoint: ``task=evaluate``: the policy checkpoint.
        resume: The run directory to continue, if any.
        physics: ``morphology.physics``: the module constants.
        limits: ``morphology.limits``: what a valid robot may not exceed.
        generator: ``morphology.generator``: random generation of robots.
        env: ``env``: the arena and the task.
        learner: ``learner``: the inner loop.
        record: ``record``: the recordings.
        ga: ``ga``: the outer loop.
        robots: ``robots``: what ``task=robots`` draws.
        retrain: ``retrain``: what ``task=retrain`` trains (None without the node).
        noise_sweep: ``noise_sweep``: one sweep trial (None without the node).
        executor: The ``executor`` node; :meth:`make_executor` builds and checks it (a
            local Ray instance starts then).
        yaml: The resolved config, as ``config.yaml`` holds it.
        training_yaml: The resolved config without the executor group (which decides
            where trainings run, not their numbers).
    """

    task: str
    seed: int
    torch_threads: int
    robot: str | None
    checkpoint: str | None
    resume: str | None
    physics: PhysicsParams
    limits: Limits
    generator: GeneratorParams
    env: EnvConfig
    learner: LearnerConfig
    record: RecordConfig
    ga: GAConfig
    robots: RobotsTask
    retrain: RetrainConfig | None
    noise_sweep: SweepSettings | None
    executor: Mapping[str, Any]
    yaml: str
    training_yaml: str

    @property
    def training(self) -> TrainingParts:
        """The physics, env, learner and record groups: what one training needs."""
        return TrainingParts(self.physics, self.env, self.learner, self.record)

    def make_executor(self) -> EvalExecutor:
        """The ``executor`` group's executor (a local Ray instance starts here)."""
        executor: EvalExecutor = instantiate(self.executor, "executor")
        return executor


def _seed(value: object) -> int:
    """The root seed: a non-negative integer (numpy's seed sequences take no other)."""
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        raise ConfigError(f"seed: expected a non-negative integer, got {value!r}")
    return value


def _threads(value: object) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise ConfigError(f"torch_threads: expected a positive integer, got {value!r}")
    return value


def _path(value: object) -> str | None:
    return None if value is None else str(value)


def typed_config(cfg: DictConfig) -> EvoConfig:
    """``cfg`` (a composed config, or a run directory's ``config.yaml``) in today's form
    (:func:`evo.config.current`), every group typed: the one place it is unpacked.

    Raises:
        ConfigError: naming the key of the first bad value.
    """
    cfg = current(cfg)
    morphology = cfg.get("morphology") or {}
    executor = cfg.get("executor")
    plain = OmegaConf.to_container(executor, resolve=True) if executor is not None else {}
    if not isinstance(plain, dict):
        raise ConfigError(f"executor: expected a mapping with a _target_ class, got {plain!r}")

    def optional(cls: type[Any], key: str) -> Any:
        node = cfg.get(key)
        return None if node is None else typed(cls, node, key)

    return EvoConfig(
        task=str(cfg.get("task", "evolve")), seed=_seed(cfg.get("seed", 0)),
        torch_threads=_threads(cfg.get("torch_threads", 1)),
        robot=_path(cfg.get("robot")), checkpoint=_path(cfg.get("checkpoint")),
        resume=_path(cfg.get("resume")),
        physics=typed(PhysicsParams, morphology.get("physics"), "morphology.physics"),
        limits=typed(Limits, morphology.get("limits"), "morphology.limits"),
        generator=typed(GeneratorParams, morphology.get("generator"), "morphology.generator"),
        env=typed(EnvConfig, cfg.get("env"), "env"),
        learner=typed(LearnerConfig, cfg.get("learner"), "learner"),
        record=typed(RecordConfig, cfg.get("record"), "record"),
        ga=typed(GAConfig, cfg.get("ga"), "ga"),
        robots=typed(RobotsTask, cfg.get("robots"), "robots"),
        retrain=optional(RetrainConfig, "retrain"),
        noise_sweep=optional(SweepSettings, "noise_sweep"),
        executor={str(k): v for k, v in plain.items()},
        yaml=OmegaConf.to_yaml(cfg, resolve=True),
        training_yaml=_without_executor(cfg),
    )


def _without_executor(cfg: DictConfig) -> str:
    """``cfg`` resolved, without the executor group: a retraining's
    :attr:`~evo.run.records.RetrainSettings.config`."""
    kept = OmegaConf.to_container(cfg, resolve=True)
    assert isinstance(kept, dict)
    kept.pop("executor", None)
    return OmegaConf.to_yaml(OmegaConf.create(kept))


def run_config(run_dir: Path) -> EvoConfig:
    """The typed config a run directory was started with (its ``config.yaml``, in
    today's form).

    Raises:
        ValueError: When the directory has no ``config.yaml``.
        ConfigError: For a value the config no longer accepts (named).
    """
    path = RunLayout(run_dir).config
    if not path.is_file():
        raise ValueError(f"{path} not found; is {run_dir} an evo run directory?")
    loaded = OmegaConf.load(path)
    if not isinstance(loaded, DictConfig):
        raise ValueError(f"{path}: not a config (a mapping)")
    return typed_config(loaded)


def warn_if_failures_cannot_end(
    budget: int, budget_key: str, learner: LearnerConfig, env: EnvConfig
) -> None:
    """Warn when ``budget`` gives each arena fewer control steps than an episode's limit:
    then only successful episodes end, and fitness (the mean return of the episodes that
    ended) would count successes alone.

    Raises:
        ConfigError: When the budget gives an arena not even one control step.
    """
    per_arena = budget // learner.num_envs
    if per_arena < 1:
        raise ConfigError(
            f"{budget_key}: {budget:,} env steps give each of learner.num_envs="
            f"{learner.num_envs} arenas no control step; a budget needs at least "
            f"{learner.num_envs} env steps (one per arena)")
    if per_arena < env.task.t_max:
        warnings.warn(
            f"{budget_key}: {budget:,} env steps over learner.num_envs={learner.num_envs} "
            f"arenas is {per_arena} control steps per arena, under the episode limit "
            f"env.task.t_max={env.task.t_max}: episodes that fail never end, so fitness "
            "counts mostly successes. Use fewer arenas or a larger budget.",
            stacklevel=2,
        )


def what_trains(config: str) -> tuple[object, ...] | None:
    """The typed groups of a resolved config (YAML) that decide a training's result
    (physics, env, learner, robot generation and limits), defaults filled in; None if it
    does not parse. Other groups (the GA's, recording) leave the numbers as they are."""
    try:
        cfg = OmegaConf.create(config)
        assert isinstance(cfg, DictConfig)
        root = typed_config(cfg)
    except Exception:  # noqa: BLE001 - any unreadable config differs from a readable one
        return None
    return root.physics, root.env, root.learner, root.generator, root.limits


def retraining(root: EvoConfig, out: Path, config: RetrainConfig, *, root_seed: int,
               overrides: Sequence[str]) -> Retraining:
    """The trainings of ``config`` under ``root`` (``evo.retrain``): settings and folder
    checked, ``settings.json`` stored (the folder is created if needed); nothing is
    trained yet.

    Raises:
        evo.retrain.RetrainError: For bad robots or a folder of other settings (named).
        ConfigError: For a config that cannot train (its key named).
    """
    learner = root.learner
    budget = learner.total_steps if config.budget is None else config.budget
    entries = load_entries(config, root_seed, generator=root.generator, limits=root.limits)
    settings = RetrainSettings(
        tuple(overrides), budget, config.seeds, root_seed, config.baseline and learner.update,
        tuple(e.robot.name for e in entries), root.training_yaml,
        first_seed=config.first_seed, evaluate=config.evaluate, confirm=config.confirm,
        labels=tuple(e.label for e in entries))
    open_folder(out, settings, what_trains)
    warn_if_failures_cannot_end(budget, "retrain.budget", learner, root.env)
    episodes = learner.eval_episodes if config.evaluate else 0
    # The random learner ("random"): the same network, never updated.
    random_learner = dataclasses.replace(learner, update=False)
    jobs = {role: Job(root.physics, root.env, trains, str(out), trains.name,
                      record=root.record, config_yaml=settings.config, eval_episodes=episodes)
            for role, trains in (("seed", learner), ("baseline", random_learner))}
    return Retraining(out, settings, tuple(entries), jobs, root.env.name)


__all__ = [
    "CONF_DIR",
    "ConfigError",
    "EvoConfig",
    "RobotsTask",
    "TrainingParts",
    "compose_config",
    "retraining",
    "run_config",
    "typed_config",
    "warn_if_failures_cannot_end",
    "what_trains",
]
