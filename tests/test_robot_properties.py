"""Property tests of robot structures: generation, file round trip, hash, crossover, mutation.

Every random input comes from a seeded ``numpy.random.Generator`` whose seed hypothesis
draws, so a failing example is reproduced from its seed alone.
"""

from __future__ import annotations

import copy
import hashlib
import json
from collections import Counter
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from evo.robot import (
    FORMAT,
    Edge,
    GeneratorParams,
    Limits,
    ModuleType,
    Node,
    OperatorError,
    Robot,
    crossover,
    mutate,
    parse_robot,
    random_robot,
    violations,
)
from evo.robot.operators import MUTATIONS
from evo.robot.tree import FACE_AXES, FACE_NORMALS, child_frame

SEEDS = st.integers(min_value=0, max_value=2**32 - 1)
PARAMS = st.builds(
    GeneratorParams,
    max_depth=st.integers(min_value=1, max_value=4),
    p_empty=st.sampled_from([0.0, 0.2, 0.5, 0.8]),
    p_passive_wheels=st.sampled_from([0.0, 0.2, 1.0]),
)
Doc = dict[str, Any]
WHEEL: Doc = {"type": "wheel"}


def motor_doc(wheel_rotation: int = 0) -> Doc:
    wheels = [
        {"face": 3, "rotation": wheel_rotation, "module": WHEEL},
        {"face": 2, "module": WHEEL},
    ]
    return {"type": "motor", "children": wheels}


def robot_doc(*edges: Doc) -> Doc:
    return {"format": FORMAT, "root": {"type": "brain", "children": list(edges)}}


def rng_of(seed: int) -> np.random.Generator:
    return np.random.default_rng(seed)


def walk_doc(node: Doc, path: tuple[int, ...] = (), parent: str | None = None) -> Iterator[Any]:
    """(path, node dict, parent type) for every module of a JSON tree, independent of evo."""
    yield path, node, parent
    for edge in node.get("children", []):
        yield from walk_doc(edge["module"], path + (edge["face"],), node["type"])


def edge_doc(root: Doc, path: tuple[int, ...]) -> Doc:
    node: Doc = root
    edge: Doc | None = None
    for face in path:
        edge = next(e for e in node["children"] if e["face"] == face)
        node = edge["module"]
    assert edge is not None
    return edge


def swapped(root: Doc, path: tuple[int, ...], donor: Doc) -> Doc:
    """``root`` with the edge at ``path`` replaced by the edge ``donor`` (same face kept)."""
    out = copy.deepcopy(root)
    target = edge_doc(out, path)
    target["rotation"] = donor["rotation"]
    target["module"] = copy.deepcopy(donor["module"])
    return out


def cut_sites(root: Doc) -> list[tuple[tuple[int, ...], str]]:
    """Paths of crossover-eligible nodes (not the root, not a wheel) with their parent type."""
    return [
        (path, parent)
        for path, node, parent in walk_doc(root)
        if parent is not None and node["type"] != "wheel"
    ]


def node_of(doc: Doc) -> Node:
    """The tree of a JSON module, built without validation (invalid trees too)."""
    edges = (
        Edge(e["face"], e.get("rotation", 0), node_of(e["module"])) for e in doc.get("children", [])
    )
    return Node(ModuleType(doc["type"]), tuple(edges))


def shuffled(node: Doc, rng: np.random.Generator) -> Doc:
    """The same structure written differently: children reordered, default keys dropped,
    wheel rotations (which have no effect) set at random."""
    out: Doc = {"type": node["type"]}
    edges = []
    for edge in node.get("children", []):
        child = shuffled(edge["module"], rng)
        raw: Doc = {"module": child, "face": edge["face"]}
        if child["type"] == "wheel":
            raw["rotation"] = int(rng.choice([0, 90, 180, 270]))
        elif edge["rotation"] != 0 or rng.random() < 0.5:
            raw["rotation"] = edge["rotation"]
        edges.append(raw)
    if edges or rng.random() < 0.5:
        out["children"] = [edges[i] for i in rng.permutation(len(edges))]
    return out


# --- frames and lattice (SPEC section 1 table) ---------------------------------------------


def test_face_frames_match_the_spec_table() -> None:
    # Columns: the child's x, y, z in the parent frame, copied from SPEC section 1.
    spec = {
        0: ((1, 0, 0), (0, 1, 0), (0, 0, 1)),
        1: ((-1, 0, 0), (0, -1, 0), (0, 0, 1)),
        2: ((0, 1, 0), (-1, 0, 0), (0, 0, 1)),
        3: ((0, -1, 0), (1, 0, 0), (0, 0, 1)),
        4: ((0, 0, 1), (0, 1, 0), (-1, 0, 0)),
        5: ((0, 0, -1), (0, 1, 0), (1, 0, 0)),
    }
    for face, (x, y, z) in spec.items():
        frame = child_frame(face, 0)
        assert frame[:, 0].tolist() == list(x), f"face {face}: child x"
        assert frame[:, 1].tolist() == list(y), f"face {face}: child y"
        assert frame[:, 2].tolist() == list(z), f"face {face}: child z"
        # The child grows along its own +x, which is the face normal.
        assert FACE_AXES[face][:, 0].tolist() == FACE_NORMALS[face].tolist()
        for rotation in (90, 180, 270):
            turned = child_frame(face, rotation)
            assert turned[:, 0].tolist() == list(x), "rotation keeps the connection axis"
            assert round(float(np.linalg.det(turned))) == 1, "frames stay right-handed"
    # Rotation 90 about the child's x turns its y onto the old z, its z onto the old -y.
    assert child_frame(0, 90)[:, 1].tolist() == [0, 0, 1]
    assert child_frame(0, 90)[:, 2].tolist() == [0, -1, 0]


def test_cells_follow_face_normals_of_the_parent_frame() -> None:
    twisted = {"face": 0, "rotation": 90, "module": motor_doc()}
    doc = robot_doc({"face": 2, "module": {"type": "main", "children": [twisted]}})
    cells = {p.path: p.cell for p in parse_robot(doc).modules()}
    # The main sits at +y; its own +x is the brain's +y, so the motor is one further.
    assert cells[(2,)] == (0, 1, 0)
    assert cells[(2, 0)] == (0, 2, 0)
    # Turned 90 about +y, the motor's own y points along the brain's -z (its axle is vertical).
    assert {cells[(2, 0, 2)], cells[(2, 0, 3)]} == {(0, 2, 1), (0, 2, -1)}


# --- generation -------------------------------------------------------------------------


@settings(max_examples=150, deadline=None)
@given(seed=SEEDS, params=PARAMS)
def test_random_robots_are_valid(seed: int, params: GeneratorParams) -> None:
    robot = random_robot(rng_of(seed), params)
    assert violations(robot.root) == [], robot.to_json()
    assert robot.root.type is ModuleType.BRAIN
    assert robot.n_motors + robot.n_pivots >= 1, "a robot needs a motion module"
    assert robot.depth <= params.max_depth
    # Every motor carries exactly its wheel pair; wheels never appear elsewhere alone.
    assert robot.count(ModuleType.WHEEL) % 2 == 0
    cells = [p.cell for p in robot.modules()]
    assert len(cells) == len(set(cells)), "two modules share a lattice cell"


@settings(max_examples=30, deadline=None)
@given(seed=SEEDS)
def test_same_seed_same_robots(seed: int) -> None:
    a = [random_robot(rng_of(seed)) for _ in range(5)]
    b = [random_robot(rng_of(seed)) for _ in range(5)]
    assert a == b


def test_random_robots_vary_in_size_and_use_every_module_type() -> None:
    rng = rng_of(11)
    robots = [random_robot(rng) for _ in range(300)]
    sizes = Counter(len(r) for r in robots)
    assert len(sizes) >= 10, f"sizes hardly vary: {sizes}"
    for kind in ModuleType:
        assert any(r.count(kind) for r in robots), f"no {kind.value} in 300 robots"
    rotations = {e.rotation for r in robots for p in r.modules() for e in p.node.children}
    assert rotations == {0, 90, 180, 270}


def test_generator_respects_tight_limits() -> None:
    limits = Limits(max_depth=2, max_modules=8)
    rng = rng_of(5)
    for _ in range(100):
        robot = random_robot(rng, GeneratorParams(max_depth=4, p_empty=0.3), limits)
        assert len(robot) <= 8 and robot.depth <= 2


def test_generator_gives_up_with_a_clear_error() -> None:
    # Four modules are too few for a brain with its motion module and anything more,
    # and p_empty=0 forces every face to be filled: no robot fits.
    params = GeneratorParams(max_depth=2, p_empty=0.0, max_tries=20)
    with pytest.raises(OperatorError, match="no valid random robot in 20 tries"):
        random_robot(rng_of(0), params, Limits(max_depth=2, max_modules=4))


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"p_empty": 1.0}, "p_empty must be below 1"),
        ({"p_empty": -0.1}, "p_empty must be a probability"),
        ({"p_passive_wheels": 1.5}, "p_passive_wheels must be a probability"),
        ({"max_depth": 0}, "max_depth must be >= 1"),
        ({"type_weights": (0.0, 0.0, 0.0)}, "type_weights must be 3 non-negative odds"),
    ],
)
def test_generator_params_reject_bad_values(kwargs: dict[str, Any], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        GeneratorParams(**kwargs)


# --- file round trip and hash -----------------------------------------------------------


@settings(max_examples=100, deadline=None)
@given(seed=SEEDS, params=PARAMS)
def test_json_round_trip_is_identity(seed: int, params: GeneratorParams) -> None:
    robot = random_robot(rng_of(seed), params)
    text = robot.to_json()
    back = parse_robot(json.loads(text))
    assert back == robot
    assert back.to_json() == text
    assert back.hash == robot.hash
    assert json.loads(text)["format"] == FORMAT


@settings(max_examples=100, deadline=None)
@given(seed=SEEDS, order_seed=SEEDS)
def test_hash_ignores_the_order_children_are_written_in(seed: int, order_seed: int) -> None:
    robot = random_robot(rng_of(seed))
    doc = {"root": shuffled(robot.to_dict()["root"], rng_of(order_seed)), "format": FORMAT}
    again = parse_robot(json.loads(json.dumps(doc)))
    assert again == robot
    assert again.hash == robot.hash
    assert again.name == robot.name == f"robot-{robot.hash[:8]}"


@settings(max_examples=100, deadline=None)
@given(seed=SEEDS)
def test_hash_changes_when_the_structure_changes(seed: int) -> None:
    rng = rng_of(seed)
    robot = random_robot(rng)
    changed = mutate(robot, rng)
    assert changed.canonical_json() != robot.canonical_json()
    assert changed.hash != robot.hash
    # A single non-wheel rotation is a different structure too.
    doc = robot.to_dict()
    edge = edge_doc(doc["root"], cut_sites(doc["root"])[0][0])
    edge["rotation"] = (edge["rotation"] + 90) % 360
    assert Robot(node_of(doc["root"])).hash != robot.hash


def test_hash_is_sha256_of_the_canonical_json() -> None:
    # Written out of order, with a wheel rotation and a default left out.
    doc = robot_doc({"face": 0, "module": motor_doc(wheel_rotation=90)})
    canonical = (
        '{"format":"evo.robot/1","root":{"children":[{"face":0,"module":{"children":['
        '{"face":2,"module":{"type":"wheel"},"rotation":0},'
        '{"face":3,"module":{"type":"wheel"},"rotation":0}],"type":"motor"},"rotation":0}],'
        '"type":"brain"}}'
    )
    robot = parse_robot(doc)
    assert robot.canonical_json() == canonical
    assert robot.hash == hashlib.sha256(canonical.encode()).hexdigest()


def test_distinct_structures_have_distinct_hashes() -> None:
    rng = rng_of(3)
    robots = [random_robot(rng) for _ in range(1000)]
    by_hash: dict[str, str] = {}
    for robot in robots:
        seen = by_hash.setdefault(robot.hash, robot.canonical_json())
        assert seen == robot.canonical_json(), "two structures share a hash"
    assert len(set(robots)) == len(by_hash), "set membership disagrees with the hash"


# --- crossover --------------------------------------------------------------------------


@settings(max_examples=120, deadline=None)
@given(seed=SEEDS, params=PARAMS)
def test_crossover_offspring_are_valid_swaps_of_parent_subtrees(
    seed: int, params: GeneratorParams
) -> None:
    rng = rng_of(seed)
    a, b = random_robot(rng, params), random_robot(rng, params)
    a_json, b_json = a.to_json(), b.to_json()
    result = crossover(a, b, rng)
    assert a.to_json() == a_json and b.to_json() == b_json, "crossover changed a parent"
    assert 1 <= len(result.offspring) <= 2 and result.tries >= 1
    for child in result.offspring:
        assert violations(child.root) == [], child.to_json()

    ra, rb = a.to_dict()["root"], b.to_dict()["root"]
    # Every possible single swap, computed on the JSON trees without evo's surgery.
    possible = []
    for p1, t1 in cut_sites(ra):
        for p2, t2 in cut_sites(rb):
            if t1 == t2:
                possible.append(swapped(ra, p1, edge_doc(rb, p2)))
                possible.append(swapped(rb, p2, edge_doc(ra, p1)))
    for child in result.offspring:
        assert child.to_dict()["root"] in possible, "offspring is not one swap of the parents"

    # The reported cut is the swap that made them: the valid ones of T1', T2', in order.
    path1, path2 = result.cut
    sites_a, sites_b = dict(cut_sites(ra)), dict(cut_sites(rb))
    assert path1 in sites_a and path2 in sites_b, "cut at the root or at a wheel"
    assert sites_a[path1] == sites_b[path2], "cut nodes' parents differ in type"
    pair = [swapped(ra, path1, edge_doc(rb, path2)), swapped(rb, path2, edge_doc(ra, path1))]
    expected = [d for d in pair if not violations(node_of(d))]
    assert [c.to_dict()["root"] for c in result.offspring] == expected


@settings(max_examples=30, deadline=None)
@given(seed=SEEDS)
def test_crossover_is_reproducible(seed: int) -> None:
    a, b = random_robot(rng_of(seed)), random_robot(rng_of(seed + 1))
    assert crossover(a, b, rng_of(seed)) == crossover(a, b, rng_of(seed))


def test_crossover_gives_up_when_no_swap_is_valid() -> None:
    # Under a depth limit of 1 every swap keeps a depth-2 pivot, so no child is valid.
    pivot = {"type": "pivot", "children": [{"face": 0, "module": {"type": "pivot"}}]}
    chain = parse_robot(robot_doc({"face": 0, "module": pivot}))
    with pytest.raises(OperatorError, match="no valid child in 7 tries"):
        crossover(chain, chain, rng_of(0), limits=Limits(max_depth=1), max_tries=7)


def test_crossover_mostly_succeeds_on_the_first_try() -> None:
    rng = rng_of(2)
    tries = [crossover(random_robot(rng), random_robot(rng), rng).tries for _ in range(200)]
    assert np.mean(np.array(tries) == 1) > 0.9, Counter(tries)


# --- mutation ---------------------------------------------------------------------------


@settings(max_examples=120, deadline=None)
@given(seed=SEEDS, params=PARAMS)
def test_mutation_keeps_validity_and_changes_the_robot(seed: int, params: GeneratorParams) -> None:
    rng = rng_of(seed)
    robot = random_robot(rng, params)
    before = robot.to_json()
    child = mutate(robot, rng, params=params)
    assert robot.to_json() == before, "mutation changed its input"
    assert child != robot
    assert violations(child.root) == [], child.to_json()


def test_each_mutation_operator_does_what_its_name_says() -> None:
    rng = rng_of(8)
    done = Counter[str]()
    for _ in range(60):
        robot = random_robot(rng)
        types = Counter(p.node.type for p in robot.modules())
        for op in MUTATIONS:
            try:
                child = mutate(robot, rng, operators=(MUTATIONS[op],), max_tries=30)
            except OperatorError:
                continue  # e.g. nothing can be removed from a one-motor robot
            done[op] += 1
            assert violations(child.root) == [] and child != robot
            child_types = Counter(p.node.type for p in child.modules())
            if op == "add_subtree":
                assert len(child) > len(robot)
            elif op == "remove_subtree":
                assert len(child) < len(robot)
            elif op == "rotate_edge":
                assert child_types == types, "rotating an edge changed the modules"
            elif op == "change_type":
                assert child_types != types
    assert all(done[op] >= 20 for op in MUTATIONS), done


def test_mutate_needs_an_operator() -> None:
    robot = random_robot(rng_of(0))
    with pytest.raises(ValueError, match="no mutation operators"):
        mutate(robot, rng_of(0), operators=())
