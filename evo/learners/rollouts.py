"""Deterministic episodes of a trained policy, frame by frame (for recording and replay).

``play`` runs a policy's mean action in one arena and keeps, for every control step, the
pose of every body of the scene (robot modules, rocks, target marker), the reward terms
and the outcome. The same ``seed`` gives the same episodes, so an episode recorded after
training can be replayed later from the checkpoint alone.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import torch

from evo.envs.task import REWARD_TERMS, EnvConfig, ReachCore
from evo.learners.common import Policy
from evo.learners.ppo import act_deterministic
from evo.robot.builder import PhysicsParams
from evo.robot.tree import Robot

F64 = npt.NDArray[np.float64]


@dataclass(frozen=True)
class Played:
    """One deterministic episode; arrays have one row per frame (frame 0 = the start).

    Attributes:
        time: Sim time of every frame, s.
        xpos: World position of every body, (T, nbody, 3).
        xquat: World orientation of every body, (T, nbody, 4), w x y z.
        qpos: Joint positions, (T, nq): with the target, enough to redraw every frame.
        target: The target, (3,).
        rewards: Each reward term per frame (0 at frame 0).
        success: Whether the robot reached the target.
    """

    time: F64
    xpos: F64
    xquat: F64
    qpos: F64
    target: F64
    rewards: dict[str, F64]
    success: bool

    @property
    def total_return(self) -> float:
        """Sum of every reward term over the episode."""
        return float(sum(v.sum() for v in self.rewards.values()))


def play(
    robot: Robot,
    policy: Policy,
    *,
    physics: PhysicsParams,
    env: EnvConfig,
    seed: int,
    episodes: int = 1,
) -> tuple[ReachCore, list[Played]]:
    """Run ``episodes`` deterministic episodes one after another in one arena.

    Returns:
        The arena (its ``model`` describes the bodies) and the episodes.
    """
    core = ReachCore(robot, physics, env.arena, env.task, num_envs=1, nthread=1, seed=seed)
    played = []
    for _ in range(episodes):
        observation = core.reset()
        frames = [core.poses(0)]
        times, qpos = [float(core.state[0, 0])], [core.qpos[0].copy()]
        rewards: dict[str, list[float]] = {name: [0.0] for name in REWARD_TERMS}
        while True:
            action = act_deterministic(policy, torch.from_numpy(observation))
            step = core.step(action.numpy())
            observation = step.observation
            frames.append(core.poses(0))
            times.append(float(core.state[0, 0]))
            qpos.append(core.qpos[0].copy())
            for name in REWARD_TERMS:
                rewards[name].append(float(step.terms[name][0]))
            if step.terminated[0] or step.truncated[0]:
                break
        played.append(
            Played(
                time=np.array(times),
                xpos=np.stack([f[0] for f in frames]),
                xquat=np.stack([f[1] for f in frames]),
                qpos=np.stack(qpos),
                target=core.target[0].copy(),
                rewards={k: np.array(v) for k, v in rewards.items()},
                success=bool(step.success[0]),
            )
        )
    return core, played
