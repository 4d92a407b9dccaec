"""The scene of one arena as MJCF: the robot at the centre, walls, rocks, the task's
marker and whatever else the task adds (``conf/env/*.yaml``), with MuJoCo's sleeping
islands when the arena asks.

An evaluation compiles its scene once (:func:`compile_scene`) and hands the
:class:`Scene` to all that simulate or draw it: its recorders, the learner's arenas
(``evo.envs.core.TaskCore``) and the recorded deterministic episode
(``evo.learners.rollouts.play``). Nothing writes to the compiled model; each user makes
its own ``MjData``.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass

import mujoco

from evo.envs.arena import ArenaParams, arena_scene
from evo.envs.tasks.base import Task
from evo.robot.builder import BuiltRobot, PhysicsParams, build
from evo.robot.tree import Robot


def build_scene(
    robot: Robot, physics: PhysicsParams, arena: ArenaParams, task: Task
) -> BuiltRobot:
    """The robot in its arena as MJCF (robot at the centre, rocks, the task's marker and
    objects)."""
    world = arena_scene(arena, task.marker_radius)

    def scene(root: ET.Element) -> None:
        body = root.find("worldbody")
        assert body is not None
        body.extend(list(world))
        task.scene(root, arena)
        if arena.sleep:
            option = root.find("option")
            assert option is not None
            ET.SubElement(option, "flag", sleep="enable")

    return build(robot, physics, scene=scene)


@dataclass(frozen=True, eq=False)
class Scene:
    """One robot in its arena, built and compiled once.

    Attributes:
        robot, physics, arena, task: What it was built from.
        built: The MJCF and the names of its actuators and bodies.
        model: ``built`` compiled (read only: users make their own ``MjData``).
    """

    robot: Robot
    physics: PhysicsParams
    arena: ArenaParams
    task: Task
    built: BuiltRobot
    model: mujoco.MjModel

    def of(self, robot: Robot, physics: PhysicsParams, arena: ArenaParams,
           task: Task) -> bool:
        """Whether this is the scene of ``robot`` under these settings."""
        return (self.robot, self.physics, self.arena, self.task) == (robot, physics, arena, task)


def compile_scene(
    robot: Robot, physics: PhysicsParams, arena: ArenaParams, task: Task
) -> Scene:
    """:func:`build_scene` and its compiled model."""
    built = build_scene(robot, physics, arena, task)
    return Scene(robot, physics, arena, task, built, built.compile())
