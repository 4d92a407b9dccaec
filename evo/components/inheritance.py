"""Lamarckian policy inheritance: which parent's policy an offspring starts from.

Crossover and mutation record where every module of a child came from
(``evo.robot.operators.Origins``). With ``ga.inheritance: parent`` an offspring starts
from the trained policy of one parent: the one that gave it the most motors and pivots
(on a tie, the parent whose brain it kept, whose tree it is). For each of the child's
actuators, in action order, the start names the parent's actuator it follows, or -1
for one that parent did not give it (a module from the other parent, or one a mutation
made or changed); ``evo.learners.common.inherit`` maps the networks' slots from that.

Nothing here draws random numbers: with inheritance off or on, breeding consumes the
same generator, so the structures of a run do not depend on the setting.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from evo.robot.operators import Origins
from evo.robot.tree import Robot

INHERITANCE_MODES = ("off", "parent")
"""``ga.inheritance``: ``off`` trains every robot from scratch; ``parent`` starts an
offspring from the policy of the parent that gave it the most motors and pivots."""


@dataclass(frozen=True, slots=True)
class PolicyStart:
    """The policy an offspring starts from.

    Attributes:
        parent: The parent's name in the run (its policy is ``evals/<parent>.pt``).
        actuators: For each actuator of the child, in action order, the index of the
            parent's actuator it follows, or -1 when it has none there.
    """

    parent: str
    actuators: tuple[int, ...]


def actuator_origins(child: Robot, origins: Origins, parent: int, robot: Robot) -> tuple[int, ...]:
    """For each actuator of ``child``, the index of the actuator of parent number
    ``parent`` (whose structure is ``robot``) it came from, or -1."""
    index = {path: i for i, path in enumerate(robot.actuator_paths())}
    out = []
    for path in child.actuator_paths():
        source, there = origins.get(path, (-1, ()))
        out.append(index.get(there, -1) if source == parent else -1)
    return tuple(out)


def policy_start(mode: str, child: Robot, parents: Sequence[tuple[str, Robot]],
                 origins: Origins) -> PolicyStart | None:
    """The start of a bred ``child`` under ``ga.inheritance`` ``mode``, or None (from
    scratch: inheritance off, or a robot with no parents or no recorded origins).

    Args:
        mode: One of :data:`INHERITANCE_MODES`.
        child: The offspring.
        parents: The parents' names and structures, in the order ``origins`` numbers them.
        origins: Where the child's modules came from.
    """
    if mode not in INHERITANCE_MODES:
        raise ValueError(f"ga.inheritance: expected one of {', '.join(INHERITANCE_MODES)}, "
                         f"got {mode!r}")
    if mode == "off" or not parents or () not in origins:
        return None
    maps = [actuator_origins(child, origins, i, robot) for i, (_, robot) in enumerate(parents)]
    host = origins[()][0]
    given = [sum(k >= 0 for k in m) for m in maps]
    chosen = max(range(len(parents)), key=lambda i: (given[i], i == host))
    return PolicyStart(parents[chosen][0], maps[chosen])
