"""Travel along a heading (SPEC section 3b; ``evo/Locomotion-v0``): as far as possible
in a fixed time on flat ground, as DERL's flat terrain and Revolve2's displacement.

Each episode draws a heading, uniform within ``heading_range`` degrees of the world's
x axis (0: always +x). The robot's position is the centroid of its modules; the
task's observation values are the heading in the brain's horizontal frame (2; x =
forward) and the distance travelled along it so far (1, m). The marker stands
``success_distance`` along the heading from the start.

Reward per control step, one term: ``forward``, the centroid's displacement along the
heading, m. An episode's return is how far the robot travelled along the heading; it
ends only by truncation after ``t_max`` control steps, a success when the robot is then
at least ``success_distance`` along.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar

import numpy as np
import numpy.typing as npt

from evo.checks import positive, within
from evo.envs.arena import ArenaParams
from evo.envs.tasks.base import F64, Arenas, Bools, Rules, Task

if TYPE_CHECKING:
    import mujoco


@dataclass(frozen=True, slots=True)
class Locomotion(Task):
    """The locomotion task (its episode is shorter than reach's: 20 s).

    Attributes:
        heading_range: Each episode's heading is drawn uniformly within this many
            degrees of the x axis, either way (0 to 180; 0: always +x).
        success_distance: An episode is a success when the robot ends at least this
            far along the heading, m.
    """

    t_max: int = 400
    heading_range: float = 180.0
    success_distance: float = 1.0

    reward_terms: ClassVar[tuple[str, ...]] = ("forward",)

    def __post_init__(self) -> None:
        Task.__post_init__(self)
        within(self, 0, 180, "heading_range", note=" (degrees either side of +x)")
        positive(self, "success_distance")

    def check_arena(self, arena: ArenaParams) -> None:
        self.within_walls(arena, "success_distance", self.success_distance)

    def rules(self, core: Arenas) -> Rules:
        return LocomotionRules(self, core)


class LocomotionRules(Rules):
    """Locomotion over a core's arenas: each one's heading, start and position."""

    task: Locomotion

    def __init__(self, task: Locomotion, core: Arenas) -> None:
        super().__init__(task, core)
        n = core.num_envs
        self.heading = np.tile([1.0, 0.0], (n, 1))  # unit vectors in the world
        self.origin = np.zeros((n, 2))  # the centroid at the episode's start
        self.along = np.zeros(n)  # distance along the heading at the last step
        self.measured = np.zeros(n)  # that of the last observe()

    def draw(self, arena: int, rng: np.random.Generator, data: mujoco.MjData) -> F64:
        angle = math.radians(rng.uniform(-self.task.heading_range, self.task.heading_range))
        self.heading[arena] = math.cos(angle), math.sin(angle)
        return np.array([*self.heading[arena], 0.0]) * self.task.success_distance

    def _centroid(self) -> F64:
        centroid: F64 = self.core.module_positions()[:, :, :2].mean(axis=1)
        return centroid

    def start(self, chosen: npt.NDArray[np.intp]) -> None:
        self.origin[chosen] = self._centroid()[chosen]
        self.along[chosen] = 0.0

    def observe(self) -> tuple[F64, F64]:
        self.measured = ((self._centroid() - self.origin) * self.heading).sum(axis=1)
        ahead = self.core.in_brain_frame(self.heading)
        return (np.concatenate([ahead, self.measured[:, None]], axis=1),
                np.zeros((self.core.num_envs, 0)))

    def step(self, stable: Bools, last: Bools) -> tuple[dict[str, F64], Bools, Bools]:
        forward = np.where(stable, self.measured - self.along, 0.0)
        self.along = np.where(stable, self.measured, self.along)
        success = stable & last & (self.along >= self.task.success_distance)
        return {"forward": forward}, success, np.zeros(self.core.num_envs, dtype=bool)
