"""Robot structures: module trees, the ``evo.robot/1`` file format, validity and operators."""

from evo.robot.io import RobotFileError, load_robot, parse_robot, save_robot
from evo.robot.operators import (
    CrossoverResult,
    GeneratorParams,
    OperatorError,
    crossover,
    mutate,
    random_robot,
    random_robots,
)
from evo.robot.tree import FORMAT, Edge, ModuleType, Node, Robot
from evo.robot.validate import InvalidRobotError, Limits, Violation, check, violations

__all__ = [
    "FORMAT",
    "CrossoverResult",
    "Edge",
    "GeneratorParams",
    "InvalidRobotError",
    "Limits",
    "ModuleType",
    "Node",
    "OperatorError",
    "Robot",
    "RobotFileError",
    "Violation",
    "check",
    "crossover",
    "load_robot",
    "mutate",
    "parse_robot",
    "random_robot",
    "random_robots",
    "save_robot",
    "violations",
]
