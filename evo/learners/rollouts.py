"""Deterministic episodes of a trained policy: its evaluation, and frame by frame play.

Both run the policy's mean action (``Policy.mean_action``, no exploration noise).
``evaluate_policy`` runs one episode per arena in parallel and returns the success rate,
returns, lengths and the time to target (``+exp=train``'s evaluation, ``+exp=evaluate``).
``play`` runs episodes one after another in one arena and keeps every frame
(``evo.episode.Episode``: poses of every body, joint positions, reward terms, outcome),
for recording and replay. The same ``seed`` gives the same episodes, so an episode recorded after
training can be replayed later from the checkpoint alone.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TypedDict

import torch

from evo.envs.core import TaskCore
from evo.envs.params import EnvConfig
from evo.envs.scene import Scene
from evo.envs.torchrl_env import make_env
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
) -> tuple[TaskCore, list[Episode]]:
    """Run ``episodes`` deterministic episodes one after another in one arena
    (``scene``: the robot's compiled arena, when the caller has it).

    Returns:
        The arena (its ``model`` describes the bodies) and the episodes.
    """
    core = TaskCore(robot, physics, env.arena, env.task, num_envs=1, nthread=1, seed=seed,
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
    lengths: list[int]
    time_to_target: float | None


@dataclass(frozen=True, slots=True)
class PolicyEvaluation:
    """The outcome of ``evaluate_policy``.

    Attributes:
        success_rate: Share of the episodes that reached the target.
        mean_return: Mean episode return.
        returns: Every episode's return, arena by arena.
        lengths: Every episode's length, control steps (``env.task.t_max`` for one
            that timed out).
        successes: Whether each episode reached the target.
        control_step: Seconds of simulated time per control step.
    """

    success_rate: float
    mean_return: float
    returns: tuple[float, ...]
    lengths: tuple[int, ...] = ()
    successes: tuple[bool, ...] = ()
    control_step: float = math.nan

    @property
    def time_to_target(self) -> float | None:
        """Mean simulated seconds to reach the target over the episodes that reached
        it; None when none did."""
        reached = [n for n, ok in zip(self.lengths, self.successes, strict=True) if ok]
        if not reached:
            return None
        return sum(reached) / len(reached) * self.control_step

    def summary(self) -> PolicyEvaluationJSON:
        """``success_rate``, ``mean_return``, the lists of ``returns`` and ``lengths``
        and ``time_to_target`` (summary.json)."""
        return {"success_rate": self.success_rate, "mean_return": self.mean_return,
                "returns": list(self.returns), "lengths": list(self.lengths),
                "time_to_target": self.time_to_target}


def evaluate_policy(
    robot: Robot,
    policy: Policy,
    *,
    physics: PhysicsParams,
    env: EnvConfig,
    episodes: int,
    seed: int,
    scene: Scene | None = None,
    stochastic: bool = False,
) -> PolicyEvaluation:
    """Run ``episodes`` deterministic episodes, one per arena, in parallel; each
    arena's first episode counts (its return, length and whether it reached the target).
    ``scene``: the robot's compiled arena, when the caller has it. With ``stochastic``
    the same episodes with the policy's random actions, as training draws them (noise
    from ``seed``; torch's global generator is left as it was)."""
    if stochastic:
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(seed)
            return _evaluate(robot, policy, physics, env, episodes, seed, scene, True)
    return _evaluate(robot, policy, physics, env, episodes, seed, scene, False)


def _evaluate(robot: Robot, policy: Policy, physics: PhysicsParams, env: EnvConfig,
              episodes: int, seed: int, scene: Scene | None, stochastic: bool
              ) -> PolicyEvaluation:
    reach = make_env(robot, physics, env, episodes, seed, scene)
    sampler = policy.sampler() if stochastic else None
    td = reach.reset()
    finished = torch.zeros(episodes, dtype=torch.bool)
    returns = torch.zeros(episodes)
    lengths = torch.zeros(episodes, dtype=torch.int64)
    success = torch.zeros(episodes, dtype=torch.bool)
    while not finished.all():
        if sampler is not None:
            with torch.no_grad():
                td["action"] = sampler.sample(td["observation"])[2]
        else:
            td["action"] = policy.mean_action(td["observation"])
        nxt = reach.step(td)["next"]
        done = nxt["done"].squeeze(-1) & ~finished
        returns[done] = nxt["episode_return"].squeeze(-1)[done]
        lengths[done] = nxt["episode_length"].squeeze(-1)[done]
        success[done] = nxt["success"].squeeze(-1)[done]
        finished |= done
        td = nxt
    control_step = reach.core.control_step
    reach.close()
    return PolicyEvaluation(float(success.float().mean()), float(returns.mean()),
                            tuple(returns.tolist()), lengths=tuple(lengths.tolist()),
                            successes=tuple(success.tolist()), control_step=control_step)
