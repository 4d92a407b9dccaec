"""Robot structure -> MuJoCo model (SPEC section 2).

One body per module (a pivot is two: its proximal and distal halves), a free joint on
the brain, pivots as +-90 degree hinges driven by PD position actuators, motor wheel
pairs as two hinges held together by an equality constraint (one axle) and driven
through a fixed tendon by one force-clamped velocity actuator (a constant torque until
the commanded speed is reached, as in the paper), passive wheels as damped
free-spinning hinges. Contacts between lattice-adjacent modules are excluded;
all other self-contact is kept.

Conventions: a positive motor command spins its wheels right-handed about the motor's
+y axis, which rolls the motor toward its own +x when its z points up. Actuators come
motors first, then pivots, each in depth-first tree order; the environment's action
and observation use the same order.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from collections.abc import Callable
from dataclasses import dataclass

import mujoco
import numpy as np
import numpy.typing as npt

from evo.checks import at_least, positive
from evo.robot.tree import (
    FACE_NORMALS,
    IntMatrix,
    ModuleType,
    Placed,
    Robot,
    child_frame,
)

FloatArray = npt.NDArray[np.float64]


WHEEL_AXIS_SKEW = 1e-6
"""Angle (rad) by which a wheel's cylinder axis is tilted off its axle.

MuJoCo's plane-cylinder test treats a cylinder as tilted as soon as its axis is more than
about 1e-15 off the plane normal, and then aims the rim point along the leftover vector.
Rounding in the composed lattice rotations leaves a wheel whose axle is vertical in the
rest pose (lying flat) a few 1e-16 off, so the rim point aims along noise and the wheel
reports a phantom 2-3 cm penetration that launches the robot at the start of an
episode. This tilt (3e-8 m at the rim) keeps the axis clear of that degenerate case.
"""


@dataclass(frozen=True, slots=True)
class PhysicsParams:
    """Physical constants of the modules (SI units throughout).

    Attributes:
        module_size: Edge of every cube module, m.
        module_gap: Clearance between neighbouring cubes' collision boxes, m.
        brain_mass: Mass of the brain (battery and computer), kg.
        module_mass: Mass of a motor, pivot or main module, kg.
        wheel_mass: Mass of one wheel, kg.
        wheel_radius: Wheel radius, m; above module_size/2 so wheels touch the floor,
            and small enough that two wheels in diagonal cells never overlap at rest
            (see ``max_wheel_radius``).
        wheel_width: Wheel thickness along its axle, m.
        friction: Sliding, torsional and rolling friction of every robot geom
            (MuJoCo's coefficients: sliding unitless, torsional and rolling in m).
        body_damping: Damping on the brain's free joint, N s/m and N m s/rad: air drag
            and rolling resistance lumped together, so a robot rocking on a wheel rim
            comes to rest.
        motor_max_speed: Wheel speed at command +-1, rad/s.
        motor_max_torque: Torque limit of a motor on its wheel pair, N m.
        motor_kv: Velocity gain of the motor, N m s/rad (saturates at the torque limit).
        motor_armature: Reflected rotor inertia of a driven wheel joint, kg m^2.
        passive_wheel_damping: Viscous damping of a passive wheel, N m s/rad.
        passive_wheel_armature: Armature of a passive wheel joint, kg m^2.
        pivot_range: Pivot angle limit (symmetric), degrees.
        pivot_kp: Pivot position gain, N m/rad.
        pivot_kd: Pivot damping gain, N m s/rad.
        pivot_max_torque: Pivot torque limit, N m.
        pivot_armature: Reflected rotor inertia of the pivot joint, kg m^2.
        timestep: Physics timestep, s.
    """

    module_size: float = 0.05
    module_gap: float = 0.001
    brain_mass: float = 0.2
    module_mass: float = 0.1
    wheel_mass: float = 0.03
    wheel_radius: float = 0.031
    wheel_width: float = 0.02
    friction: tuple[float, float, float] = (1.0, 0.005, 0.0001)
    body_damping: float = 0.01
    motor_max_speed: float = 12.0
    motor_max_torque: float = 0.4
    motor_kv: float = 1.0
    motor_armature: float = 0.0005
    passive_wheel_damping: float = 0.0005
    passive_wheel_armature: float = 0.0001
    pivot_range: float = 90.0
    pivot_kp: float = 4.0
    pivot_kd: float = 0.1
    pivot_max_torque: float = 1.0
    pivot_armature: float = 0.002
    timestep: float = 0.005

    @property
    def max_wheel_radius(self) -> float:
        """Largest wheel radius at which wheels in diagonal cells cannot touch at rest, m.

        A wheel sticks out of its cell radially by ``r - s/2``; two wheels sticking into
        the same empty cell from two sides meet once (s - r)^2 + (s/2 + gap)^2 <= r^2.
        """
        s = self.module_size
        return (s**2 + (s / 2 + self.module_gap) ** 2) / (2 * s)

    def __post_init__(self) -> None:
        positive(self, "module_size", "brain_mass", "module_mass", "wheel_mass", "wheel_width",
                 "motor_max_speed", "motor_max_torque", "motor_kv", "pivot_max_torque",
                 "pivot_kp", "timestep")
        at_least(self, 0, "module_gap", "friction", "body_damping", "motor_armature",
                 "passive_wheel_damping", "passive_wheel_armature", "pivot_kd", "pivot_armature")
        half, top = self.module_size / 2, self.max_wheel_radius
        if not half < self.wheel_radius < top:
            raise ValueError(
                f"wheel_radius must lie between module_size/2 ({half:.4f} m) and "
                f"{top:.4f} m (wheels in diagonal cells would overlap), got {self.wheel_radius}"
            )
        if not 0 < self.pivot_range <= 90:
            raise ValueError(f"pivot_range must be in (0, 90] degrees, got {self.pivot_range}")


@dataclass(frozen=True, slots=True)
class BuiltRobot:
    """A robot turned into MJCF, with the names the environment needs.

    Attributes:
        xml: The complete MJCF document.
        motors: Actuator names of the motors, in action order.
        pivots: Actuator names of the pivots, in action order (after the motors).
        bodies: Body name of every module (a pivot's proximal half), in tree order.
        brain_height: Height of the brain's centre in the rest pose when its lowest
            point touches the floor, m.
    """

    xml: str
    motors: tuple[str, ...]
    pivots: tuple[str, ...]
    bodies: tuple[str, ...]
    brain_height: float

    @property
    def actuators(self) -> tuple[str, ...]:
        """All actuator names in action order: motors, then pivots."""
        return self.motors + self.pivots

    def compile(self) -> mujoco.MjModel:
        """The compiled MuJoCo model."""
        return mujoco.MjModel.from_xml_string(self.xml)


SceneHook = Callable[[ET.Element], None]
"""Adds world elements (floor, walls, rocks, target) to the MJCF root."""


def floor_scene(root: ET.Element) -> None:
    """A plain floor plane, the scene used when no arena is given."""
    world = root.find("worldbody")
    assert world is not None
    ET.SubElement(world, "geom", name="floor", type="plane", size="2 2 0.1", material="grid")


def _fmt(values: npt.ArrayLike) -> str:
    return " ".join(f"{v:.6g}" for v in np.asarray(values, dtype=float).ravel())


def _span(limit: float) -> str:
    """A symmetric MJCF range, ``-limit limit``."""
    return _fmt((-limit, limit))


def _quat(frame: IntMatrix) -> str:
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, np.asarray(frame, dtype=float).ravel())
    return _fmt(quat)


def _lowest_point(placed: list[Placed], p: PhysicsParams) -> float:
    """Lowest z of the robot in the rest pose, with the brain's centre at z = 0."""
    s, lowest = p.module_size, 0.0
    for m in placed:
        if m.node.type is ModuleType.WHEEL:
            assert m.parent is not None
            axis = m.frame[:, 0].astype(float)
            centre = np.asarray(m.parent.cell, dtype=float) * s + axis * (
                s / 2 + p.module_gap + p.wheel_width / 2
            )
            reach = p.wheel_radius * math.sqrt(max(0.0, 1 - axis[2] ** 2))
            reach += p.wheel_width / 2 * abs(axis[2])
            lowest = min(lowest, centre[2] - reach)
        else:
            # The collision boxes leave a gap between cubes; a pivot's two half boxes
            # reach a little further along its own x than across it.
            along_x = m.node.type is ModuleType.PIVOT and abs(int(m.frame[2, 0])) == 1
            half = s / 2 - p.module_gap / (4 if along_x else 2)
            lowest = min(lowest, m.cell[2] * s - half)
    return lowest


class _Builder:
    """Walks the tree once, emitting bodies, joints, actuators, sensors and exclusions."""

    def __init__(self, robot: Robot, params: PhysicsParams) -> None:
        self.robot, self.p = robot, params
        self.placed = robot.modules()
        self.names: dict[tuple[int, ...], str] = {}
        self.bodies_of: dict[tuple[int, ...], list[str]] = {}
        self.motors: list[str] = []
        self.pivots: list[str] = []
        self.wheel_joints: dict[tuple[int, ...], list[str]] = {}

    def name(self, m: Placed, index: int) -> str:
        return "brain" if m.parent is None else f"{m.node.type.value}{index}"

    def build(self, root: ET.Element, brain_z: float, free: bool) -> None:
        world = root.find("worldbody")
        assert world is not None
        elements: dict[tuple[int, ...], ET.Element] = {}
        for index, m in enumerate(self.placed):
            name = self.name(m, index)
            self.names[m.path] = name
            if m.parent is None:
                body = ET.SubElement(world, "body", name=name, pos=f"0 0 {brain_z:.6g}")
                if free:
                    ET.SubElement(
                        body,
                        "joint",
                        type="free",
                        name="root",
                        damping=f"{self.p.body_damping:.6g}",
                    )
                ET.SubElement(body, "site", name="imu", size="0.005")
            else:
                body = self.child_body(elements[m.parent.path], m, name)
            elements[m.path] = self.module_geoms(body, m, name)
        self.actuators_and_sensors(root)
        self.exclusions(root)

    def child_body(self, parent: ET.Element, m: Placed, name: str) -> ET.Element:
        assert m.parent is not None
        s, face = self.p.module_size, m.path[-1]
        normal = FACE_NORMALS[face].astype(float)
        if m.node.type is ModuleType.WHEEL:
            offset = normal * (s / 2 + self.p.module_gap + self.p.wheel_width / 2)
            frame = child_frame(face, 0)
        else:
            offset = normal * s
            frame = child_frame(face, m.rotation)
        return ET.SubElement(parent, "body", name=name, pos=_fmt(offset), quat=_quat(frame))

    def module_geoms(self, body: ET.Element, m: Placed, name: str) -> ET.Element:
        """Geoms and joints of one module; returns the body its children attach to."""
        p, kind = self.p, m.node.type
        self.bodies_of[m.path] = [name]
        if kind is ModuleType.WHEEL:
            return self.wheel(body, m, name)
        if kind is ModuleType.PIVOT:
            return self.pivot(body, m, name)
        mass = p.brain_mass if kind is ModuleType.BRAIN else p.module_mass
        half = p.module_size / 2 - p.module_gap / 2
        ET.SubElement(body, "geom", name=name, type="box", size=_fmt([half] * 3),
                      mass=f"{mass:.6g}", material=kind.value)
        if kind is ModuleType.MOTOR:
            self.motors.append(name)
        return body

    def wheel(self, body: ET.Element, m: Placed, name: str) -> ET.Element:
        """A wheel: a cylinder on a hinge, driven by its parent motor or passive."""
        p = self.p
        assert m.parent is not None
        sign = 1 if m.path[-1] % 2 == 0 else -1
        driven = m.parent.node.type is ModuleType.MOTOR
        ET.SubElement(
            body,
            "joint",
            name=name,
            type="hinge",
            axis=f"{sign} 0 0",
            armature=f"{p.motor_armature if driven else p.passive_wheel_armature:.6g}",
            damping="0" if driven else f"{p.passive_wheel_damping:.6g}",
        )
        ET.SubElement(
            body,
            "geom",
            name=name,
            type="cylinder",
            zaxis=f"1 {WHEEL_AXIS_SKEW:.6g} 0",
            size=f"{p.wheel_radius:.6g} {p.wheel_width / 2:.6g}",
            mass=f"{p.wheel_mass:.6g}",
            material="wheel",
        )
        self.wheel_joints.setdefault(m.parent.path, []).append(name)
        return body

    def pivot(self, body: ET.Element, m: Placed, name: str) -> ET.Element:
        """A pivot: the proximal half is ``body``, the distal half a child body on the
        hinge, which its children attach to."""
        p = self.p
        half, quarter = p.module_size / 2 - p.module_gap / 2, p.module_size / 4
        box = _fmt([quarter - p.module_gap / 4, half, half])
        mass = p.module_mass
        ET.SubElement(body, "geom", name=name, type="box", size=box, pos=f"{-quarter:.6g} 0 0",
                      mass=f"{mass / 2:.6g}", material="pivot")
        distal = ET.SubElement(body, "body", name=f"{name}_distal")
        limit = p.pivot_range
        ET.SubElement(
            distal,
            "joint",
            name=name,
            type="hinge",
            axis="0 0 1",
            range=_span(limit),
            armature=f"{p.pivot_armature:.6g}",
        )
        ET.SubElement(distal, "geom", name=f"{name}_distal", type="box", size=box,
                      pos=f"{quarter:.6g} 0 0", mass=f"{mass / 2:.6g}", material="pivot_distal")
        self.bodies_of[m.path].append(f"{name}_distal")
        self.pivots.append(name)
        return distal

    def actuators_and_sensors(self, root: ET.Element) -> None:
        p = self.p
        tendon = ET.SubElement(root, "tendon")
        equality = ET.SubElement(root, "equality")
        actuator = ET.SubElement(root, "actuator")
        sensor = ET.SubElement(root, "sensor")
        ET.SubElement(sensor, "velocimeter", name="brain_linvel", site="imu")
        ET.SubElement(sensor, "gyro", name="brain_angvel", site="imu")
        ET.SubElement(sensor, "framepos", name="brain_origin", objtype="body", objname="brain")
        ET.SubElement(sensor, "framexaxis", name="brain_xaxis", objtype="body", objname="brain")
        ET.SubElement(sensor, "framezaxis", name="brain_zaxis", objtype="body", objname="brain")
        motor_paths = [m.path for m in self.placed if m.node.type is ModuleType.MOTOR]
        for path in motor_paths:
            name = self.names[path]
            fixed = ET.SubElement(tendon, "fixed", name=name)
            for joint in self.wheel_joints[path]:
                ET.SubElement(fixed, "joint", joint=joint, coef="0.5")
            # The pair turns together, as on one axle.
            first, second = self.wheel_joints[path]
            ET.SubElement(equality, "joint", joint1=first, joint2=second, polycoef="0 1 0 0 0")
            ET.SubElement(actuator, "velocity", name=name, tendon=name, kv=_fmt(p.motor_kv),
                          ctrlrange=_span(p.motor_max_speed),
                          forcerange=_span(p.motor_max_torque))
            ET.SubElement(sensor, "tendonvel", name=f"{name}_speed", tendon=name)
        limit = math.radians(p.pivot_range)
        for name in self.pivots:
            ET.SubElement(actuator, "position", name=name, joint=name, kp=_fmt(p.pivot_kp),
                          kv=_fmt(p.pivot_kd), ctrlrange=_span(limit),
                          forcerange=_span(p.pivot_max_torque))
            ET.SubElement(sensor, "jointpos", name=f"{name}_angle", joint=name)
        for m in self.placed:
            name = self.names[m.path]
            ET.SubElement(
                sensor,
                "framepos",
                name=f"{name}_pos",
                objtype="body",
                objname=self.bodies_of[m.path][-1],
            )

    def exclusions(self, root: ET.Element) -> None:
        """Exclude contacts within a pivot and between modules in face-adjacent cells.

        MuJoCo's own parent-child filter does not apply to bodies welded to the world
        (a fixed base), so every pair is listed explicitly.
        """
        contact = ET.SubElement(root, "contact")
        by_cell = {m.cell: m for m in self.placed}
        for m in self.placed:
            own = self.bodies_of[m.path]
            if len(own) == 2:
                ET.SubElement(contact, "exclude", body1=own[0], body2=own[1])
            for d in ((1, 0, 0), (0, 1, 0), (0, 0, 1)):
                other = by_cell.get((m.cell[0] + d[0], m.cell[1] + d[1], m.cell[2] + d[2]))
                if other is None:
                    continue
                for b1 in own:
                    for b2 in self.bodies_of[other.path]:
                        ET.SubElement(contact, "exclude", body1=b1, body2=b2)


_ASSETS = """
<asset>
  <texture name="grid" type="2d" builtin="checker" rgb1=".82 .82 .8" rgb2=".72 .72 .7"
           width="256" height="256" mark="edge" markrgb=".6 .6 .6"/>
  <material name="grid" texture="grid" texrepeat="8 8" reflectance="0.05"/>
  <material name="brain" rgba=".95 .55 .1 1"/>
  <material name="motor" rgba=".15 .45 .85 1"/>
  <material name="pivot" rgba=".2 .7 .35 1"/>
  <material name="pivot_distal" rgba=".1 .55 .25 1"/>
  <material name="main" rgba=".85 .85 .85 1"/>
  <material name="wheel" rgba=".12 .12 .12 1"/>
</asset>
"""


def build(
    robot: Robot,
    params: PhysicsParams | None = None,
    scene: SceneHook = floor_scene,
    clearance: float = 0.005,
    free: bool = True,
) -> BuiltRobot:
    """Turn a robot into a complete MJCF document.

    Args:
        robot: The (valid) robot structure.
        params: Physical constants (defaults to ``PhysicsParams()``).
        scene: Adds the world around the robot (floor by default; arenas add walls,
            rocks and the target).
        clearance: Height of the robot's lowest point above the floor at the start, m.
        free: Give the brain a free joint; False fixes it in place (for tests and
            pictures of the actuators alone).

    Returns:
        The MJCF text with the actuator, body and sensor names the environment uses.
    """
    params = params or PhysicsParams()
    builder = _Builder(robot, params)
    root = ET.Element("mujoco", model=robot.name)
    ET.SubElement(root, "compiler", angle="degree", autolimits="true")
    ET.SubElement(root, "option", timestep=f"{params.timestep:.6g}", integrator="implicitfast")
    default = ET.SubElement(ET.SubElement(root, "default"), "geom")
    default.set("friction", _fmt(params.friction))
    default.set("condim", "3")
    root.append(ET.fromstring(_ASSETS))
    world = ET.SubElement(root, "worldbody")
    ET.SubElement(world, "light", name="sun", pos="0 0 3", dir="0 0 -1", directional="true")
    scene(root)
    height = -_lowest_point(builder.placed, params)
    builder.build(root, height + clearance, free)
    ET.indent(root)
    return BuiltRobot(
        xml=ET.tostring(root, encoding="unicode"),
        motors=tuple(builder.motors),
        pivots=tuple(builder.pivots),
        bodies=tuple(builder.bodies_of[m.path][0] for m in builder.placed),
        brain_height=height,
    )
