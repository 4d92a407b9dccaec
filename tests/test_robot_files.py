"""Bad robot files: one test per kind of mistake, each checking the message a user sees.

Every error must name the file and say what is wrong; structural problems come with the
path of the node they are about, and validation lists every problem, not just the first.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from evo.robot import (
    FORMAT,
    InvalidRobotError,
    Limits,
    RobotFileError,
    Violation,
    load_robot,
    parse_robot,
    save_robot,
)

REPO = Path(__file__).resolve().parents[1]
Doc = dict[str, Any]
WHEEL: Doc = {"type": "wheel"}


def motor() -> Doc:
    return {
        "type": "motor",
        "children": [{"face": 2, "module": WHEEL}, {"face": 3, "module": WHEEL}],
    }


def edge(face: Any, module: Doc, rotation: Any = 0) -> Doc:
    return {"face": face, "rotation": rotation, "module": module}


def brain(*edges: Doc) -> Doc:
    return {"type": "brain", "children": list(edges)}


def write(tmp_path: Path, content: Any, name: str = "robot.json") -> Path:
    path = tmp_path / name
    text = content if isinstance(content, str) else json.dumps(content)
    path.write_text(text, encoding="utf-8")
    return path


def robot_file(tmp_path: Path, root: Doc) -> Path:
    return write(tmp_path, {"format": FORMAT, "root": root})


def load_error(path: Path, limits: Limits | None = None) -> InvalidRobotError:
    """Load ``path`` expecting an invalid robot; check the message names the file."""
    with pytest.raises(InvalidRobotError) as info:
        load_robot(path, limits)
    err = info.value
    assert err.source == str(path)
    assert str(err).startswith(f"{path} is not a valid robot"), str(err)
    for v in err.violations:
        assert f"  - {v}" in str(err), f"violation {v} missing from the message"
    return err


def invalid(path: Path, limits: Limits | None = None) -> list[Violation]:
    """The violations of an invalid robot file."""
    return load_error(path, limits).violations


def only(found: list[Violation]) -> Violation:
    assert len(found) == 1, f"expected one problem, got {[str(v) for v in found]}"
    return found[0]


# --- the file itself --------------------------------------------------------------------


def test_example_robots_load(tmp_path: Path) -> None:
    files = sorted((REPO / "robots").glob("*.json"))
    assert files, "no example robots in robots/"
    for path in files:
        robot = load_robot(path)
        again = load_robot(save_robot(robot, tmp_path / path.name))
        assert again == robot


def test_unreadable_file(tmp_path: Path) -> None:
    missing = tmp_path / "nowhere" / "robot.json"
    with pytest.raises(RobotFileError, match="cannot read file") as info:
        load_robot(missing)
    assert str(missing) in str(info.value)
    with pytest.raises(RobotFileError, match="cannot read file"):
        load_robot(tmp_path)  # a directory
    binary = tmp_path / "binary.json"
    binary.write_bytes(b"\xff\xfe\x00garbage")
    with pytest.raises(RobotFileError, match="cannot read file") as info:
        load_robot(binary)
    assert str(binary) in str(info.value)


def test_broken_json(tmp_path: Path) -> None:
    path = write(tmp_path, '{"format": "evo.robot/1", "root": {"type": "brain",')
    with pytest.raises(RobotFileError, match="not valid JSON") as info:
        load_robot(path)
    assert str(info.value).startswith(f"{path}: ")
    assert "line 1" in info.value.reason, "the reason should say where the JSON breaks"


def test_absurdly_nested_json(tmp_path: Path) -> None:
    path = write(tmp_path, "[" * 100_000 + "]" * 100_000)
    with pytest.raises(RobotFileError, match="nested too deeply") as info:
        load_robot(path)
    assert str(path) in str(info.value)


@pytest.mark.parametrize(("content", "kind"), [([1, 2], "list"), ('"robot"', "str"), ("3", "int")])
def test_wrong_top_level_type(tmp_path: Path, content: Any, kind: str) -> None:
    path = write(tmp_path, content if isinstance(content, str) else json.dumps(content))
    with pytest.raises(RobotFileError, match=f"expected a JSON object at the top, got {kind}"):
        load_robot(path)


def test_missing_format(tmp_path: Path) -> None:
    path = write(tmp_path, {"root": brain(edge(0, motor()))})
    with pytest.raises(RobotFileError, match="missing 'format' key") as info:
        load_robot(path)
    assert str(path) in str(info.value) and FORMAT in str(info.value)


def test_unknown_format(tmp_path: Path) -> None:
    path = write(tmp_path, {"format": "evo.robot/9", "root": brain(edge(0, motor()))})
    with pytest.raises(RobotFileError, match=r"unknown format 'evo.robot/9'") as info:
        load_robot(path)
    assert str(path) in str(info.value)


def test_missing_root(tmp_path: Path) -> None:
    v = only(invalid(write(tmp_path, {"format": FORMAT})))
    assert v.path == "root" and "missing 'root'" in v.message


# --- module and edge fields -------------------------------------------------------------


def test_unknown_module_type(tmp_path: Path) -> None:
    path = robot_file(tmp_path, brain(edge(0, motor()), edge(2, {"type": "laser"})))
    v = only(invalid(path))
    assert v.path == "root/2"
    assert "unknown module type 'laser'" in v.message
    assert "brain, motor, pivot, main, wheel" in v.message


def test_unknown_keys_in_a_module_or_child(tmp_path: Path) -> None:
    root = brain({"face": 0, "module": motor(), "angle": 3})
    root["colour"] = "red"
    found = invalid(robot_file(tmp_path, root))
    messages = " | ".join(v.message for v in found)
    assert "unknown key 'colour'" in messages and "unknown key 'angle'" in messages


@pytest.mark.parametrize("face", [6, -1, "0", 0.0, True, None, [0]])
def test_face_out_of_range_or_of_the_wrong_type(tmp_path: Path, face: Any) -> None:
    v = only(invalid(robot_file(tmp_path, brain(edge(0, motor()), edge(face, motor())))))
    assert v.path == "root/children[1]"
    assert v.message == f"'face' must be an integer 0..5, got {face!r}"


@pytest.mark.parametrize("rotation", [45, 360, -90, "90", 90.0, True, None])
def test_rotation_out_of_range_or_of_the_wrong_type(tmp_path: Path, rotation: Any) -> None:
    v = only(invalid(robot_file(tmp_path, brain(edge(0, motor(), rotation=rotation)))))
    assert v.path == "root/children[0]"
    assert v.message == f"'rotation' must be one of 0, 90, 180, 270, got {rotation!r}"


def test_rotation_may_be_left_out(tmp_path: Path) -> None:
    robot = load_robot(robot_file(tmp_path, brain({"face": 0, "module": motor()})))
    assert robot.root.children[0].rotation == 0


def test_children_must_be_a_list_of_objects(tmp_path: Path) -> None:
    found = invalid(robot_file(tmp_path, {"type": "brain", "children": {"face": 0}}))
    assert "'children' must be a list, got dict" in only(found).message
    found = invalid(robot_file(tmp_path, {"type": "brain", "children": [edge(0, motor()), 7]}))
    assert "a child must be a JSON object, got int" in only(found).message


# --- structural rules -------------------------------------------------------------------


def test_duplicate_face(tmp_path: Path) -> None:
    found = invalid(robot_file(tmp_path, brain(edge(0, motor()), edge(0, {"type": "main"}))))
    assert any(
        v.path == "root" and "2 children on face 0; a face holds at most one" in v.message
        for v in found
    ), found


def test_child_on_the_mating_face(tmp_path: Path) -> None:
    root = brain(edge(0, motor()), edge(2, {"type": "main", "children": [edge(1, motor())]}))
    first, *rest = invalid(robot_file(tmp_path, root))
    assert first.path == "root/2:main" and "child on the mating face 1 (-x)" in first.message
    # The child folds back onto the brain's cell, so it collides as well.
    assert rest and all("self-collision" in v.message for v in rest), rest


def test_child_on_the_brains_button_face(tmp_path: Path) -> None:
    v = only(invalid(robot_file(tmp_path, brain(edge(4, motor())))))
    assert v.path == "root" and "child on the brain's button face 4 (+z)" in v.message


def test_single_wheel(tmp_path: Path) -> None:
    main = {"type": "main", "children": [edge(2, WHEEL)]}
    v = only(invalid(robot_file(tmp_path, brain(edge(0, motor()), edge(2, main)))))
    assert v.path == "root/2:main" and "single wheel on face 2; wheels come in pairs" in v.message


def test_motor_with_a_single_wheel(tmp_path: Path) -> None:
    lonely = {"type": "motor", "children": [edge(2, WHEEL)]}
    v = only(invalid(robot_file(tmp_path, brain(edge(0, lonely)))))
    assert v.path == "root/0:motor"
    assert "motor needs exactly one wheel pair on faces 2 and 3, has wheels on [2]" in v.message


def test_wheel_under_a_pivot(tmp_path: Path) -> None:
    pivot = {"type": "pivot", "children": [edge(0, WHEEL)]}
    v = only(invalid(robot_file(tmp_path, brain(edge(0, pivot)))))
    assert v.path == "root/0:pivot" and "wheel under a pivot" in v.message


def test_wheel_under_the_brain(tmp_path: Path) -> None:
    v = only(invalid(robot_file(tmp_path, brain(edge(0, motor()), edge(2, WHEEL), edge(3, WHEEL)))))
    assert v.path == "root" and "wheel under the brain" in v.message


def test_wheel_pair_on_faces_that_are_not_opposite(tmp_path: Path) -> None:
    main = {"type": "main", "children": [edge(2, WHEEL), edge(4, WHEEL)]}
    v = only(invalid(robot_file(tmp_path, brain(edge(0, motor()), edge(1, main)))))
    assert v.path == "root/1:main"
    assert "wheels on faces [2, 4]; a main carries one pair, on faces 2+3 or 4+5" in v.message


def test_motor_wheels_off_their_faces(tmp_path: Path) -> None:
    wrong = {"type": "motor", "children": [edge(4, WHEEL), edge(5, WHEEL)]}
    v = only(invalid(robot_file(tmp_path, brain(edge(0, wrong)))))
    assert v.path == "root/0:motor" and "has wheels on [4, 5]" in v.message


def test_motor_with_a_non_wheel_child(tmp_path: Path) -> None:
    busy = motor()
    busy["children"].append(edge(0, {"type": "main"}))
    v = only(invalid(robot_file(tmp_path, brain(edge(0, busy)))))
    assert v.path == "root/0:motor" and "motor with a non-wheel child" in v.message


def test_pivot_child_off_face_0(tmp_path: Path) -> None:
    pivot = {"type": "pivot", "children": [edge(2, motor())]}
    v = only(invalid(robot_file(tmp_path, brain(edge(0, pivot)))))
    assert v.path == "root/0:pivot" and "pivot child off face 0" in v.message


def test_two_brains(tmp_path: Path) -> None:
    v = only(invalid(robot_file(tmp_path, brain(edge(0, motor()), edge(2, brain())))))
    assert v.path == "root/2:brain" and "a second brain" in v.message


def test_root_that_is_not_a_brain(tmp_path: Path) -> None:
    found = invalid(robot_file(tmp_path, motor()))
    assert any(
        v.path == "root" and "the root must be a brain, not a motor" in v.message for v in found
    ), found


def test_no_motion_module(tmp_path: Path) -> None:
    v = only(invalid(robot_file(tmp_path, brain(edge(0, {"type": "main"})))))
    assert v.path == "root" and "no motion module" in v.message


def test_self_collision(tmp_path: Path) -> None:
    # The main at +y turns its -y face toward +x, onto the cell of the motor's wheel.
    root = brain(
        edge(0, motor()), edge(2, {"type": "main", "children": [edge(3, {"type": "main"})]})
    )
    v = only(invalid(robot_file(tmp_path, root)))
    assert v.path == "root/2:main/3:main"
    assert "self-collision: shares cell (1, 1, 0) with root/0:motor/2:wheel" in v.message


def pivot_chain(length: int) -> Doc:
    node: Doc = {"type": "pivot"}
    for _ in range(length - 1):
        node = {"type": "pivot", "children": [edge(0, node)]}
    return brain(edge(0, node))


def test_over_the_depth_limit(tmp_path: Path) -> None:
    path = robot_file(tmp_path, pivot_chain(7))
    v = only(invalid(path))
    assert v.path.startswith("root/0:pivot/0:pivot") and "deeper than the limit of 6" in v.message
    assert load_robot(path, Limits(max_depth=7)).depth == 7
    v = only(invalid(robot_file(tmp_path, pivot_chain(3)), Limits(max_depth=2)))
    assert "deeper than the limit of 2" in v.message


def test_over_the_module_limit(tmp_path: Path) -> None:
    mains = (edge(f, {"type": "main"}) for f in (2, 3, 5))
    path = robot_file(tmp_path, brain(edge(0, motor()), edge(1, motor()), *mains))
    assert len(load_robot(path)) == 10
    v = only(invalid(path, Limits(max_modules=9)))
    assert v.path == "root" and "10 modules, over the limit of 9" in v.message


def test_a_200_deep_chain_fails_fast(tmp_path: Path) -> None:
    """Validation walks one level below the depth limit and no further: in a 200-deep
    chain whose every pivot from depth 10 on also carries a wheel (faults of its own), it
    finds the depth alone, having checked 8 modules, not 200."""
    node: Doc = {"type": "pivot"}
    for depth in range(199, 0, -1):
        wheel = [edge(1, WHEEL)] if depth >= 10 else []
        node = {"type": "pivot", "children": [edge(0, node), *wheel]}
    found = invalid(robot_file(tmp_path, brain(edge(0, node))))
    assert len(found) == 1 and "deeper than the limit of 6" in found[0].message, found[:3]
    # With the limit lifted, the iterative checks handle the chain without recursing.
    deep = {"format": FORMAT, "root": pivot_chain(200)}
    assert parse_robot(deep, limits=Limits(max_depth=300, max_modules=300)).depth == 200


def test_validation_reports_every_violation(tmp_path: Path) -> None:
    root = brain(
        edge(4, motor()),
        edge(0, {"type": "main", "children": [edge(2, WHEEL)]}),
        edge(1, {"type": "pivot", "children": [edge(2, {"type": "main"})]}),
    )
    err = load_error(robot_file(tmp_path, root))
    assert [(v.path, v.message.split(";")[0]) for v in err.violations] == [
        ("root", "child on the brain's button face 4 (+z)"),
        ("root/0:main", "single wheel on face 2"),
        ("root/1:pivot", "pivot child off face 0"),
    ]
    assert "(3 problems)" in str(err)
    one = load_error(robot_file(tmp_path, brain(edge(4, motor()))))
    assert "(1 problem)" in str(one)


def test_format_errors_are_all_reported_too(tmp_path: Path) -> None:
    root = brain(edge(9, motor()), edge(0, motor(), rotation=45), edge(2, {"type": "tank"}))
    found = invalid(robot_file(tmp_path, root))
    assert [v.path for v in found] == ["root/children[0]", "root/children[1]", "root/2"]
