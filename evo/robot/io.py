"""Reading and writing ``evo.robot/1`` files.

Two kinds of failure are told apart, because scripts act on them differently
(``python -m evo.robot validate`` exits 2 and 1 for them):

* ``RobotFileError``: the file cannot be read, is not JSON, or is not an
  ``evo.robot/1`` document (wrong top-level type, missing or unknown ``format``).
* ``InvalidRobotError``: an ``evo.robot/1`` document that describes an invalid robot
  (unknown module type, bad face or rotation, broken structural rule). Every problem
  is listed, each with its node path.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

from evo.robot.tree import FORMAT, ROTATIONS, Edge, ModuleType, Node, Robot
from evo.robot.validate import InvalidRobotError, Limits, Violation, check

_MODULE_KEYS = {"type", "children"}
_EDGE_KEYS = {"face", "rotation", "module"}
_TYPES = ", ".join(t.value for t in ModuleType)


class RobotFileError(ValueError):
    """A robot file that cannot be read or is not an ``evo.robot/1`` document."""

    def __init__(self, source: str, reason: str) -> None:
        self.source = source
        self.reason = reason
        super().__init__(f"{source}: {reason}")


class _Parser:
    """Turns a JSON document into a tree, collecting every format problem on the way."""

    def __init__(self, limits: Limits) -> None:
        self.limits = limits
        self.problems: list[Violation] = []
        self.deep_reported = False

    def problem(self, path: str, message: str) -> None:
        self.problems.append(Violation(path, message))

    def module(self, raw: Any, path: str, depth: int) -> Node | None:
        if not isinstance(raw, dict):
            self.problem(path, f"a module must be a JSON object, got {type(raw).__name__}")
            return None
        for key in sorted(set(raw) - _MODULE_KEYS):
            self.problem(path, f"unknown key {key!r} in a module (expected 'type', 'children')")
        type_name = raw.get("type")
        if type_name not in {t.value for t in ModuleType}:
            self.problem(path, f"unknown module type {type_name!r}; expected one of {_TYPES}")
            return None
        children_raw = raw.get("children", [])
        if not isinstance(children_raw, list):
            self.problem(path, f"'children' must be a list, got {type(children_raw).__name__}")
            return None
        if children_raw and depth > self.limits.max_depth:
            if not self.deep_reported:
                self.deep_reported = True
                self.problem(path, f"nested deeper than the limit of {self.limits.max_depth}")
            return None
        edges = [self.edge(c, path, i, depth) for i, c in enumerate(children_raw)]
        return Node(ModuleType(type_name), tuple(e for e in edges if e is not None))

    def edge(self, raw: Any, parent: str, index: int, depth: int) -> Edge | None:
        here = f"{parent}/children[{index}]"
        if not isinstance(raw, dict):
            self.problem(here, f"a child must be a JSON object, got {type(raw).__name__}")
            return None
        for key in sorted(set(raw) - _EDGE_KEYS):
            self.problem(here, f"unknown key {key!r} in a child (expected face, rotation, module)")
        face, rotation = raw.get("face"), raw.get("rotation", 0)
        ok = True
        if isinstance(face, bool) or not isinstance(face, int) or not 0 <= face <= 5:
            self.problem(here, f"'face' must be an integer 0..5, got {face!r}")
            ok = False
        if isinstance(rotation, bool) or not isinstance(rotation, int) or rotation not in ROTATIONS:
            self.problem(here, f"'rotation' must be one of 0, 90, 180, 270, got {rotation!r}")
            ok = False
        if "module" not in raw:
            self.problem(here, "missing 'module'")
            return None
        node = self.module(raw["module"], f"{parent}/{face}" if ok else here, depth + 1)
        if not ok or node is None or face is None:
            return None
        return Edge(face, rotation, node)


def parse_robot(doc: Any, source: str = "robot", limits: Limits | None = None) -> Robot:
    """Build a valid robot from a decoded ``evo.robot/1`` JSON document.

    Args:
        doc: The decoded JSON value.
        source: What to call the document in messages (usually the file name).
        limits: Size limits (defaults to ``Limits()``).

    Returns:
        The robot, in canonical form.

    Raises:
        RobotFileError: ``doc`` is not an ``evo.robot/1`` document.
        InvalidRobotError: the document describes an invalid robot (every problem listed).
    """
    limits = limits or Limits()
    if not isinstance(doc, dict):
        raise RobotFileError(source, f"expected a JSON object at the top, got {type(doc).__name__}")
    if "format" not in doc:
        raise RobotFileError(source, f"missing 'format' key (expected {FORMAT!r})")
    if doc["format"] != FORMAT:
        raise RobotFileError(source, f"unknown format {doc['format']!r} (expected {FORMAT!r})")
    if "root" not in doc:
        raise InvalidRobotError([Violation("root", "missing 'root' module")], source)
    parser = _Parser(limits)
    root = parser.module(doc["root"], "root", 0)
    if parser.problems or root is None:
        raise InvalidRobotError(parser.problems, source)
    return check(Robot(root), limits, source)


def load_robot(path: str | os.PathLike[str], limits: Limits | None = None) -> Robot:
    """Read a robot file.

    Raises:
        RobotFileError: unreadable, not JSON, or not an ``evo.robot/1`` document.
        InvalidRobotError: the robot breaks a rule (every problem listed, with node paths).
    """
    source = str(path)
    try:
        text = Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as err:
        raise RobotFileError(source, f"cannot read file: {err}") from None
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as err:
        raise RobotFileError(source, f"not valid JSON: {err}") from None
    except RecursionError:
        raise RobotFileError(source, "JSON nested too deeply to be a robot") from None
    return parse_robot(doc, source, limits)


def save_robot(robot: Robot, path: str | os.PathLike[str]) -> Path:
    """Write ``robot`` as canonical ``evo.robot/1`` JSON and return the path."""
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(out.name + ".tmp")
    tmp.write_text(robot.to_json() + "\n", encoding="utf-8")
    tmp.replace(out)
    return out
