"""What every task is: its settings (:class:`Task`) and its rules over a batch of arenas
(:class:`Rules`), which the batched core (``evo.envs.core.Arenas``) calls.

A task's observation keeps the layout inheritance relies on (``evo.envs.params``): the
brain's linear and angular velocity (6) and three values of the task's own, two values
per actuator in action order, then ``extra_slots`` more values of the task's, with
``observe_up`` gravity (3), with ``observe_stall`` how long the robot has stood still (1)
and with ``observe_stall_count`` how often it has this episode (1), with ``observe_range``
how far the obstacles around it are (``range_sectors``) and with ``observe_clock`` a
clock (2). Its reward is a sum of named terms (``reward_terms``), each logged as
``train/reward/<term>``.

Writing a task is one module and one YAML file::

    @dataclass(frozen=True, slots=True)
    class Spin(Task):
        '''Turn on the spot as fast as possible.'''
        reward_terms: ClassVar[tuple[str, ...]] = ("spin",)

        def rules(self, core: Core) -> Rules:
            return SpinRules(self, core)

with ``conf/env/task/spin.yaml`` naming it (``_target_: mypackage.Spin``) and chosen by
``env/task=spin``; ``docs/tasks.md`` walks through one.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar, Protocol

import numpy as np
import numpy.typing as npt

from evo.checks import at_least, positive

if TYPE_CHECKING:
    import mujoco

    from evo.envs.arena import ArenaParams

F64 = npt.NDArray[np.float64]
Bools = npt.NDArray[np.bool_]


class Arenas(Protocol):
    """What a task's rules read of the batched core (``evo.envs.core.Arenas``), all
    arrays over its ``num_envs`` arenas."""

    num_envs: int
    arena: ArenaParams
    sensordata: F64
    qpos: F64
    """(N, nq): every arena's joint positions (a free body's: x, y, z, then w, x, y, z)."""
    target: F64
    """(N, 3): where each arena's marker stands (what :meth:`Rules.draw` returned)."""
    steps: npt.NDArray[np.int64]
    """Control steps of each running episode."""

    def mocap_index(self, name: str) -> int:
        """The index of mocap body ``name`` in ``MjData.mocap_pos``."""
        ...

    def joint_address(self, name: str) -> int:
        """Where joint ``name``'s values start in a ``qpos`` row."""
        ...

    def module_positions(self) -> F64:
        """World position of every module, (N, modules, 3)."""
        ...

    def in_brain_frame(self, vectors: F64) -> F64:
        """Horizontal world vectors (N, 2) in each brain's horizontal frame."""
        ...

    def direction_to(self, points: F64) -> F64:
        """Unit direction from each brain to its point, in the brain's horizontal frame."""
        ...


@dataclass(frozen=True, slots=True)
class Task:
    """What every task sets: the episode's length and control rate, what it adds to
    the observation, and when the physics threw the robot.

    Attributes:
        t_max: Control steps per episode before truncation.
        frame_skip: Physics steps per control step (0.005 s x 10 = 20 Hz control).
        observe_up: Add gravity's direction in the brain frame to the observation.
        observe_stall: Add how long the brain has stood still to the observation
            (one value, after gravity): the time since it last moved ``stall_radius`` away from
            where it was, over ``stall_seconds``, capped at 1. A memoryless controller
            pinned against an obstacle sees the same observation every step and so
            repeats its action; this value changes while it stays pinned.
        observe_stall_count: Add how many times this episode the brain has stood still
            for ``stall_seconds``, over 4, capped at 1 (one value, after the stall
            value): a controller pinned by the same rock again can act otherwise than
            the time before.
        observe_range: Add what a ring of range sensors on the brain would read
            (``range_sectors`` values, last): the circle around the brain's centre cut
            into ``range_sectors`` equal sectors, counter-clockwise from its heading
            (the first centred straight ahead), each the distance to the nearest rock
            (its horizontal bounding circle, whatever its height) or wall in it, over
            ``range_max``, capped at 1. Without it a robot of the cluttered arena
            cannot tell a rock ahead from open floor.
        range_sectors: Sensors (sectors) of ``observe_range``.
        range_max: Distance at which a sensor's value reaches 1, m.
        observe_clock: Add a clock to the observation (two values, last): the sine and
            cosine of 2 pi t / ``clock_period``, t the episode's simulated time (0 after a
            reset). A memoryless controller's mean action is a function of the body's
            state alone; with the clock it can also follow a rhythm of its own (on the
            reach task it made every robot tried worse: docs/results/deployed.md).
        clock_period: Period of ``observe_clock``, s.
        stall_radius: Horizontal distance the brain must move to count as moving, m.
        stall_seconds: Time of standing still at which the stall value reaches 1 (and
            a stall counts), s.
        max_height: A module centre higher than this, m, or beyond the walls' centre
            lines means the physics threw the robot (a contact blow-up): that arena's
            episode ends as unstable.
    """

    t_max: int = 1000
    frame_skip: int = 10
    observe_up: bool = False
    max_height: float = 1.0
    observe_stall: bool = False
    observe_stall_count: bool = False
    stall_radius: float = 0.05
    stall_seconds: float = 2.0
    observe_range: bool = False
    range_sectors: int = 8
    range_max: float = 0.5
    observe_clock: bool = False
    clock_period: float = 1.0

    reward_terms: ClassVar[tuple[str, ...]] = ()
    """The names of the reward's terms, in the order they are summed."""
    extra_slots: ClassVar[int] = 0
    """Observation values the task adds after the per-actuator ones (before gravity)."""

    def __post_init__(self) -> None:
        at_least(self, 1, "t_max", "frame_skip", "range_sectors")
        positive(self, "max_height", "stall_radius", "stall_seconds", "range_max",
                 "clock_period")

    @property
    def marker_radius(self) -> float:
        """Radius of the flat disc that marks the task's point (a target, a heading, a
        goal) in pictures and replays, m."""
        return 0.1

    def check_arena(self, arena: ArenaParams) -> None:
        """Raise ``ValueError`` (naming the key) when ``arena`` cannot hold this task."""

    @staticmethod
    def within_walls(arena: ArenaParams, what: str, reach: float, why: str = "") -> None:
        """Raise ``ValueError`` unless ``reach`` (m from the arena's centre; ``what``
        names the keys it comes from) is below half the arena side less a wall."""
        inside = arena.side / 2 - arena.wall_thickness
        if reach >= inside:
            raise ValueError(f"{what} ({reach} m) must be below half the arena side less "
                             f"a wall, {inside:g} m (arena.side = {arena.side} m){why}")

    def scene(self, root: ET.Element, arena: ArenaParams) -> None:
        """Add the task's own bodies and assets to the scene's MJCF ``root``
        (``<mujoco>``: its ``<worldbody>`` holds the robot, the arena's floor, walls and
        rocks and the ``target`` marker already; its ``<asset>``, the builder's)."""

    def rules(self, core: Arenas) -> Rules:
        """The task's rules over ``core``'s arenas."""
        raise NotImplementedError(f"{type(self).__name__}: a task must define rules()")


class Rules:
    """A task played over the ``N`` arenas of one core, all with arrays over arenas.

    The core calls, for the arenas that start an episode, :meth:`draw` for each (then
    runs MuJoCo's forward pass and reads the sensors), :meth:`start` for them all and
    :meth:`observe`; at every control step, after the physics, :meth:`observe` then
    :meth:`step`. ``core.sensordata``, ``core.target`` (the marker of each arena)
    and ``core.steps`` (control steps of each running episode) are the state it reads.

    Args:
        task: The task's settings.
        core: The core whose arenas it plays on.
    """

    def __init__(self, task: Task, core: Arenas) -> None:
        self.task, self.core = task, core

    def draw(self, arena: int, rng: np.random.Generator, data: mujoco.MjData) -> F64:
        """Draw ``arena``'s new episode from ``rng`` into ``data`` (freshly reset, before
        the forward pass: its objects' ``qpos``) and return where its marker stands,
        (3,) m. The arena's rocks are scattered around the marker afterwards."""
        raise NotImplementedError

    def start(self, chosen: npt.NDArray[np.intp]) -> None:
        """The arenas ``chosen`` begin an episode (or their marker moved): take the
        current sensors as their starting point."""

    def observe(self) -> tuple[F64, F64]:
        """The task's observation values of every arena from the current sensors:
        three after the brain's velocities, (N, 3), and ``extra_slots`` after the
        actuators', (N, extra_slots). Keeps what :meth:`step` measures."""
        raise NotImplementedError

    def step(self, stable: Bools, last: Bools) -> tuple[dict[str, F64], Bools, Bools]:
        """One control step's reward terms (by ``reward_terms``), success and
        termination of every arena; ``stable``: the arenas whose physics stayed sound
        (an unstable one earns no task term), ``last``: those at their last step."""
        raise NotImplementedError
