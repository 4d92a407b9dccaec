"""evo's entry point: ``python evo/main.py +exp=<name> [key=value ...]``.

This is the config edge (STYLE rule 1): the Hydra config is turned into typed objects
here and nothing below sees a ``DictConfig``. Outputs go only to the run directory
(Hydra's output dir, chosen with ``hydra.run.dir=...``).

Tasks (``task=``):

* ``evolve`` (the default): the GA of ``conf/ga``, evaluations on ``conf/executor``;
  ``resume=<run dir>`` continues a stopped run in its own directory;
* ``robots``: generate, save and picture random robots;
* ``train``: train one robot (``robot=FILE``) and evaluate it deterministically;
* ``evaluate``: run a trained policy (``robot=FILE checkpoint=FILE``).
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from pathlib import Path

import hydra
import numpy as np
import torch
from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig, OmegaConf

from evo.components.ga import Evolve, RandomStructures, StructureStrategy
from evo.config import ConfigError, instantiate, typed
from evo.envs.task import EnvConfig
from evo.evaluation import Job
from evo.evolution import Evolution, GAConfig
from evo.learners.common import LearnerConfig
from evo.robot import (
    GeneratorParams,
    InvalidRobotError,
    Limits,
    Robot,
    RobotFileError,
    load_robot,
    random_robot,
)
from evo.robot.builder import PhysicsParams


def _robot(cfg: DictConfig) -> Robot:
    """The robot named by ``robot=``; a missing key or bad file is a ``ConfigError``."""
    if cfg.robot is None:
        raise ConfigError("robot: give the robot to use, e.g. robot=robots/four_wheeler.json")
    limits = typed(Limits, cfg.morphology.limits, "morphology.limits")
    try:
        return load_robot(str(cfg.robot), limits)
    except (RobotFileError, InvalidRobotError) as err:
        raise ConfigError(f"robot: {err}") from None


def _physics(cfg: DictConfig) -> PhysicsParams:
    return typed(PhysicsParams, cfg.morphology.physics, "morphology.physics")


def run_robots(cfg: DictConfig, out: Path) -> None:
    """Generate, save and picture ``robots.count`` random robots."""
    from evo.robot.gallery import write_gallery

    params = typed(GeneratorParams, cfg.morphology.generator, "morphology.generator")
    limits = typed(Limits, cfg.morphology.limits, "morphology.limits")
    count = int(cfg.robots.count)
    if count < 1:
        raise ConfigError(f"robots.count: expected a positive integer, got {count}")
    rng = np.random.default_rng(int(cfg.seed))
    robots: dict[str, Robot] = {}
    for _ in range(100 * count):  # distinct structures, as many as asked
        robot = random_robot(rng, params, limits)
        robots.setdefault(robot.name, robot)
        if len(robots) == count:
            break
    else:
        raise ConfigError(f"robots.count: only {len(robots)} distinct robots at these settings")
    write_gallery(list(robots.values()), out / "robots", _physics(cfg), bool(cfg.robots.render))


def run_train(cfg: DictConfig, out: Path) -> None:
    """Train one robot and evaluate it (``+exp=train``)."""
    from evo.learners.session import train_robot

    train_robot(
        _robot(cfg),
        physics=_physics(cfg),
        env=typed(EnvConfig, cfg.env, "env"),
        learner=typed(LearnerConfig, cfg.learner, "learner"),
        seed=int(cfg.seed),
        out=out,
    )


def run_evaluate(cfg: DictConfig, out: Path) -> None:
    """Evaluate a trained policy deterministically (``+exp=evaluate``)."""
    from evo.learners.session import evaluate_robot

    if cfg.checkpoint is None:
        raise ConfigError(
            "checkpoint: give the policy to run, e.g. checkpoint=outputs/.../policy.pt"
        )
    learner = typed(LearnerConfig, cfg.learner, "learner")
    try:
        evaluate_robot(
            _robot(cfg),
            Path(str(cfg.checkpoint)),
            physics=_physics(cfg),
            env=typed(EnvConfig, cfg.env, "env"),
            episodes=learner.eval_episodes,
            seed=int(cfg.seed),
            out=out,
        )
    except ValueError as err:
        raise ConfigError(f"checkpoint: {err}") from None


def _strategy(cfg: DictConfig) -> StructureStrategy:
    generator = typed(GeneratorParams, cfg.morphology.generator, "morphology.generator")
    limits = typed(Limits, cfg.morphology.limits, "morphology.limits")
    g = cfg.ga
    if g.structure == "R":
        return RandomStructures(generator, limits)
    if g.structure != "E":
        raise ConfigError(f"ga.structure: expected E (evolve) or R (random), got {g.structure!r}")
    options = {
        k: g[k] for k in ("crossover_tries", "parent_tries", "mutation_rate", "mutation_operators")
    }
    return typed(
        Evolve,
        {
            **options,
            "generator": generator,
            "limits": limits,
            "selection": instantiate(g.selection, "ga.selection"),
        },
        "ga",
    )


def run_evolve(cfg: DictConfig, out: Path) -> None:
    """The GA (``+exp=smoke``, ``demo``, ``paper_clean``, ...); ``resume=DIR`` continues."""
    from evo.progress import evolution_progress, print_summary

    if cfg.resume is not None:
        cfg = _resumed_config(Path(str(cfg.resume)))
    learner = typed(LearnerConfig, cfg.learner, "learner")
    strategy = _strategy(cfg)
    ga = typed(GAConfig, {k: cfg.ga[k] for k in ("population_size", "robot_budget")}, "ga")
    method = f"{strategy.code}+{'L' if learner.update else 'R'}"
    job = Job(_physics(cfg), typed(EnvConfig, cfg.env, "env"), learner, str(out), method)
    replacement = instantiate(cfg.ga.replacement, "ga.replacement")
    schedule = instantiate(cfg.ga.schedule, "ga.schedule")
    executor = instantiate(cfg.executor, "executor")
    with evolution_progress(ga.robot_budget, method) as show:
        evolution = Evolution(
            out,
            ga=ga,
            strategy=strategy,
            replacement=replacement,
            schedule=schedule,
            job=job,
            executor=executor,
            seed=int(cfg.seed),
            on_result=show,
        )
        if (out / "state.json").exists():
            try:
                evolution.resume()
            except ValueError as err:
                raise ConfigError(f"resume: {err}") from None
            show.resumed(evolution.history)
        summary = evolution.run()
    print_summary(summary, out)


def _resumed_config(run_dir: Path) -> DictConfig:
    """The resolved config a run directory was started with."""
    path = run_dir / "config.yaml"
    if not path.is_file():
        raise ConfigError(f"resume: {path} not found; is {run_dir} an evo run directory?")
    loaded = OmegaConf.load(path)
    assert isinstance(loaded, DictConfig)
    loaded.resume = None
    return loaded


TASKS: dict[str, Callable[[DictConfig, Path], None]] = {
    "evolve": run_evolve,
    "robots": run_robots,
    "train": run_train,
    "evaluate": run_evaluate,
}


@hydra.main(version_base="1.3", config_path="../conf", config_name="config")
def main(cfg: DictConfig) -> None:
    """Dispatch on ``task``; a bad config value ends the run with one clear line."""
    out = Path(HydraConfig.get().runtime.output_dir)
    try:
        task = TASKS.get(str(cfg.task))
        if task is None:
            raise ConfigError(f"task: unknown task {cfg.task!r}; expected one of {sorted(TASKS)}")
        threads = cfg.torch_threads
        if not isinstance(threads, int) or threads < 1:
            raise ConfigError(f"torch_threads: expected a positive integer, got {threads!r}")
        torch.set_num_threads(threads)
        if cfg.resume is None:
            (out / "config.yaml").write_text(OmegaConf.to_yaml(cfg, resolve=True))
        task(cfg, out)
    except ConfigError as err:
        print(f"error: bad config: {err}", file=sys.stderr)
        sys.exit(2)


def _resume_in_place(argv: list[str]) -> list[str]:
    """``resume=DIR`` runs in DIR itself: Hydra writes nothing anywhere else."""
    for arg in argv:
        if arg.startswith("resume=") and arg != "resume=null":
            run_dir = arg.split("=", 1)[1]
            return [*argv, f"hydra.run.dir={run_dir}", "hydra.output_subdir=null"]
    return argv


if __name__ == "__main__":
    sys.argv = _resume_in_place(sys.argv)
    main()
