"""Reach the target (the paper's task, SPEC section 3; ``evo/Reach-v0``).

Each episode draws a target uniformly in area over an annulus around the arena's
centre, where the robot starts. The task's observation values are the direction to
the target in the brain's horizontal frame (2; x = heading) and the distance d (1, m):
the closest horizontal distance of any module to the target.

Reward per control step, as named terms (their sum is the reward):

* ``time``: ``-1 / t_max``;
* ``approach``: ``((d_prev - d) / L) * (1 - d / L)``, positive when the robot gets closer
  (the sign of the paper's Eq. 10 is reversed there; SPEC decision);
* ``success``: ``+1`` on the step where ``d < success_radius``, which also terminates.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar

import numpy as np
import numpy.typing as npt

from evo.checks import positive
from evo.envs.arena import ArenaParams, sample_target
from evo.envs.tasks.base import F64, Arenas, Bools, Rules, Task

if TYPE_CHECKING:
    import mujoco


@dataclass(frozen=True, slots=True)
class Reach(Task):
    """The reach task.

    Attributes:
        success_radius: Success when any module is this close to the target
            (horizontally), m.
        target_min: Inner radius of the annulus the target is drawn from, m.
        target_max: Outer radius of that annulus, m.
    """

    success_radius: float = 0.1
    target_min: float = 0.5
    target_max: float = 1.5

    reward_terms: ClassVar[tuple[str, ...]] = ("time", "approach", "success")

    def __post_init__(self) -> None:
        Task.__post_init__(self)
        positive(self, "success_radius")
        if not 0 <= self.target_min <= self.target_max:
            raise ValueError(
                f"need 0 <= target_min <= target_max, got {self.target_min}, {self.target_max}"
            )

    @property
    def marker_radius(self) -> float:
        """The target's disc: the success radius."""
        return self.success_radius

    def check_arena(self, arena: ArenaParams) -> None:
        self.within_walls(arena, "target_max", self.target_max,
                          ": the target lies inside the walls")

    def rules(self, core: Arenas) -> Rules:
        return ReachRules(self, core)


class ReachRules(Rules):
    """The reach task over a core's arenas: the distance d of each, kept between steps."""

    task: Reach

    def __init__(self, task: Reach, core: Arenas) -> None:
        super().__init__(task, core)
        self.distance = np.zeros(core.num_envs)  # d at the last step (or the reset)
        self.measured = np.zeros(core.num_envs)  # d of the last observe()

    def draw(self, arena: int, rng: np.random.Generator, data: mujoco.MjData) -> F64:
        return sample_target(rng, self.task.target_min, self.task.target_max)

    def _distance(self) -> F64:
        """d of every arena: the closest horizontal distance of a module to the target."""
        gap = self.core.target[:, None, :2] - self.core.module_positions()[:, :, :2]
        distance: F64 = np.sqrt((gap**2).sum(axis=2)).min(axis=1)
        return distance

    def start(self, chosen: npt.NDArray[np.intp]) -> None:
        self.distance[chosen] = self._distance()[chosen]

    def observe(self) -> tuple[F64, F64]:
        self.measured = self._distance()
        direction = self.core.direction_to(self.core.target)
        return (np.concatenate([direction, self.measured[:, None]], axis=1),
                np.zeros((self.core.num_envs, 0)))

    def step(self, stable: Bools, last: Bools) -> tuple[dict[str, F64], Bools, Bools]:
        distance, L = self.measured, self.core.arena.side
        approach = np.where(stable, (self.distance - distance) / L * (1 - distance / L), 0.0)
        success = stable & (distance < self.task.success_radius)
        self.distance = np.where(stable, distance, self.distance)
        terms = {
            "time": np.full(self.core.num_envs, -1.0 / self.task.t_max),
            "approach": approach,
            "success": success.astype(np.float64),
        }
        return terms, success, success
