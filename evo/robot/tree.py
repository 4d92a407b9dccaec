"""Robot structures as immutable trees of cube modules on an integer lattice.

A robot is a tree whose root is the ``brain``. Each edge stores the parent face the
child sits on (0..5: +x -x +y -y +z -z in the parent frame) and the child's rotation
about the connection axis (0, 90, 180 or 270 degrees). Trees are values: children are
kept sorted by face and a wheel edge's rotation (which has no physical effect) is
stored as 0, so two trees that describe the same structure compare and hash equal
however their children were listed.

Frames: a child on parent face ``f`` gets the axes ``FACE_AXES[f]`` (columns: the
child's x, y, z in the parent frame), then turned by its ``rotation`` about its own x.
The child's -x face is the one that mates with the parent, so every module grows
along its own +x, and its cell is the parent's cell plus the face normal.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Iterator
from dataclasses import dataclass, field
from enum import StrEnum
from typing import NotRequired, TypedDict

import numpy as np
import numpy.typing as npt

FORMAT = "evo.robot/1"
"""The value of the ``format`` key of every robot file."""

ROTATIONS = (0, 90, 180, 270)
"""Allowed child rotations about the connection axis, in degrees."""

IntMatrix = npt.NDArray[np.int64]


class ModuleType(StrEnum):
    """The module catalogue (paper section 3)."""

    BRAIN = "brain"
    MOTOR = "motor"
    PIVOT = "pivot"
    MAIN = "main"
    WHEEL = "wheel"


MOTION_TYPES = frozenset({ModuleType.MOTOR, ModuleType.PIVOT})
"""Module types that can move the robot; a valid robot has at least one."""

BODY_TYPES = (ModuleType.MOTOR, ModuleType.PIVOT, ModuleType.MAIN)
"""Module types the random generator and the type mutation choose from."""

MATING_FACE = 1
"""Every non-root module mates with its parent on its own -x face."""

BUTTON_FACE = 4
"""The brain's +z face carries its buttons and takes no child."""

DISTAL_FACE = 0
"""A pivot's only child sits on its +x face, on the distal half."""

MOTOR_WHEEL_FACES = (2, 3)
"""A motor's wheel pair sits on its +y and -y faces (axle along its y)."""

MAIN_WHEEL_FACE_PAIRS = ((2, 3), (4, 5))
"""Opposite face pairs on which a main module may carry a passive wheel pair."""

FACE_NORMALS: IntMatrix = np.array(
    [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], dtype=np.int64
)
"""Outward normal of each face in the module's own frame."""

FACE_AXES: tuple[IntMatrix, ...] = tuple(
    np.array(cols, dtype=np.int64).T
    for cols in (
        ([1, 0, 0], [0, 1, 0], [0, 0, 1]),
        ([-1, 0, 0], [0, -1, 0], [0, 0, 1]),
        ([0, 1, 0], [-1, 0, 0], [0, 0, 1]),
        ([0, -1, 0], [1, 0, 0], [0, 0, 1]),
        ([0, 0, 1], [0, 1, 0], [-1, 0, 0]),
        ([0, 0, -1], [0, 1, 0], [1, 0, 0]),
    )
)
"""Rotation of a child on each parent face (columns: child x, y, z in the parent frame)."""


def _rot_x(degrees: int) -> IntMatrix:
    c, s = {0: (1, 0), 90: (0, 1), 180: (-1, 0), 270: (0, -1)}[degrees]
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]], dtype=np.int64)


ROT_X: dict[int, IntMatrix] = {r: _rot_x(r) for r in ROTATIONS}
"""Rotation about a module's own x axis by each allowed angle."""


def child_frame(face: int, rotation: int) -> IntMatrix:
    """Orientation of a child relative to its parent.

    Args:
        face: The parent face the child sits on (0..5).
        rotation: The child's rotation about its own x, in degrees.

    Returns:
        A 3x3 integer rotation matrix whose columns are the child's axes in the parent frame.
    """
    return FACE_AXES[face] @ ROT_X[rotation]


class EdgeJSON(TypedDict):
    """A child on a face, in an ``evo.robot/1`` document."""

    face: int
    rotation: int
    module: NodeJSON


class NodeJSON(TypedDict):
    """A module in an ``evo.robot/1`` document (``children`` only when it has some)."""

    type: str
    children: NotRequired[list[EdgeJSON]]


class RobotJSON(TypedDict):
    """An ``evo.robot/1`` document."""

    format: str
    root: NodeJSON


@dataclass(frozen=True, slots=True)
class Edge:
    """The connection of a child module to one face of its parent."""

    face: int
    rotation: int
    module: Node


@dataclass(frozen=True, slots=True)
class Node:
    """One module and the edges to its children, kept in canonical order.

    Construct with children in any order: they are sorted by face, and wheel edges get
    rotation 0, so equal structures are equal values.
    """

    type: ModuleType
    children: tuple[Edge, ...] = field(default=())

    def __post_init__(self) -> None:
        canonical = tuple(
            sorted(
                (
                    Edge(e.face, 0, e.module) if e.module.type is ModuleType.WHEEL else e
                    for e in self.children
                ),
                key=lambda e: e.face,
            )
        )
        if canonical != self.children:
            object.__setattr__(self, "children", canonical)

    def child_on(self, face: int) -> Edge | None:
        """The edge on ``face``, or None when the face is free."""
        return next((e for e in self.children if e.face == face), None)

    def to_dict(self) -> NodeJSON:
        """The node as the JSON object of the ``evo.robot/1`` format."""
        out: NodeJSON = {"type": self.type.value}
        if self.children:
            out["children"] = [
                {"face": e.face, "rotation": e.rotation, "module": e.module.to_dict()}
                for e in self.children
            ]
        return out


Path = tuple[int, ...]
"""A node's address: the faces taken from the root to reach it."""


def format_path(path: Path, types: tuple[ModuleType, ...] | None = None) -> str:
    """A readable node path such as ``root/0:motor/2:wheel``.

    Args:
        path: The faces from the root to the node.
        types: The module type at each step (optional), printed beside the faces.
    """
    parts = ["root"]
    for i, face in enumerate(path):
        parts.append(f"{face}:{types[i].value}" if types else str(face))
    return "/".join(parts)


@dataclass(frozen=True, slots=True)
class Placed:
    """A module placed in the rest pose: its lattice cell, orientation and edge rotation."""

    path: Path
    node: Node
    parent: Placed | None
    cell: tuple[int, int, int]
    frame: IntMatrix = field(compare=False, repr=False)
    depth: int
    rotation: int = 0

    @property
    def label(self) -> str:
        """The node path with the module type of every step, for messages."""
        types: list[ModuleType] = []
        p: Placed | None = self
        while p is not None and p.parent is not None:
            types.append(p.node.type)
            p = p.parent
        return format_path(self.path, tuple(reversed(types)))


def walk(root: Node, max_depth: int | None = None) -> Iterator[Placed]:
    """Every module of the tree in depth-first order, placed on the lattice.

    Args:
        root: The root module (the brain).
        max_depth: Stop descending below this depth (protects against absurd inputs).

    Yields:
        Each module with its path, lattice cell and orientation, parents before children.
    """
    first = Placed((), root, None, (0, 0, 0), np.eye(3, dtype=np.int64), 0)
    stack = [first]
    while stack:
        placed = stack.pop()
        yield placed
        if max_depth is not None and placed.depth >= max_depth:
            continue
        for edge in reversed(placed.node.children):
            offset = placed.frame @ FACE_NORMALS[edge.face]
            cell = (
                placed.cell[0] + int(offset[0]),
                placed.cell[1] + int(offset[1]),
                placed.cell[2] + int(offset[2]),
            )
            frame = placed.frame @ child_frame(edge.face, edge.rotation)
            stack.append(
                Placed(
                    placed.path + (edge.face,),
                    edge.module,
                    placed,
                    cell,
                    frame,
                    placed.depth + 1,
                    edge.rotation,
                )
            )


@dataclass(frozen=True, slots=True)
class Robot:
    """A robot structure: an immutable module tree rooted at the brain.

    Equality and hashing come from the canonical form, so a robot can be used as a dict
    key or a set member for de-duplication.
    """

    root: Node

    def to_dict(self) -> RobotJSON:
        """The robot as an ``evo.robot/1`` JSON document."""
        return {"format": FORMAT, "root": self.root.to_dict()}

    def to_json(self, indent: int | None = 2) -> str:
        """The robot as ``evo.robot/1`` JSON text (canonical: children sorted by face)."""
        return json.dumps(self.to_dict(), indent=indent)

    def canonical_json(self) -> str:
        """The compact canonical serialisation that the hash is computed from."""
        return json.dumps(self.to_dict(), separators=(",", ":"), sort_keys=True)

    @property
    def hash(self) -> str:
        """A stable SHA-256 hex digest of the canonical form."""
        return hashlib.sha256(self.canonical_json().encode()).hexdigest()

    @property
    def name(self) -> str:
        """The robot's name, ``robot-<first 8 hex digits of the hash>``."""
        return f"robot-{self.hash[:8]}"

    def modules(self) -> list[Placed]:
        """Every module (wheels included) placed on the lattice, parents first."""
        return list(walk(self.root))

    def count(self, module_type: ModuleType) -> int:
        """How many modules of ``module_type`` the robot has."""
        return sum(1 for p in walk(self.root) if p.node.type is module_type)

    @property
    def n_motors(self) -> int:
        """m: the number of motors (each drives one wheel pair)."""
        return self.count(ModuleType.MOTOR)

    @property
    def n_pivots(self) -> int:
        """n: the number of pivots."""
        return self.count(ModuleType.PIVOT)

    @property
    def n_actuators(self) -> int:
        """m + n: one actuator per motor and per pivot (motors first in the model)."""
        return self.n_motors + self.n_pivots

    def actuator_paths(self) -> tuple[Path, ...]:
        """The node paths of the motors, then of the pivots, each in depth-first order:
        the order of the model's actuators (``evo.robot.builder``), so of a task's
        per-actuator slots."""
        placed = list(walk(self.root))
        return tuple(p.path for kind in (ModuleType.MOTOR, ModuleType.PIVOT)
                     for p in placed if p.node.type is kind)

    @property
    def depth(self) -> int:
        """Structural depth: edges from the brain to the deepest non-wheel module."""
        return max(p.depth for p in walk(self.root) if p.node.type is not ModuleType.WHEEL)

    def __len__(self) -> int:
        return sum(1 for _ in walk(self.root))
