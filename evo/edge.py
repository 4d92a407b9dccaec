"""The config edge shared by ``evo/main.py``, the analysis tools and ``bench/``.

``python evo/main.py`` composes its config through ``@hydra.main``; a tool that trains
robots the way a run does (``python -m analysis.noise_ceiling``, the benchmarks)
composes the same ``conf/`` tree with the same overrides through :func:`compose_config`.
Either way, the typed parts every training needs come from one place here, so a key
is checked, and named in errors, the same way everywhere (STYLE rule 1); so do the
noise ceiling's trainings (:func:`retraining`, for ``task=retrain``, its alias and the
noise sweep's trials).
"""

from __future__ import annotations

import dataclasses
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from omegaconf import DictConfig, OmegaConf

from evo.components.executors import EvalExecutor
from evo.config import ConfigError, current, instantiate, typed
from evo.envs.params import EnvConfig
from evo.learners.common import LearnerConfig
from evo.record import RecordConfig
from evo.robot import GeneratorParams, Limits
from evo.robot.builder import PhysicsParams

if TYPE_CHECKING:
    from evo.retrain import RetrainConfig, Retraining

CONF_DIR = Path(__file__).resolve().parents[1] / "conf"
"""The Hydra config tree (``conf/`` at the repository root)."""


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


def physics_of(cfg: DictConfig) -> PhysicsParams:
    """``morphology.physics``: the module constants."""
    return typed(PhysicsParams, cfg.morphology.physics, "morphology.physics")


def env_of(cfg: DictConfig) -> EnvConfig:
    """``env``: the arena and the task."""
    return typed(EnvConfig, cfg.env, "env")


def limits_of(cfg: DictConfig) -> Limits:
    """``morphology.limits``: what a valid robot may not exceed."""
    return typed(Limits, cfg.morphology.limits, "morphology.limits")


def generator_of(cfg: DictConfig) -> GeneratorParams:
    """``morphology.generator``: random generation of robots."""
    return typed(GeneratorParams, cfg.morphology.generator, "morphology.generator")


def training_parts(cfg: DictConfig) -> TrainingParts:
    """The physics, env, learner and record groups of ``cfg``, typed.

    Raises:
        ConfigError: naming the key of the first bad value.
    """
    cfg = current(cfg)
    return TrainingParts(
        physics=physics_of(cfg),
        env=env_of(cfg),
        learner=typed(LearnerConfig, cfg.learner, "learner"),
        record=typed(RecordConfig, cfg.record, "record"),
    )


def executor_of(cfg: DictConfig) -> EvalExecutor:
    """The ``executor`` group's executor (a local Ray instance starts here)."""
    executor: EvalExecutor = instantiate(cfg.executor, "executor")
    return executor


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


def settings_config(cfg: DictConfig) -> str:
    """``cfg`` resolved, without the executor group (which decides where trainings run,
    not their numbers): a noise ceiling's ``evo.retrain.Settings.config``."""
    kept = OmegaConf.to_container(cfg, resolve=True)
    assert isinstance(kept, dict)
    kept.pop("executor", None)
    return OmegaConf.to_yaml(OmegaConf.create(kept))


def what_trains(config: str) -> tuple[object, ...] | None:
    """The typed groups of a resolved config (YAML) that decide a training's result
    (physics, env, learner, robot generation and limits), defaults filled in; None if it
    does not parse. Other groups (the GA's, recording) leave the numbers as they are."""
    try:
        cfg = OmegaConf.create(config)
        assert isinstance(cfg, DictConfig)
        parts = training_parts(cfg)
        return parts.physics, parts.env, parts.learner, generator_of(cfg), limits_of(cfg)
    except Exception:  # noqa: BLE001 - any unreadable config differs from a readable one
        return None


def retraining(cfg: DictConfig, out: Path, config: RetrainConfig, *, root_seed: int,
               overrides: Sequence[str]) -> Retraining:
    """The trainings of ``config`` under ``cfg`` (``evo.retrain``): settings and folder
    checked, ``settings.json`` stored (the folder is created if needed); nothing is
    trained yet.

    Raises:
        evo.retrain.RetrainError: For bad robots or a folder of other settings (named).
        ConfigError: For a config that cannot train (its key named).
    """
    from evo.evaluation import Job
    from evo.retrain import Retraining, load_entries, open_folder
    from evo.run.records import RetrainSettings

    parts = training_parts(cfg)
    budget = parts.learner.total_steps if config.budget is None else config.budget
    entries = load_entries(config, root_seed, generator=generator_of(cfg),
                           limits=limits_of(cfg))
    baseline = config.baseline and parts.learner.update
    settings = RetrainSettings(
        tuple(overrides), budget, config.seeds, root_seed, baseline,
        tuple(e.robot.name for e in entries), settings_config(cfg),
        first_seed=config.first_seed, evaluate=config.evaluate, confirm=config.confirm,
        labels=tuple(e.label for e in entries))
    open_folder(out, settings, what_trains)
    warn_if_failures_cannot_end(budget, "retrain.budget", parts.learner, parts.env)
    episodes = parts.learner.eval_episodes if config.evaluate else 0
    # The random learner ("random"): the same network, never updated.
    random_learner = dataclasses.replace(parts.learner, update=False)
    jobs = {role: Job(parts.physics, parts.env, learner, str(out), learner.name,
                      record=parts.record, config_yaml=settings.config,
                      eval_episodes=episodes)
            for role, learner in (("seed", parts.learner), ("baseline", random_learner))}
    return Retraining(out, settings, tuple(entries), jobs, parts.env.name)


__all__ = [
    "CONF_DIR",
    "ConfigError",
    "TrainingParts",
    "compose_config",
    "env_of",
    "executor_of",
    "generator_of",
    "limits_of",
    "physics_of",
    "retraining",
    "settings_config",
    "training_parts",
    "warn_if_failures_cannot_end",
    "what_trains",
]
