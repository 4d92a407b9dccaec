"""Push a box to a goal (SPEC section 3b; ``evo/Push-v0``), as DERL's manipulation task
and EvoGym's pushers.

Each episode places a movable box ``box_min``–``box_max`` m from the arena's centre,
where the robot starts, in a random direction, and the goal (the marker)
``goal_min``–``goal_max`` m beyond the box, in a direction within 90° either way of
straight on (start to box), so the box is never pushed back past the start. The
task's observation values are the direction to the box in the brain's horizontal frame
(2) and the distance to it (1, m: the closest horizontal distance of any module to the
box's centre); after the actuators' values, the direction from the box to the goal in
the brain's frame (2) and the box's distance to the goal (1, m).

Reward per control step, as named terms (their sum is the reward):

* ``time``: ``-1 / t_max``;
* ``near``: ``near_weight`` times how much closer the robot came to the box, m;
* ``push``: ``push_weight`` times how much closer the box came to the goal, m;
* ``success``: ``+1`` on the step where the box's centre is within ``goal_radius`` of
  the goal, which also terminates.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar

import numpy as np
import numpy.typing as npt

from evo.checks import at_least, positive
from evo.envs.arena import ArenaParams
from evo.envs.tasks.base import F64, Arenas, Bools, Rules, Task

if TYPE_CHECKING:
    import mujoco


@dataclass(frozen=True, slots=True)
class Push(Task):
    """The push task (its episode is shorter than reach's: 20 s, time enough to bring the
    box at most 1.1 m; more episodes per budget make the fitness steadier).

    Attributes:
        box_size: Half the side of the cubic box, m.
        box_mass: The box's mass, kg.
        box_min: Inner radius of the annulus around the start the box is placed in, m.
        box_max: Outer radius of that annulus, m.
        goal_min: Nearest the goal is drawn from the box, m.
        goal_max: Farthest the goal is drawn from the box, m.
        goal_radius: Success when the box's centre is this close to the goal, m.
        near_weight: Weight of the ``near`` term (per m the robot closes on the box).
        push_weight: Weight of the ``push`` term (per m the box closes on the goal).
    """

    t_max: int = 400
    box_size: float = 0.05
    box_mass: float = 0.1
    box_min: float = 0.3
    box_max: float = 0.5
    goal_min: float = 0.3
    goal_max: float = 0.6
    goal_radius: float = 0.1
    near_weight: float = 0.5
    push_weight: float = 2.0

    reward_terms: ClassVar[tuple[str, ...]] = ("time", "near", "push", "success")
    extra_slots: ClassVar[int] = 3

    def __post_init__(self) -> None:
        Task.__post_init__(self)
        positive(self, "box_size", "box_mass", "goal_radius")
        at_least(self, 0, "near_weight", "push_weight")
        for low, high in (("box_min", "box_max"), ("goal_min", "goal_max")):
            if not 0 <= getattr(self, low) <= getattr(self, high):
                raise ValueError(f"need 0 <= {low} <= {high}, got {getattr(self, low)}, "
                                 f"{getattr(self, high)}")
        if self.box_min < 2 * self.box_size + 0.15:
            raise ValueError(f"box_min ({self.box_min} m) must leave the robot's start "
                             f"clear: at least 2 x box_size + 0.15 = "
                             f"{2 * self.box_size + 0.15:g} m")

    @property
    def marker_radius(self) -> float:
        """The goal's disc: the goal radius."""
        return self.goal_radius

    def check_arena(self, arena: ArenaParams) -> None:
        self.within_walls(arena, "box_max + goal_max", round(self.box_max + self.goal_max, 9),
                          ": the goal lies inside the walls")

    def scene(self, root: ET.Element, arena: ArenaParams) -> None:
        """The box: a free body ``box`` that the robot can push."""
        size = f"{self.box_size:.6g}"
        world = root.find("worldbody")
        assert world is not None
        body = ET.SubElement(world, "body", name="box", pos=f"0 0 {size}")
        ET.SubElement(body, "freejoint", name="box")
        ET.SubElement(body, "geom", name="box", type="box", size=f"{size} {size} {size}",
                      mass=f"{self.box_mass:.6g}", rgba=".2 .45 .8 1")

    def rules(self, core: Arenas) -> Rules:
        return PushRules(self, core)


class PushRules(Rules):
    """The push task over a core's arenas: the robot's distance to the box and the box's
    to the goal, kept between steps."""

    task: Push

    def __init__(self, task: Push, core: Arenas) -> None:
        super().__init__(task, core)
        n = core.num_envs
        self.near = np.zeros(n)  # robot to box at the last step
        self.to_goal = np.zeros(n)  # box to goal at the last step
        self.measured = np.zeros((2, n))  # both of the last observe()
        self.address = core.joint_address("box")  # the box's free joint in qpos

    def draw(self, arena: int, rng: np.random.Generator, data: mujoco.MjData) -> F64:
        task = self.task
        r = math.sqrt(rng.uniform(task.box_min**2, task.box_max**2))
        a = rng.uniform(0, 2 * math.pi)
        box = np.array([r * math.cos(a), r * math.sin(a)])
        turn = a + rng.uniform(-math.pi / 2, math.pi / 2)  # onwards, away from the start
        reach = rng.uniform(task.goal_min, task.goal_max)
        goal = box + reach * np.array([math.cos(turn), math.sin(turn)])
        data.qpos[self.address:self.address + 7] = [*box, task.box_size, 1.0, 0.0, 0.0, 0.0]
        return np.array([*goal, 0.0])

    def _box(self) -> F64:
        box: F64 = self.core.qpos[:, self.address:self.address + 2]
        return box

    def _measure(self) -> F64:
        box = self._box()
        modules = self.core.module_positions()[:, :, :2]
        near = np.sqrt(((modules - box[:, None]) ** 2).sum(axis=2)).min(axis=1)
        to_goal = np.linalg.norm(self.core.target[:, :2] - box, axis=1)
        return np.stack([near, to_goal])

    def start(self, chosen: npt.NDArray[np.intp]) -> None:
        near, to_goal = self._measure()
        self.near[chosen], self.to_goal[chosen] = near[chosen], to_goal[chosen]

    def observe(self) -> tuple[F64, F64]:
        self.measured = self._measure()
        box = self._box()
        towards_goal = self.core.target[:, :2] - box
        towards_goal /= np.maximum(np.linalg.norm(towards_goal, axis=1, keepdims=True), 1e-9)
        return (np.concatenate([self.core.direction_to(box), self.measured[0, :, None]], axis=1),
                np.concatenate([self.core.in_brain_frame(towards_goal),
                                self.measured[1, :, None]], axis=1))

    def step(self, stable: Bools, last: Bools) -> tuple[dict[str, F64], Bools, Bools]:
        near, to_goal = self.measured
        task = self.task
        terms = {
            "time": np.full(self.core.num_envs, -1.0 / task.t_max),
            "near": np.where(stable, task.near_weight * (self.near - near), 0.0),
            "push": np.where(stable, task.push_weight * (self.to_goal - to_goal), 0.0),
        }
        success = stable & (to_goal < task.goal_radius)
        terms["success"] = success.astype(np.float64)
        self.near = np.where(stable, near, self.near)
        self.to_goal = np.where(stable, to_goal, self.to_goal)
        return terms, success, success
