"""Structure operators: random generation, subtree crossover and mutation (paper section 6).

Every operator takes an explicit ``numpy.random.Generator`` and returns new trees; the
inputs are never changed. Operators retry until their result is valid, a bounded number
of times, then raise ``OperatorError`` with what they tried.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from evo.checks import at_least
from evo.robot.tree import (
    BODY_TYPES,
    BUTTON_FACE,
    DISTAL_FACE,
    FACE_NORMALS,
    MAIN_WHEEL_FACE_PAIRS,
    MATING_FACE,
    MOTOR_WHEEL_FACES,
    ROTATIONS,
    Edge,
    IntMatrix,
    ModuleType,
    Node,
    Path,
    Placed,
    Robot,
    child_frame,
    walk,
)
from evo.robot.validate import Limits, is_valid

Cell = tuple[int, int, int]


class OperatorError(RuntimeError):
    """A structure operator found no valid result within its retry budget."""


@dataclass(frozen=True, slots=True)
class GeneratorParams:
    """How random robots are grown (paper section 6, "Generation").

    Attributes:
        max_depth: Deepest level (edges from the brain) a non-wheel module is placed at.
        p_empty: Probability that a free face is left empty, so robot sizes vary.
        p_passive_wheels: Probability that a main module carries a passive wheel pair.
        type_weights: Relative odds of motor, pivot and main for each new module.
        max_tries: Attempts before giving up on a valid robot.
    """

    max_depth: int = 3
    p_empty: float = 0.5
    p_passive_wheels: float = 0.2
    type_weights: tuple[float, float, float] = (1.0, 1.0, 1.0)
    max_tries: int = 1000

    def __post_init__(self) -> None:
        at_least(self, 1, "max_depth", "max_tries")
        for key in ("p_empty", "p_passive_wheels"):
            value = getattr(self, key)
            if not 0.0 <= value <= 1.0:
                raise ValueError(f"{key} must be a probability in [0, 1], got {value}")
        if self.p_empty >= 1.0:
            raise ValueError("p_empty must be below 1, or no module is ever attached")
        if len(self.type_weights) != 3 or min(self.type_weights) < 0 or sum(self.type_weights) <= 0:
            raise ValueError(
                f"type_weights must be 3 non-negative odds (motor, pivot, main), got "
                f"{self.type_weights}"
            )


def free_faces(module_type: ModuleType, is_root: bool) -> tuple[int, ...]:
    """The faces a module of this type may give to non-wheel children."""
    if module_type is ModuleType.BRAIN:
        return tuple(f for f in range(6) if f != BUTTON_FACE)
    if module_type is ModuleType.PIVOT:
        return (DISTAL_FACE,)
    if module_type is ModuleType.MAIN:
        return tuple(f for f in range(6) if f != MATING_FACE or is_root)
    return ()


def _neighbour(cell: Cell, frame: IntMatrix, face: int) -> Cell:
    d = frame @ FACE_NORMALS[face]
    return (cell[0] + int(d[0]), cell[1] + int(d[1]), cell[2] + int(d[2]))


_WHEEL = Node(ModuleType.WHEEL)


class _Grower:
    """Grows random subtrees into the free cells of a lattice (collision-aware undo)."""

    def __init__(self, rng: np.random.Generator, params: GeneratorParams, occupied: set[Cell]):
        self.rng = rng
        self.params = params
        self.occupied = occupied
        weights = np.asarray(params.type_weights, dtype=float)
        self.type_p = weights / weights.sum()

    def wheel_pair(self, cell: Cell, frame: IntMatrix, faces: tuple[int, int]) -> list[Edge]:
        """Two wheels on ``faces`` if both cells are free, else none."""
        cells = [_neighbour(cell, frame, f) for f in faces]
        if any(c in self.occupied for c in cells):
            return []
        self.occupied.update(cells)
        return [Edge(f, 0, _WHEEL) for f in faces]

    def grow(self, kind: ModuleType, cell: Cell, frame: IntMatrix, depth: int) -> Node | None:
        """A random subtree rooted at a module of type ``kind`` already placed at ``cell``."""
        if kind is ModuleType.MOTOR:
            wheels = self.wheel_pair(cell, frame, MOTOR_WHEEL_FACES)
            return Node(kind, tuple(wheels)) if wheels else None
        children: list[Edge] = []
        faces = list(free_faces(kind, is_root=depth == 0))
        if kind is ModuleType.MAIN and self.rng.random() < self.params.p_passive_wheels:
            pair = MAIN_WHEEL_FACE_PAIRS[self.rng.integers(len(MAIN_WHEEL_FACE_PAIRS))]
            wheels = self.wheel_pair(cell, frame, pair)
            children.extend(wheels)
            if wheels:
                faces = [f for f in faces if f not in pair]
        if depth < self.params.max_depth:
            for face in faces:
                edge = self.attach(cell, frame, face, depth)
                if edge is not None:
                    children.append(edge)
        return Node(kind, tuple(children))

    def attach(self, cell: Cell, frame: IntMatrix, face: int, depth: int) -> Edge | None:
        """Maybe grow a random child on ``face``; undo it when it would self-collide."""
        if self.rng.random() < self.params.p_empty:
            return None
        target = _neighbour(cell, frame, face)
        if target in self.occupied:
            return None
        kind = BODY_TYPES[self.rng.choice(len(BODY_TYPES), p=self.type_p)]
        rotation = ROTATIONS[self.rng.integers(len(ROTATIONS))]
        self.occupied.add(target)
        node = self.grow(kind, target, frame @ child_frame(face, rotation), depth + 1)
        if node is None:
            self.occupied.discard(target)
            return None
        return Edge(face, rotation, node)


def random_robot(
    rng: np.random.Generator,
    params: GeneratorParams | None = None,
    limits: Limits | None = None,
) -> Robot:
    """A random valid robot grown from the brain as in the paper.

    Each free face gets a random module (motor, pivot or main) or, with probability
    ``p_empty``, nothing; a motor gets its wheel pair and ends its branch; an extension
    that would share a lattice cell with an existing module is undone. Robots without a
    motion module or over the size limits are drawn again.

    Raises:
        OperatorError: no valid robot in ``params.max_tries`` attempts.
    """
    params = params or GeneratorParams()
    limits = limits or Limits()
    for _ in range(params.max_tries):
        grower = _Grower(rng, params, {(0, 0, 0)})
        root = grower.grow(ModuleType.BRAIN, (0, 0, 0), np.eye(3, dtype=np.int64), 0)
        if root is not None and is_valid(root, limits):
            return Robot(root)
    raise OperatorError(
        f"no valid random robot in {params.max_tries} tries (max_depth={params.max_depth}, "
        f"p_empty={params.p_empty}); lower p_empty or raise the size limits"
    )


def random_robots(
    rng: np.random.Generator,
    count: int,
    params: GeneratorParams | None = None,
    limits: Limits | None = None,
) -> list[Robot]:
    """``count`` random robots of distinct structure (names), in the order drawn.

    Raises:
        ValueError: When ``100 * count`` draws give fewer distinct structures.
    """
    robots: dict[str, Robot] = {}
    for _ in range(100 * count):
        robot = random_robot(rng, params, limits)
        robots.setdefault(robot.name, robot)
        if len(robots) == count:
            return list(robots.values())
    raise ValueError(f"only {len(robots)} distinct robots at these settings, asked for {count}")


# --- tree surgery ------------------------------------------------------------------------


def subtree_at(root: Node, path: Path) -> Edge:
    """The edge that leads to the node at ``path`` (a non-empty path)."""
    node, edge = root, None
    for face in path:
        edge = node.child_on(face)
        if edge is None:
            raise KeyError(f"no child on face {face} along path {path}")
        node = edge.module
    if edge is None:
        raise KeyError("the root has no edge")
    return edge


def replace_node(root: Node, path: Path, node: Node) -> Node:
    """A copy of the tree with the module at ``path`` replaced, keeping its edge."""
    if not path:
        return node
    edge = subtree_at(root, path)
    return replace_at(root, path, Edge(edge.face, edge.rotation, node))


def replace_at(root: Node, path: Path, new: Edge | None) -> Node:
    """A copy of the tree with the edge at ``path`` replaced by ``new`` (None removes it)."""
    face, rest = path[0], path[1:]
    children = []
    for edge in root.children:
        if edge.face != face:
            children.append(edge)
        elif rest:
            children.append(Edge(edge.face, edge.rotation, replace_at(edge.module, rest, new)))
        elif new is not None:
            children.append(Edge(face, new.rotation, new.module))
    return Node(root.type, tuple(children))


# --- crossover ---------------------------------------------------------------------------


Origins = dict[Path, tuple[int, Path]]
"""Where the modules of a bred robot came from: a module's node path in the child ->
(which parent, 0 or 1, and its node path there). A module made new (by a mutation)
has no entry."""


@dataclass(frozen=True, slots=True)
class CrossoverResult:
    """The valid offspring of one subtree crossover and how it was reached.

    Attributes:
        offspring: The valid children (one or two), T1' first.
        cut: The node paths swapped in the first and second parent.
        tries: How many swaps were drawn before one gave a valid child.
        origins: For each child of ``offspring``, where each of its modules came from
            (parent 0 is the first parent, ``a``).
    """

    offspring: tuple[Robot, ...]
    cut: tuple[Path, Path]
    tries: int
    origins: tuple[Origins, ...] = ()


def crossover_origins(parents: tuple[Robot, Robot], host: int, cut: Path, graft: Path) -> Origins:
    """The origins of the child that keeps ``parents[host]``'s tree with its subtree at
    ``cut`` replaced by the other parent's subtree at ``graft``.

    Subtree surgery keeps every path: a module outside the cut keeps its host path, and
    the grafted module at ``cut + rest`` was at ``graft + rest`` in the other parent.
    """
    donor = 1 - host
    kept = replace_at(parents[host].root, cut, None)
    origins: Origins = {p.path: (host, p.path) for p in walk(kept)}
    for p in walk(subtree_at(parents[donor].root, graft).module):
        origins[cut + p.path] = (donor, graft + p.path)
    return origins


def surviving_origins(before: Robot, after: Robot, origins: Origins | None = None) -> Origins:
    """The origins of ``after``, a mutation of ``before`` whose modules had ``origins``
    (by default: ``before`` is parent 0 itself).

    No mutation operator moves a subtree (children are addressed by face), so a module
    survives a mutation when ``after`` has a module of the same type at the same path
    (a turned one too: it keeps its slots, its axle or hinge turned with it); one whose
    type changed, or one grown new, has no origin.
    """
    old = {p.path: p.node.type for p in walk(before.root)}
    base = origins if origins is not None else {path: (0, path) for path in old}
    return {p.path: base[p.path] for p in walk(after.root)
            if old.get(p.path) is p.node.type and p.path in base}


def crossover_sites(a: Robot, b: Robot) -> list[tuple[Path, Path]]:
    """Pairs of swappable nodes: neither root nor wheel, and their parents share a type."""

    def sites(robot: Robot) -> list[Placed]:
        return [
            p
            for p in walk(robot.root)
            if p.parent is not None and p.node.type is not ModuleType.WHEEL
        ]

    pairs = []
    for p1 in sites(a):
        for p2 in sites(b):
            assert p1.parent is not None and p2.parent is not None
            if p1.parent.node.type is p2.parent.node.type:
                pairs.append((p1.path, p2.path))
    return pairs


def crossover(
    a: Robot,
    b: Robot,
    rng: np.random.Generator,
    limits: Limits | None = None,
    max_tries: int = 100,
) -> CrossoverResult:
    """Subtree crossover (paper Fig. 5).

    Picks nodes n1 in ``a`` and n2 in ``b`` (neither the root nor a wheel, parents of the
    same type), swaps the subtrees (each keeps its own rotation, so a twisted part
    stays twisted) and keeps the valid children. When neither child is valid it starts
    again from a new pair.

    Raises:
        OperatorError: the parents have no compatible pair, or ``max_tries`` swaps gave
            no valid child.
    """
    pairs = crossover_sites(a, b)
    if not pairs:
        raise OperatorError(
            f"no crossover site between {a.name} and {b.name}: no non-root, non-wheel nodes "
            "whose parents share a type"
        )
    for tries in range(1, max_tries + 1):
        path1, path2 = pairs[rng.integers(len(pairs))]
        e1, e2 = subtree_at(a.root, path1), subtree_at(b.root, path2)
        children = (Robot(replace_at(a.root, path1, e2)), Robot(replace_at(b.root, path2, e1)))
        valid = [i for i, c in enumerate(children) if is_valid(c.root, limits)]
        if valid:
            cuts = ((path1, path2), (path2, path1))
            return CrossoverResult(
                tuple(children[i] for i in valid), (path1, path2), tries,
                tuple(crossover_origins((a, b), i, *cuts[i]) for i in valid))
    raise OperatorError(f"crossover of {a.name} and {b.name}: no valid child in {max_tries} tries")


# --- mutation (an extension, off in the paper configs) -----------------------------------


@dataclass(frozen=True, slots=True)
class Mutation:
    """A mutation operator: ``ga.mutation_operators`` names each one an offspring may get
    with ``_target_``. A subclass's ``__call__`` returns the changed robot (not yet
    checked for validity), or None when this robot offers it nothing to change."""

    def __call__(self, robot: Robot, rng: np.random.Generator,
                 params: GeneratorParams) -> Robot | None:
        raise NotImplementedError(f"{type(self).__name__} changes nothing")


@dataclass(frozen=True, slots=True)
class AddSubtree(Mutation):
    """Grow a random subtree on a free face of a random module."""

    def __call__(self, robot: Robot, rng: np.random.Generator,
                 params: GeneratorParams) -> Robot | None:
        placed = robot.modules()
        occupied = {p.cell for p in placed}
        options = [
            (p, face)
            for p in placed
            if p.node.type is not ModuleType.WHEEL
            for face in free_faces(p.node.type, p.parent is None)
            if p.node.child_on(face) is None
        ]
        if not options:
            return None
        host, face = options[rng.integers(len(options))]
        always = GeneratorParams(params.max_depth, 0.0, params.p_passive_wheels,
                                 params.type_weights)
        edge = _Grower(rng, always, occupied).attach(host.cell, host.frame, face, host.depth)
        if edge is None:
            return None
        return Robot(
            replace_node(robot.root, host.path, Node(host.node.type, host.node.children + (edge,)))
        )


@dataclass(frozen=True, slots=True)
class _ModuleMutation(Mutation):
    """A mutation of one non-root, non-wheel module, drawn uniformly (one draw, before any
    other); None when the robot has no such module."""

    def __call__(self, robot: Robot, rng: np.random.Generator,
                 params: GeneratorParams) -> Robot | None:
        options = [p for p in walk(robot.root)
                   if p.node.type is not ModuleType.WHEEL and p.parent is not None]
        if not options:
            return None
        return self.change(robot, options[rng.integers(len(options))], rng)

    def change(self, robot: Robot, target: Placed, rng: np.random.Generator) -> Robot:
        """``robot`` with ``target`` changed."""
        raise NotImplementedError(f"{type(self).__name__} changes nothing")


@dataclass(frozen=True, slots=True)
class RemoveSubtree(_ModuleMutation):
    """Remove a random non-root module with everything below it."""

    def change(self, robot: Robot, target: Placed, rng: np.random.Generator) -> Robot:
        return Robot(replace_at(robot.root, target.path, None))


@dataclass(frozen=True, slots=True)
class RotateEdge(_ModuleMutation):
    """Turn a random non-wheel module to another rotation about its connection axis."""

    def change(self, robot: Robot, target: Placed, rng: np.random.Generator) -> Robot:
        edge = subtree_at(robot.root, target.path)
        rotations = [r for r in ROTATIONS if r != edge.rotation]
        rotation = rotations[rng.integers(len(rotations))]
        return Robot(replace_at(robot.root, target.path, Edge(edge.face, rotation, edge.module)))


@dataclass(frozen=True, slots=True)
class ChangeType(_ModuleMutation):
    """Change a random non-root module into another body type, adapting its children.

    A new motor gets a fresh wheel pair instead of its children; a new pivot keeps only
    its face-0 child; a new main keeps every child (a motor's wheels become passive).
    """

    def change(self, robot: Robot, target: Placed, rng: np.random.Generator) -> Robot:
        kinds = [t for t in BODY_TYPES if t is not target.node.type]
        kind = kinds[rng.integers(len(kinds))]
        old = target.node.children
        if kind is ModuleType.MOTOR:
            children = tuple(Edge(f, 0, _WHEEL) for f in MOTOR_WHEEL_FACES)
        elif kind is ModuleType.PIVOT:
            children = tuple(e for e in old if e.face == DISTAL_FACE)
        else:
            children = old
        return Robot(replace_node(robot.root, target.path, Node(kind, children)))


MUTATIONS: dict[str, Mutation] = {
    "add_subtree": AddSubtree(),
    "remove_subtree": RemoveSubtree(),
    "rotate_edge": RotateEdge(),
    "change_type": ChangeType(),
}
"""Every mutation operator, by the name ``ga.mutation_operators`` may also give it
(the shorthand of older configs and the command line, :func:`evo.config.current`)."""


def mutate(
    robot: Robot,
    rng: np.random.Generator,
    operators: Sequence[Mutation] = tuple(MUTATIONS.values()),
    params: GeneratorParams | None = None,
    limits: Limits | None = None,
    max_tries: int = 100,
) -> Robot:
    """Apply one randomly chosen mutation operator, retrying until the result is valid.

    Raises:
        OperatorError: ``max_tries`` attempts gave no valid, changed robot.
        ValueError: no operators to choose from.
    """
    params = params or GeneratorParams()
    if not operators:
        raise ValueError(f"no mutation operators to choose from; expected some of "
                         f"{list(MUTATIONS)}")
    for _ in range(max_tries):
        op = operators[int(rng.integers(len(operators)))]
        child = op(robot, rng, params)
        if child is not None and child != robot and is_valid(child.root, limits):
            return child
    raise OperatorError(f"mutation of {robot.name}: no valid change in {max_tries} tries")
