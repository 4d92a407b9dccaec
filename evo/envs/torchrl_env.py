"""``TaskEnv``: the reach task as a batched TorchRL environment (the training fast path).

One ``TaskEnv`` holds ``num_envs`` arenas of one robot in one process
(``batch_size=[num_envs]``); the physics of all arenas advances in one
``mujoco.batch.Batch`` call per control step (see ``evo.envs.core``). Besides
``observation``, ``reward`` and the done flags, every step carries

* ``reward_terms/<name>``: each named reward term (they sum to ``reward``);
* ``success`` and ``unstable``: why an episode ended;
* ``episode_return`` and ``episode_length``: running totals of the current episode, so
  a learner reads the return of every completed episode at its done step.

Partial resets follow TorchRL's ``_reset`` mask, so collectors reset only the arenas
whose episodes ended.
"""

from __future__ import annotations

import time

import numpy as np
import torch
from tensordict import TensorDict, TensorDictBase
from torchrl.data import Bounded, Categorical, Composite, Unbounded
from torchrl.envs import EnvBase

from evo.envs.core import TaskCore
from evo.envs.params import EnvConfig
from evo.envs.scene import Scene
from evo.robot.builder import PhysicsParams
from evo.robot.tree import Robot


def _flags(n: int) -> Categorical:
    return Categorical(2, shape=(n, 1), dtype=torch.bool)


def _column(values: np.ndarray, dtype: torch.dtype = torch.float32) -> torch.Tensor:
    return torch.as_tensor(values.reshape(-1, 1), dtype=dtype)


class TaskEnv(EnvBase):  # type: ignore[misc]
    """The reach task over the arenas of ``core``, one robot in each, as a TorchRL env.

    Args:
        core: The batched task; its ``num_envs`` arenas are the batch (``set_seed``
            re-seeds its targets and rocks).
    """

    def __init__(self, core: TaskCore) -> None:
        super().__init__(batch_size=torch.Size([core.num_envs]), device=None)
        self.core = core
        self.step_seconds = 0.0  # wall time inside _step, physics included
        n = core.num_envs
        self.observation_spec = Composite(
            observation=Unbounded((n, self.core.obs_size), dtype=torch.float32),
            reward_terms=Composite(
                {name: Unbounded((n, 1), dtype=torch.float32) for name in core.task.reward_terms},
                shape=(n,),
            ),
            success=_flags(n),
            unstable=_flags(n),
            episode_return=Unbounded((n, 1), dtype=torch.float32),
            episode_length=Unbounded((n, 1), dtype=torch.int64),
            shape=(n,),
        )
        self.action_spec = Bounded(-1.0, 1.0, (n, self.core.action_size), dtype=torch.float32)
        self.reward_spec = Unbounded((n, 1), dtype=torch.float32)
        self.done_spec = Composite(
            done=_flags(n), terminated=_flags(n), truncated=_flags(n), shape=(n,)
        )

    @property
    def num_envs(self) -> int:
        """Number of arenas."""
        return self.core.num_envs

    def _reset(self, tensordict: TensorDictBase | None = None, **kwargs: object) -> TensorDict:
        mask = None
        if tensordict is not None and "_reset" in tensordict:
            mask = tensordict.get("_reset").reshape(-1).numpy()
        observation = self.core.reset(mask)
        n = self.num_envs
        zeros = torch.zeros((n, 1))
        false = torch.zeros((n, 1), dtype=torch.bool)
        return TensorDict(
            {
                "observation": torch.from_numpy(observation),
                "reward_terms": TensorDict(
                    {name: zeros.clone() for name in self.core.task.reward_terms}, batch_size=(n,)
                ),
                "success": false.clone(),
                "unstable": false.clone(),
                "episode_return": zeros.clone(),
                "episode_length": torch.zeros((n, 1), dtype=torch.int64),
                "done": false.clone(),
                "terminated": false.clone(),
                "truncated": false.clone(),
            },
            batch_size=(n,),
        )

    def _step(self, tensordict: TensorDictBase) -> TensorDict:
        tick = time.perf_counter()
        step = self.core.step(tensordict.get("action").numpy())
        n = self.num_envs
        out = TensorDict(
            {
                "observation": torch.from_numpy(step.observation),
                "reward": _column(step.reward),
                "reward_terms": TensorDict(
                    {name: _column(v) for name, v in step.terms.items()}, batch_size=(n,)
                ),
                "success": _column(step.success, torch.bool),
                "unstable": _column(step.unstable, torch.bool),
                "episode_return": _column(step.episode_return),
                "episode_length": _column(step.episode_length, torch.int64),
                "done": _column(step.terminated | step.truncated, torch.bool),
                "terminated": _column(step.terminated, torch.bool),
                "truncated": _column(step.truncated, torch.bool),
            },
            batch_size=(n,),
        )
        self.step_seconds += time.perf_counter() - tick
        return out

    def _set_seed(self, seed: int | None) -> None:
        self.core.seed(seed)


def make_env(
    robot: Robot, physics: PhysicsParams, env: EnvConfig, num_envs: int, seed: int | None,
    scene: Scene | None = None,
) -> TaskEnv:
    """A ``TaskEnv`` of ``num_envs`` arenas as ``env`` (one ``conf/env`` file) describes
    (``scene``: its compiled scene, when the caller has one)."""
    return TaskEnv(TaskCore(robot, physics, env.arena, env.task, num_envs, env.nthread, seed,
                              scene=scene))
