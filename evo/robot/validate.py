"""Structural validity of robot trees (SPEC section 1).

``violations`` returns every problem it finds, each with the path of the node it is
about, so a user fixing a hand-written file sees them all at once.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass

from evo.checks import at_least
from evo.robot.tree import (
    BUTTON_FACE,
    DISTAL_FACE,
    MAIN_WHEEL_FACE_PAIRS,
    MATING_FACE,
    MOTION_TYPES,
    MOTOR_WHEEL_FACES,
    ModuleType,
    Node,
    Placed,
    Robot,
    walk,
)


@dataclass(frozen=True, slots=True)
class Limits:
    """Size limits a valid robot must respect.

    Attributes:
        max_depth: Most edges from the brain to any non-wheel module.
        max_modules: Most modules in all, brain and wheels included.
    """

    max_depth: int = 6
    max_modules: int = 40

    def __post_init__(self) -> None:
        at_least(self, 1, "max_depth")
        at_least(self, 4, "max_modules")


@dataclass(frozen=True, slots=True)
class Violation:
    """One reason a robot is invalid."""

    path: str
    message: str

    def __str__(self) -> str:
        return f"{self.path}: {self.message}"


class InvalidRobotError(ValueError):
    """A robot that breaks the structural rules; ``violations`` lists every problem."""

    def __init__(self, violations: list[Violation], source: str = "robot") -> None:
        self.violations = violations
        self.source = source
        lines = "\n".join(f"  - {v}" for v in violations)
        count = f"{len(violations)} problem{'' if len(violations) == 1 else 's'}"
        super().__init__(f"{source} is not a valid robot ({count}):\n{lines}")


def _wheel_faces(node: Node) -> list[int]:
    return [e.face for e in node.children if e.module.type is ModuleType.WHEEL]


def _check_children(p: Placed) -> list[str]:
    """Rules on one module's own children, by module type."""
    node, problems = p.node, []
    faces = [e.face for e in node.children]
    for face, n in Counter(faces).items():
        if n > 1:
            problems.append(f"{n} children on face {face}; a face holds at most one")
    wheels = _wheel_faces(node)
    others = [e for e in node.children if e.module.type is not ModuleType.WHEEL]
    kind = node.type
    if kind is ModuleType.BRAIN:
        if p.parent is not None:
            problems.append("a second brain; a robot has exactly one, at the root")
        if BUTTON_FACE in faces:
            problems.append(f"child on the brain's button face {BUTTON_FACE} (+z)")
        if wheels:
            problems.append("wheel under the brain; wheels go only under a motor or main")
    elif kind is ModuleType.WHEEL and node.children:
        problems.append("a wheel has children; wheels are leaves")
    if kind is not ModuleType.BRAIN and MATING_FACE in faces:
        problems.append(f"child on the mating face {MATING_FACE} (-x)")
    if kind is ModuleType.MOTOR:
        if others:
            problems.append("motor with a non-wheel child; a motor carries only its wheel pair")
        if sorted(wheels) != list(MOTOR_WHEEL_FACES):
            problems.append(
                f"motor needs exactly one wheel pair on faces 2 and 3, has wheels on {wheels}"
            )
    elif kind is ModuleType.PIVOT:
        if wheels:
            problems.append("wheel under a pivot; wheels go only under a motor or main")
        if len(node.children) > 1:
            problems.append(f"pivot has {len(node.children)} children; it takes at most one")
        if any(f != DISTAL_FACE for f in faces):
            problems.append(f"pivot child off face {DISTAL_FACE}; it sits on the distal face 0")
    elif kind is ModuleType.MAIN and wheels:
        if len(wheels) == 1:
            problems.append(f"single wheel on face {wheels[0]}; wheels come in pairs")
        elif tuple(sorted(wheels)) not in MAIN_WHEEL_FACE_PAIRS:
            problems.append(
                f"wheels on faces {sorted(wheels)}; a main carries one pair, on faces 2+3 or 4+5"
            )
    return problems


def violations(root: Node, limits: Limits | None = None) -> list[Violation]:
    """Every rule the tree breaks.

    Args:
        root: The tree's root module.
        limits: Size limits (defaults to ``Limits()``).

    Returns:
        One ``Violation`` per problem, with the node path; empty when the robot is valid.
    """
    limits = limits or Limits()
    found: list[Violation] = []
    if root.type is not ModuleType.BRAIN:
        found.append(Violation("root", f"the root must be a brain, not a {root.type.value}"))
    occupied: dict[tuple[int, int, int], Placed] = {}
    n_modules, has_motion, too_deep = 0, False, False
    # The walk stops one level below the limit, so a 200-deep chain fails fast.
    for p in walk(root, max_depth=limits.max_depth + 1):
        n_modules += 1
        has_motion |= p.node.type in MOTION_TYPES
        if p.node.type is not ModuleType.WHEEL and p.depth > limits.max_depth and not too_deep:
            too_deep = True
            found.append(Violation(p.label, f"deeper than the limit of {limits.max_depth}"))
        found.extend(Violation(p.label, msg) for msg in _check_children(p))
        other = occupied.setdefault(p.cell, p)
        if other is not p:  # labels are built only for messages: they cost half the check
            found.append(
                Violation(p.label, f"self-collision: shares cell {p.cell} with {other.label}")
            )
    if n_modules > limits.max_modules:
        found.append(
            Violation("root", f"{n_modules} modules, over the limit of {limits.max_modules}")
        )
    if not has_motion:
        found.append(Violation("root", "no motion module; a robot needs a motor or a pivot"))
    return found


def is_valid(root: Node, limits: Limits | None = None) -> bool:
    """Whether the tree breaks no rule."""
    return not violations(root, limits)


def check(robot: Robot, limits: Limits | None = None, source: str = "robot") -> Robot:
    """Return ``robot`` unchanged, or raise ``InvalidRobotError`` listing every problem."""
    found = violations(robot.root, limits)
    if found:
        raise InvalidRobotError(found, source)
    return robot
