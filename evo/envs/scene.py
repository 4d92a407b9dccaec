"""The scene of one arena as MJCF: the robot at the centre, walls, rocks and the target
marker (``conf/env/*.yaml``), with MuJoCo's sleeping islands when the arena asks."""

from __future__ import annotations

import xml.etree.ElementTree as ET

from evo.envs.arena import ArenaParams, arena_scene
from evo.envs.params import TaskParams
from evo.robot.builder import BuiltRobot, PhysicsParams, build
from evo.robot.tree import Robot


def build_scene(
    robot: Robot, physics: PhysicsParams, arena: ArenaParams, task: TaskParams
) -> BuiltRobot:
    """The robot in its arena as MJCF (robot at the centre, rocks and target marker)."""
    world = arena_scene(arena, task.success_radius)

    def scene(root: ET.Element) -> None:
        body = root.find("worldbody")
        assert body is not None
        body.extend(list(world))
        if arena.sleep:
            option = root.find("option")
            assert option is not None
            ET.SubElement(option, "flag", sleep="enable")

    return build(robot, physics, scene=scene)
