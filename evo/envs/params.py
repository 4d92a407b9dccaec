"""The reach task's configuration and sizes, without the simulator (SPEC section 3).

What a robot's observation and action look like is the task's business, not the
body's: a robot knows its motors and pivots (``Robot.n_actuators``); the reach task
observes 9 + 2(m + n) numbers (+ 3 with ``observe_up``) and takes one command per
actuator. Nothing here imports MuJoCo, so ``python -m evo.robot info`` can print the
sizes on a machine without a working OpenGL.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from evo.checks import at_least, positive
from evo.envs.arena import ArenaParams
from evo.robot.tree import Robot

REWARD_TERMS = ("time", "approach", "success")

GLOBAL_SLOTS = 9
"""Observation values before the per-actuator ones: the brain's linear and angular
velocity (6), the direction to the target (2) and its distance (1)."""

ACTUATOR_SLOTS = 2
"""Observation values per actuator, in action order (motors, then pivots): its state
(wheel speed or hinge angle) and its last command."""

UP_SLOTS = 3
"""Observation values after the per-actuator ones with ``observe_up``: gravity."""


@dataclass(frozen=True, slots=True)
class TaskParams:
    """The reach task.

    Attributes:
        t_max: Control steps per episode before truncation.
        frame_skip: Physics steps per control step (0.005 s x 10 = 20 Hz control).
        success_radius: Success when any module is this close to the target
            (horizontally), m.
        target_min: Inner radius of the annulus the target is drawn from, m.
        target_max: Outer radius of that annulus, m.
        observe_up: Add gravity's direction in the brain frame to the observation.
        max_height: A module centre higher than this, m, or beyond the walls' centre
            lines means the physics threw the robot (a contact blow-up): that arena's
            episode ends as unstable. Far outside the arena the approach term grows
            with distance and would pay for being thrown.
    """

    t_max: int = 1000
    frame_skip: int = 10
    success_radius: float = 0.1
    target_min: float = 0.5
    target_max: float = 1.5
    observe_up: bool = False
    max_height: float = 1.0

    def __post_init__(self) -> None:
        at_least(self, 1, "t_max", "frame_skip")
        positive(self, "success_radius", "max_height")
        if not 0 <= self.target_min <= self.target_max:
            raise ValueError(
                f"need 0 <= target_min <= target_max, got {self.target_min}, {self.target_max}"
            )


def observation_size(robot: Robot, task: TaskParams) -> int:
    """Length of the reach task's observation for ``robot``: 9 + 2(m + n), + 3 with
    ``observe_up``."""
    return GLOBAL_SLOTS + ACTUATOR_SLOTS * robot.n_actuators + (UP_SLOTS if task.observe_up else 0)


def observation_origins(actuators: Sequence[int], parent_actuators: int,
                        parent_obs: int) -> list[int]:
    """Where each observation value of a robot comes from in another robot's observation.

    The layout is ``GLOBAL_SLOTS`` values of the brain, ``ACTUATOR_SLOTS`` per actuator
    in action order, then what the task adds at the end (``UP_SLOTS`` with
    ``observe_up``): the global and trailing values mean the same for every body, an
    actuator's two values follow the actuator.

    Args:
        actuators: For each actuator of the robot, the other robot's actuator it
            follows, or -1 for none.
        parent_actuators: The other robot's actuator count.
        parent_obs: The other robot's observation size.

    Returns:
        For each observation value of the robot, the index of the other robot's value it
        is, or -1 when it has none.
    """
    out = list(range(GLOBAL_SLOTS))
    for k in actuators:
        out += [GLOBAL_SLOTS + ACTUATOR_SLOTS * k + i if k >= 0 else -1
                for i in range(ACTUATOR_SLOTS)]
    tail = GLOBAL_SLOTS + ACTUATOR_SLOTS * parent_actuators
    return out + list(range(tail, parent_obs))


def action_size(robot: Robot) -> int:
    """Length of the reach task's action for ``robot``: one command per actuator, m + n."""
    return robot.n_actuators


@dataclass(frozen=True, slots=True)
class EnvConfig:
    """One ``conf/env/*.yaml``: which arena, the task, and how many threads step it.

    Attributes:
        name: Label of the arena (clean, cluttered), used in run names and reports.
        nthread: Threads MuJoCo uses to step one evaluation's arenas (1: one per
            worker of the executor).
        arena: The arena.
        task: The task.
    """

    name: str = "clean"
    nthread: int = 1
    arena: ArenaParams = ArenaParams()
    task: TaskParams = TaskParams()

    def __post_init__(self) -> None:
        at_least(self, 1, "nthread")
        inside = self.arena.side / 2 - self.arena.wall_thickness
        if self.task.target_max >= inside:
            raise ValueError(
                f"task: target_max ({self.task.target_max} m) must be below half the arena "
                f"side less a wall, {inside:g} m (arena.side = {self.arena.side} m): the "
                "target lies inside the walls")
