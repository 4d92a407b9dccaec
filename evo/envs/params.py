"""The environment's configuration and the observation's sizes, without the simulator
(SPEC sections 3 and 3b).

What a robot's observation and action look like is the task's business, not the
body's: a robot knows its motors and pivots (``Robot.n_actuators``); every task
observes 9 + 2(m + n) numbers, plus its ``extra_slots``, 3 with ``observe_up``, 1 with
``observe_stall``, 1 with ``observe_stall_count``, ``range_sectors`` with
``observe_range`` and 2 with ``observe_clock``, and takes one command per actuator.
Nothing here imports MuJoCo.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

from evo.checks import SWAPPABLE, at_least
from evo.envs.arena import ArenaParams
from evo.envs.tasks.base import Task
from evo.envs.tasks.reach import Reach
from evo.robot.tree import Robot

GLOBAL_SLOTS = 9
"""Observation values before the per-actuator ones: the brain's linear and angular
velocity (6) and three of the task's (reach: the direction to the target, 2, and its
distance, 1)."""

ACTUATOR_SLOTS = 2
"""Observation values per actuator, in action order (motors, then pivots): its state
(wheel speed or hinge angle) and its last command."""

UP_SLOTS = 3
"""Observation values after the task's extra ones with ``observe_up``: gravity."""

STALL_SLOTS = 1
"""Observation values after gravity with ``observe_stall``: how long the robot stood still."""

STALL_COUNT_SLOTS = 1
"""Observation values after the stall with ``observe_stall_count``: how often it stood still."""

CLOCK_SLOTS = 2
"""Observation values after the ranges with ``observe_clock``: the clock's sine and cosine."""


def observation_size(robot: Robot, task: Task) -> int:
    """Length of ``task``'s observation for ``robot``: 9 + 2(m + n), + the task's
    ``extra_slots``, + 3 with ``observe_up``, + 1 with ``observe_stall``, + 1 with
    ``observe_stall_count``, + ``range_sectors`` with ``observe_range``, + 2 with
    ``observe_clock``."""
    return (GLOBAL_SLOTS + ACTUATOR_SLOTS * robot.n_actuators + task.extra_slots
            + (UP_SLOTS if task.observe_up else 0)
            + (STALL_SLOTS if task.observe_stall else 0)
            + (STALL_COUNT_SLOTS if task.observe_stall_count else 0)
            + (task.range_sectors if task.observe_range else 0)
            + (CLOCK_SLOTS if task.observe_clock else 0))


def observation_origins(actuators: Sequence[int], parent_actuators: int,
                        parent_obs: int) -> list[int]:
    """Where each observation value of a robot comes from in another robot's observation.

    The layout is ``GLOBAL_SLOTS`` values of the brain and the task, ``ACTUATOR_SLOTS``
    per actuator in action order, then what the task adds at the end (its
    ``extra_slots``, ``UP_SLOTS`` with ``observe_up``, ``STALL_SLOTS`` with
    ``observe_stall``, ``STALL_COUNT_SLOTS`` with ``observe_stall_count``, ``range_sectors``
    with ``observe_range``, ``CLOCK_SLOTS`` with ``observe_clock``): the global and
    trailing values mean the same for every body, an actuator's two values follow the
    actuator.

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
    """Length of every task's action for ``robot``: one command per actuator, m + n."""
    return robot.n_actuators


@dataclass(frozen=True, slots=True)
class EnvConfig:
    """One ``conf/env/*.yaml``: which arena, the task, and how many threads step it.

    Attributes:
        name: Label of the arena (clean, cluttered), used in run names and reports.
        nthread: Threads MuJoCo uses to step one evaluation's arenas (1: one per
            worker of the executor).
        arena: The arena.
        task: The task, a swappable part (``conf/env/task/``, ``env/task=<name>``;
            ``evo.envs.tasks``): reach by default.
    """

    name: str = "clean"
    nthread: int = 1
    arena: ArenaParams = ArenaParams()
    task: Task = field(default=Reach(), metadata=SWAPPABLE)

    def __post_init__(self) -> None:
        at_least(self, 1, "nthread")
        try:
            self.task.check_arena(self.arena)
        except ValueError as err:
            raise ValueError(f"task: {err}") from None
