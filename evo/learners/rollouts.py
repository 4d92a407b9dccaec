"""Deterministic episodes of a trained policy: its evaluation, and frame by frame play.

Both run the policy's mean action (``Policy.mean_action``, no exploration noise).
``evaluate_policy`` runs one episode per arena in parallel and returns the success rate
and returns (``+exp=train``'s evaluation, ``+exp=evaluate``). ``play`` runs episodes
one after another in one arena and keeps every frame (``evo.episode.Episode``: poses
of every body, joint positions, reward terms, outcome), for recording and
replay. The same ``seed`` gives the same episodes, so an episode recorded after
training can be replayed later from the checkpoint alone.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TypedDict

import torch

from evo.envs.params import EnvConfig
from evo.envs.reach import make_env
from evo.envs.scene import Scene
from evo.envs.task import ReachCore
from evo.episode import Episode
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
    scene: Scene | None = None,
) -> tuple[ReachCore, list[Episode]]:
    """Run ``episodes`` deterministic episodes one after another in one arena
    (``scene``: the robot's compiled arena, when the caller has it).

    Returns:
        The arena (its ``model`` describes the bodies) and the episodes.
    """
    core = ReachCore(robot, physics, env.arena, env.task, num_envs=1, nthread=1, seed=seed,
                     scene=scene)
    played: list[Episode] = []
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


class PolicyEvaluationJSON(TypedDict):
    """A :class:`PolicyEvaluation` as ``summary.json`` holds it."""

    success_rate: float
    mean_return: float
    returns: list[float]


@dataclass(frozen=True, slots=True)
class PolicyEvaluation:
    """The outcome of ``evaluate_policy``.

    Attributes:
        success_rate: Share of the episodes that reached the target.
        mean_return: Mean episode return.
        returns: Every episode's return, arena by arena.
    """

    success_rate: float
    mean_return: float
    returns: tuple[float, ...]

    def summary(self) -> PolicyEvaluationJSON:
        """``success_rate``, ``mean_return`` and the list of ``returns`` (summary.json)."""
        return {"success_rate": self.success_rate, "mean_return": self.mean_return,
                "returns": list(self.returns)}


def evaluate_policy(
    robot: Robot,
    policy: Policy,
    *,
    physics: PhysicsParams,
    env: EnvConfig,
    episodes: int,
    seed: int,
) -> PolicyEvaluation:
    """Run ``episodes`` deterministic episodes, one per arena, in parallel."""
    reach = make_env(robot, physics, env, episodes, seed)
    td = reach.reset()
    finished = torch.zeros(episodes, dtype=torch.bool)
    returns = torch.zeros(episodes)
    success = torch.zeros(episodes, dtype=torch.bool)
    while not finished.all():
        td["action"] = policy.mean_action(td["observation"])
        nxt = reach.step(td)["next"]
        done = nxt["done"].squeeze(-1) & ~finished
        returns[done] = nxt["episode_return"].squeeze(-1)[done]
        success[done] = nxt["success"].squeeze(-1)[done]
        finished |= done
        td = nxt
    reach.close()
    return PolicyEvaluation(float(success.float().mean()), float(returns.mean()),
                            tuple(returns.tolist()))
