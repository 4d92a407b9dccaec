"""evo's entry point: ``python evo/main.py +exp=<name> [key=value ...]``.

This is the config edge (STYLE rule 1): the Hydra config is turned into typed objects
here and nothing below sees a ``DictConfig``. Outputs go only to Hydra's run directory.
"""

from __future__ import annotations

import sys
from pathlib import Path

import hydra
import numpy as np
from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig

from evo.config import ConfigError, typed
from evo.robot import GeneratorParams, Limits, random_robot
from evo.robot.builder import PhysicsParams
from evo.robot.gallery import write_gallery


def run_robots(cfg: DictConfig, out: Path) -> None:
    """Generate, save and picture ``robots.count`` random robots."""
    params = typed(GeneratorParams, cfg.robot.generator, "robot.generator")
    limits = typed(Limits, cfg.robot.limits, "robot.limits")
    physics = typed(PhysicsParams, cfg.robot.physics, "robot.physics")
    count = int(cfg.robots.count)
    if count < 1:
        raise ConfigError(f"robots.count: expected a positive integer, got {count}")
    rng = np.random.default_rng(int(cfg.seed))
    robots = [random_robot(rng, params, limits) for _ in range(count)]
    write_gallery(robots, out / "robots", physics, bool(cfg.robots.render))


TASKS = {"robots": run_robots}


@hydra.main(version_base="1.3", config_path="../conf", config_name="config")
def main(cfg: DictConfig) -> None:
    """Dispatch on ``task``; a bad config value ends the run with one clear line."""
    out = Path(HydraConfig.get().runtime.output_dir)
    try:
        task = TASKS.get(str(cfg.task))
        if task is None:
            raise ConfigError(f"task: unknown task {cfg.task!r}; expected one of {sorted(TASKS)}")
        task(cfg, out)
    except ConfigError as err:
        print(f"error: bad config: {err}", file=sys.stderr)
        sys.exit(2)


if __name__ == "__main__":
    main()
