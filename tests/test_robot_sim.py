"""Random robots in MuJoCo: they compile, rest on the floor, and their actuators work.

Measured facts the thresholds rest on: about 0.5-1.3% of random robots are still
tipping at 2 s (balanced on an edge, falling from numerical noise); about 15% of
pivots cannot reach 60 degrees because their own modules block them.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from functools import cache
from pathlib import Path

import mujoco
import numpy as np
import pytest

from evo.robot import GeneratorParams, Robot, load_robot, random_robot
from evo.robot.builder import BuiltRobot, PhysicsParams, build

REPO = Path(__file__).resolve().parents[1]
SETTLE_ROBOTS = 400
ACTUATED_ROBOTS = 80


@cache
def robots(seed: int, count: int) -> tuple[Robot, ...]:
    rng = np.random.default_rng(seed)
    return tuple(random_robot(rng) for _ in range(count))


def warnings(data: mujoco.MjData) -> dict[str, int]:
    """MuJoCo warnings raised so far, by name."""
    return {
        mujoco.mjtWarning(i).name: int(data.warning[i].number)
        for i in range(len(data.warning))
        if data.warning[i].number
    }


def step(model: mujoco.MjModel, data: mujoco.MjData, seconds: float) -> None:
    for _ in range(round(seconds / model.opt.timestep)):
        mujoco.mj_step(model, data)


def no_scene(root: ET.Element) -> None:
    """No floor: the robot hangs in empty space."""


def fixed_in_space(robot: Robot) -> tuple[BuiltRobot, mujoco.MjModel]:
    """The robot with its brain welded in place, no floor and no gravity."""
    built = build(robot, scene=no_scene, free=False)
    model = built.compile()
    model.opt.gravity[:] = 0.0
    return built, model


def subtree(model: mujoco.MjModel, body: int) -> set[int]:
    """``body`` and every body below it."""
    return {b for b in range(model.nbody) if any(a == body for a in ancestors(model, b))}


def ancestors(model: mujoco.MjModel, body: int) -> list[int]:
    out = [body]
    while body > 0:
        body = int(model.body_parentid[body])
        out.append(body)
    return out


def touching(model: mujoco.MjModel, data: mujoco.MjData, moving: set[int]) -> bool:
    """Whether a body in ``moving`` is in contact with a body outside it."""
    for i in range(data.ncon):
        b1 = int(model.geom_bodyid[data.contact[i].geom1])
        b2 = int(model.geom_bodyid[data.contact[i].geom2])
        if (b1 in moving) != (b2 in moving):
            return True
    return False


# --- on the floor -------------------------------------------------------------------------


def test_random_robots_compile_and_come_to_rest_on_the_floor() -> None:
    at_rest, still_moving = 0, []
    for robot in robots(0, SETTLE_ROBOTS):
        model = build(robot).compile()
        assert model.nu == robot.n_motors + robot.n_pivots, robot.name
        data = mujoco.MjData(model)
        mujoco.mj_forward(model, data)
        # Dropped from just above the floor: nothing touches anything at the start.
        assert data.ncon == 0, f"{robot.name} starts in contact: {robot.to_json(indent=None)}"
        step(model, data, 2.0)
        state = np.concatenate([data.qpos, data.qvel, data.qacc])
        assert np.all(np.isfinite(state)), f"{robot.name} blew up"
        assert warnings(data) == {}, f"{robot.name}: {warnings(data)}"
        assert data.xpos[1:, 2].min() > 0.0, f"{robot.name} sank through the floor"
        linear = np.linalg.norm(data.sensor("brain_linvel").data)
        angular = np.linalg.norm(data.sensor("brain_angvel").data)
        if linear < 0.02 and angular < 0.2:
            at_rest += 1
        else:
            still_moving.append((robot.name, round(float(linear), 3), round(float(angular), 3)))
    share = at_rest / SETTLE_ROBOTS
    assert share >= 0.97, f"only {share:.1%} at rest after 2 s; moving: {still_moving}"


def test_robots_start_just_above_the_floor() -> None:
    for robot in robots(1, 200):
        built = build(robot, clearance=0.005)
        model = built.compile()
        data = mujoco.MjData(model)
        mujoco.mj_forward(model, data)
        floor = model.geom("floor").id
        gaps = []
        for g in range(model.ngeom):
            if g == floor:
                continue
            dist = mujoco.mj_geomDistance(model, data, floor, g, 0.1, None)
            gaps.append(dist)
        assert min(gaps) == pytest.approx(0.005, abs=1e-6), robot.name


def test_the_four_wheeler_drives_forward() -> None:
    built = build(load_robot(REPO / "robots" / "four_wheeler.json"))
    model = built.compile()
    data = mujoco.MjData(model)
    step(model, data, 0.5)  # land first
    start = data.body("brain").xpos.copy()
    for name in built.motors:
        data.actuator(name).ctrl = model.actuator(name).ctrlrange[1]  # command +1
    step(model, data, 2.0)
    moved = data.body("brain").xpos - start
    assert moved[0] > 0.4, f"moved {moved} in 2 s at full speed"
    assert abs(moved[1]) < 0.25 * moved[0], f"veered off: {moved}"
    # Reversing the motors drives it back.
    for name in built.motors:
        data.actuator(name).ctrl = model.actuator(name).ctrlrange[0]
    back_from = data.body("brain").xpos.copy()
    step(model, data, 2.0)
    assert data.body("brain").xpos[0] < back_from[0] - 0.4


# --- actuators ----------------------------------------------------------------------------


def test_actuators_are_the_motors_then_the_pivots() -> None:
    for robot in robots(2, 200):
        built = build(robot)
        model = built.compile()
        m, n = robot.n_motors, robot.n_pivots
        assert model.nu == m + n == robot.n_actuators, robot.name
        assert len(built.motors) == m and len(built.pivots) == n
        names = [model.actuator(i).name for i in range(model.nu)]
        assert names == list(built.actuators), "actuator order differs from the action order"
        for name in built.motors:
            assert model.sensor(f"{name}_speed").dim[0] == 1
        for name in built.pivots:
            assert model.sensor(f"{name}_angle").dim[0] == 1
        assert len(built.bodies) == len(robot)


@pytest.mark.parametrize("command", [0.5, -1.0])
def test_a_motor_command_turns_its_wheels(command: float) -> None:
    count = 0
    for robot in robots(3, ACTUATED_ROBOTS):
        built, model = fixed_in_space(robot)
        for name in built.motors:
            data = mujoco.MjData(model)
            actuator = model.actuator(name)
            target = command * actuator.ctrlrange[1]
            data.ctrl[actuator.id] = target
            step(model, data, 0.5)
            speed = float(data.sensor(f"{name}_speed").data[0])
            assert speed == pytest.approx(target, rel=0.02), f"{robot.name} {name}: {speed}"
            # Both wheels of the pair turn, at the same speed (one axle).
            tendon = model.tendon(name).id
            adr, num = model.tendon_adr[tendon], model.tendon_num[tendon]
            joints = model.wrap_objid[adr : adr + num]
            assert len(joints) == 2
            for j in joints:
                qvel = float(data.qvel[model.jnt_dofadr[j]])
                assert qvel == pytest.approx(target, rel=0.02), f"{robot.name} wheel {j}"
            for other in built.motors:
                if other != name:
                    idle = float(data.sensor(f"{other}_speed").data[0])
                    assert abs(idle) < 0.05 * abs(target), f"{other} turns with {name}"
            assert warnings(data) == {}
            count += 1
    assert count >= 40, f"only {count} motors tried"


@pytest.mark.parametrize("degrees", [60.0, -60.0])
def test_a_pivot_command_moves_its_hinge(degrees: float) -> None:
    reached, blocked = 0, 0
    for robot in robots(4, ACTUATED_ROBOTS):
        built, model = fixed_in_space(robot)
        for name in built.pivots:
            data = mujoco.MjData(model)
            target = math.radians(degrees)
            data.ctrl[model.actuator(name).id] = target
            step(model, data, 1.0)
            angle = float(data.sensor(f"{name}_angle").data[0])
            assert warnings(data) == {}
            if abs(angle - target) < 0.05:
                reached += 1
                continue
            # Not there: its own moving half must be pushing against the rest of the robot.
            moving = subtree(model, model.body(f"{name}_distal").id)
            assert touching(model, data, moving), (
                f"{robot.name} {name}: at {math.degrees(angle):.1f} deg, "
                f"commanded {degrees}, and nothing blocks it"
            )
            assert np.sign(angle) == np.sign(target) or abs(angle) < 0.05
            blocked += 1
    total = reached + blocked
    assert total >= 40, f"only {total} pivots tried"
    assert reached / total >= 0.75, f"{reached} of {total} pivots reached {degrees} deg"


def test_pivot_angle_is_limited_to_its_range() -> None:
    robot = load_robot(REPO / "robots" / "four_wheeler.json")
    built, model = fixed_in_space(robot)
    (name,) = built.pivots
    data = mujoco.MjData(model)
    data.ctrl[model.actuator(name).id] = 10.0  # far beyond the range: clamped by ctrlrange
    step(model, data, 1.5)
    angle = float(data.sensor(f"{name}_angle").data[0])
    assert abs(angle) <= math.radians(90) + 0.02


# --- physics parameters -------------------------------------------------------------------


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"wheel_radius": 0.01}, "wheel_radius must lie between module_size/2"),
        ({"wheel_radius": 0.04}, "wheels in diagonal cells would overlap"),
        ({"module_mass": 0.0}, "module_mass must be positive"),
        ({"pivot_range": 120.0}, r"pivot_range must be in \(0, 90\]"),
    ],
)
def test_physics_params_reject_bad_values(change: dict[str, float], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        PhysicsParams(**change)  # type: ignore[arg-type]


def test_physics_params_reach_the_model() -> None:
    params = PhysicsParams(timestep=0.002, motor_max_speed=5.0, pivot_kp=7.0, wheel_mass=0.05)
    robot = random_robot(np.random.default_rng(9), GeneratorParams(p_empty=0.0, max_depth=2))
    built = build(robot, params)
    model = built.compile()
    assert model.opt.timestep == pytest.approx(0.002)
    for name in built.motors:
        assert model.actuator(name).ctrlrange[1] == pytest.approx(5.0)
    for name in built.pivots:
        assert model.actuator(name).gainprm[0] == pytest.approx(7.0)
        assert model.jnt_range[model.joint(name).id][1] == pytest.approx(math.pi / 2)
    wheels = [g for g in range(model.ngeom) if model.geom(g).name.startswith("wheel")]
    assert wheels
    for g in wheels:
        assert model.body_mass[model.geom_bodyid[g]] == pytest.approx(0.05)
