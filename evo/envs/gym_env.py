"""``TaskGymEnv``: a task as a single-arena ``gymnasium.Env`` (``evo/Reach-v0``,
``evo/Locomotion-v0``).

For users of gymnasium-based libraries (Stable-Baselines3, CleanRL, ...). It runs the
same task code as the batched TorchRL ``TaskEnv`` (``evo.envs.core.TaskCore`` with one
arena), so observations, rewards and termination are identical::

    import gymnasium as gym
    import evo.envs  # registers evo/Reach-v0 and the other tasks' ids

    env = gym.make("evo/Reach-v0", robot="robots/four_wheeler.json", arena="cluttered")

(or, without the import, ``gym.make("evo.envs:evo/Reach-v0", ...)``). The env truncates
its own episodes after ``t_max`` control steps; ``info`` carries every reward term
(``reward/<name>``), ``success`` and ``unstable``.
"""

from __future__ import annotations

import os
from typing import Any

import gymnasium as gym
import mujoco
import numpy as np
import numpy.typing as npt

from evo.envs.arena import ArenaParams
from evo.envs.core import TaskCore
from evo.envs.tasks.base import Task
from evo.robot.builder import PhysicsParams
from evo.robot.io import load_robot
from evo.robot.tree import Robot

Obs = npt.NDArray[np.float32]


def arena_params(arena: str | ArenaParams) -> ArenaParams:
    """``ArenaParams`` from a preset name (``clean``, ``cluttered``, ``open``) or as given."""
    if isinstance(arena, ArenaParams):
        return arena
    presets = {"clean": ArenaParams.clean, "cluttered": ArenaParams.cluttered,
               "open": ArenaParams.open}
    if arena not in presets:
        raise ValueError(f"arena must be one of {sorted(presets)} or ArenaParams, got {arena!r}")
    return presets[arena]()


class TaskGymEnv(gym.Env[Obs, Obs]):  # type: ignore[misc]
    """One arena of a task.

    Args:
        robot: A robot, or the path of an ``evo.robot/1`` file.
        arena: ``"clean"``, ``"cluttered"``, ``"open"`` or ``ArenaParams``.
        physics: Module constants (defaults when None).
        task: The task and its settings (reach when None).
        render_mode: ``"rgb_array"`` for pictures from ``render()``.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 20}

    def __init__(
        self,
        robot: Robot | str | os.PathLike[str],
        arena: str | ArenaParams = "clean",
        physics: PhysicsParams | None = None,
        task: Task | None = None,
        render_mode: str | None = None,
    ) -> None:
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be 'rgb_array' or None, got {render_mode!r}")
        if not isinstance(robot, Robot):
            robot = load_robot(robot)
        self.core = TaskCore(robot, physics, arena_params(arena), task, num_envs=1)
        size = self.core.obs_size
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, (size,), np.float32)
        self.action_space = gym.spaces.Box(-1.0, 1.0, (self.core.action_size,), np.float32)
        self.render_mode = render_mode
        self._renderer: mujoco.Renderer | None = None
        self._needs_reset = True  # before the first reset and after an episode ends

    # The options and info dicts take gymnasium.Env's types (str keys, Any values): its
    # checker and wrappers call these; their keys are documented above.
    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[Obs, dict[str, Any]]:
        super().reset(seed=seed)
        if seed is not None:
            self.core.seed(seed)
        observation = self.core.reset()[0]
        self._needs_reset = False
        return observation, {"target": self.core.target[0].copy()}

    def step(self, action: npt.ArrayLike) -> tuple[Obs, float, bool, bool, dict[str, Any]]:
        """One control step; ``action`` holds one value in [-1, 1] per actuator.

        Raises:
            gymnasium.error.ResetNeeded: Before the first ``reset`` and after an episode
                terminated or was truncated (gymnasium's convention: reset, then step).
            ValueError: For an action of the wrong size (named with the expected one).
        """
        if self._needs_reset:
            raise gym.error.ResetNeeded(
                "call reset() before step(): at the start, and after an episode terminated "
                "or was truncated")
        act = np.asarray(action, dtype=np.float64)
        if act.shape != self.action_space.shape:
            raise ValueError(
                f"action: expected shape {self.action_space.shape} (one value per motor, then "
                f"per pivot), got shape {act.shape}")
        step = self.core.step(act[None])
        self._needs_reset = bool(step.terminated[0] or step.truncated[0])
        info: dict[str, Any] = {  # gymnasium's info type
            f"reward/{k}": float(v[0]) for k, v in step.terms.items()}
        info["success"] = bool(step.success[0])
        info["unstable"] = bool(step.unstable[0])
        return (
            step.observation[0],
            float(step.reward[0]),
            bool(step.terminated[0]),
            bool(step.truncated[0]),
            info,
        )

    def render(self) -> npt.NDArray[np.uint8] | None:
        if self.render_mode != "rgb_array":
            return None
        from evo.robot.render import make_renderer

        if self._renderer is None:
            self._renderer = make_renderer(self.core.model, 480, 360)
        self.core.poses(0)  # puts arena 0's state into the scratch data
        data = self.core.scratch
        camera = mujoco.MjvCamera()
        camera.lookat[:] = (data.body("brain").xpos + self.core.target[0]) / 2
        camera.distance = 1.2 + float(np.linalg.norm(self.core.target[0, :2]))
        camera.azimuth, camera.elevation = 135.0, -45.0
        self._renderer.update_scene(data, camera=camera)
        image: npt.NDArray[np.uint8] = self._renderer.render().copy()
        return image

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
