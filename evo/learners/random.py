"""The random learner: the "R" behaviour of the paper's ablations.

It builds the same policy network as PPO from the same seed and runs the same number of
env steps, but never updates the network (nor its observation statistics), so its
fitness is directly comparable with PPO's.
"""

from __future__ import annotations

import dataclasses

from evo.envs.task import EnvConfig
from evo.learners.common import LearnerConfig, TrainResult
from evo.learners.ppo import CurveHook, EpisodeHook
from evo.learners.ppo import train as train_ppo
from evo.robot.builder import PhysicsParams
from evo.robot.tree import Robot


def train(
    robot: Robot,
    *,
    physics: PhysicsParams,
    env: EnvConfig,
    config: LearnerConfig,
    budget: int,
    seed: int,
    on_curve: CurveHook | None = None,
    on_episode: EpisodeHook | None = None,
) -> TrainResult:
    """Collect ``budget`` env steps with the initial, never-updated policy."""
    frozen = dataclasses.replace(config, update=False)
    return train_ppo(robot, physics=physics, env=env, config=frozen, budget=budget, seed=seed,
                     on_curve=on_curve, on_episode=on_episode)
