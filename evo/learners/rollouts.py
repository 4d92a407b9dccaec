"""Deterministic episodes of a trained policy, frame by frame (for recording and replay).

``play`` runs a policy's mean action in one arena and keeps every frame of every
episode (``evo.envs.task.Trajectory``: poses of every body, joint positions, reward
terms, outcome). The same ``seed`` gives the same episodes, so an episode recorded after
training can be replayed later from the checkpoint alone.
"""

from __future__ import annotations

import torch

from evo.envs.task import EnvConfig, ReachCore, Trajectory
from evo.learners.common import Policy
from evo.robot.builder import PhysicsParams
from evo.robot.tree import Robot


def play(
    robot: Robot,
    policy: Policy,
    *,
    physics: PhysicsParams,
    env: EnvConfig,
    seed: int,
    episodes: int = 1,
) -> tuple[ReachCore, list[Trajectory]]:
    """Run ``episodes`` deterministic episodes one after another in one arena.

    Returns:
        The arena (its ``model`` describes the bodies) and the episodes.
    """
    core = ReachCore(robot, physics, env.arena, env.task, num_envs=1, nthread=1, seed=seed)
    played: list[Trajectory] = []
    core.watch(played.append)
    for _ in range(episodes):
        observation = core.reset()
        done = False
        while not done:
            step = core.step(policy.mean_action(torch.from_numpy(observation)).numpy())
            observation = step.observation
            done = bool(step.terminated[0] or step.truncated[0])
    core.watch(None)
    return core, played
