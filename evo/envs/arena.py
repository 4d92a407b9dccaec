"""Arenas of the tasks (SPEC sections 3, 3b): floor, walls, movable rocks and a marker.

An arena is a square of side ``side`` with walls, the robot starting at its centre.
``clean`` is floor + walls; ``cluttered`` also has ``n_rocks`` movable rocks of five fixed
types (rock ``i`` has type ``i mod 5``), re-scattered around the target every episode.
The target itself is a mocap marker without collision: the task measures distances to
it in numpy, the marker only shows it in pictures and replays.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from evo.checks import at_least, positive

SHAPES = ("box", "sphere", "cylinder", "ellipsoid")
ROCK_DRAWS = 512
"""Draws a rock gets for a spot clear of the rocks placed before it."""


@dataclass(frozen=True, slots=True)
class RockType:
    """One rock shape.

    Attributes:
        shape: MuJoCo geom type: box, sphere, cylinder (upright) or ellipsoid.
        size: MuJoCo size, m: half extents (box, ellipsoid), radius (sphere), radius and
            half height (cylinder).
    """

    shape: str
    size: tuple[float, ...]

    def __post_init__(self) -> None:
        expected = {"box": 3, "sphere": 1, "cylinder": 2, "ellipsoid": 3}
        if self.shape not in expected:
            raise ValueError(f"rock shape must be one of {', '.join(SHAPES)}, got {self.shape!r}")
        if len(self.size) != expected[self.shape] or min(self.size) <= 0:
            raise ValueError(
                f"a {self.shape} rock needs {expected[self.shape]} positive sizes, got {self.size}"
            )

    @property
    def half_height(self) -> float:
        """Height of the rock's centre when it rests on the floor, m."""
        return self.size[0] if self.shape == "sphere" else self.size[-1]

    @property
    def radius(self) -> float:
        """Horizontal bounding radius, m (used to keep rocks apart when scattering)."""
        if self.shape == "box":
            return math.hypot(self.size[0], self.size[1])
        if self.shape == "ellipsoid":
            return max(self.size[0], self.size[1])
        return self.size[0]


DEFAULT_ROCKS = (
    RockType("box", (0.04, 0.04, 0.04)),
    RockType("box", (0.07, 0.035, 0.02)),
    RockType("sphere", (0.04,)),
    RockType("cylinder", (0.045, 0.025)),
    RockType("ellipsoid", (0.06, 0.04, 0.03)),
)
"""The five rock shapes of the cluttered arena: a cube and a slab (half extents), a
ball (radius), an upright disc (radius and half height) and a pebble (semi-axes), m."""


@dataclass(frozen=True, slots=True)
class ArenaParams:
    """The world around the robot.

    Attributes:
        side: Side of the square arena, m (the paper's L).
        wall_height: Height of the walls, m.
        wall_thickness: Thickness of the walls, m.
        n_rocks: Rocks per episode (0 = clean arena).
        rock_types: The rock shapes (:data:`DEFAULT_ROCKS`); rock i has type i mod
            len(rock_types).
        rock_density: Density of the rocks, kg/m^3 (light enough to be pushed).
        rock_spread: Rocks are scattered within this distance of the target, m.
        start_clearance: No rock centre closer than this to the arena centre (the
            robot's start), m.
        target_clearance: No rock centre closer than this to the target, m.
        sleep: Let bodies at rest sleep (MuJoCo's sleeping islands): a rock that has
            settled leaves the simulation, and its contacts with the floor, until
            something awake touches it. The robot never sleeps (it has actuators).
    """

    side: float = 4.0
    wall_height: float = 0.1
    wall_thickness: float = 0.05
    n_rocks: int = 0
    rock_types: tuple[RockType, ...] = field(default=DEFAULT_ROCKS)
    rock_density: float = 300.0
    rock_spread: float = 0.6
    start_clearance: float = 0.35
    target_clearance: float = 0.12
    sleep: bool = False

    def __post_init__(self) -> None:
        positive(self, "side", "wall_height", "wall_thickness", "rock_density", "rock_spread")
        at_least(self, 0, "n_rocks")
        if self.n_rocks and not self.rock_types:
            raise ValueError("rock_types must list at least one rock when n_rocks > 0")
        at_least(self, 0, "start_clearance", "target_clearance")
        if self.rock_spread >= self.side / 2:
            raise ValueError(f"rock_spread ({self.rock_spread} m) must be below half the "
                             f"arena side ({self.side / 2:g} m)")
        if self.n_rocks and self.rock_footprint > self.free_area:
            raise ValueError(
                f"n_rocks ({self.n_rocks}) do not fit: their footprints cover "
                f"{self.rock_footprint:.3g} m^2, the free area within rock_spread of the "
                f"target is {self.free_area:.3g} m^2 (at most "
                f"{self.most_rocks} rocks of these types)")

    @classmethod
    def clean(cls) -> ArenaParams:
        """Floor and walls only."""
        return cls()

    @classmethod
    def cluttered(cls) -> ArenaParams:
        """Floor, walls and 40 rocks around the target; settled rocks sleep."""
        return cls(n_rocks=40, sleep=True)

    @classmethod
    def open(cls) -> ArenaParams:
        """Floor and walls 30 m apart: room to travel (``conf/env/task/locomotion.yaml``)."""
        return cls(side=30.0)

    @property
    def free_area(self) -> float:
        """Where rocks may lie: the disc of radius ``rock_spread`` around the target
        without the target's clearance, m^2."""
        return math.pi * (self.rock_spread**2 - min(self.target_clearance, self.rock_spread)**2)

    @property
    def rock_footprint(self) -> float:
        """Floor area the rocks' bounding circles cover, m^2 (O(len(rock_types)))."""
        if not self.rock_types:
            return 0.0
        areas = [math.pi * rock.radius**2 for rock in self.rock_types]
        whole, part = divmod(self.n_rocks, len(areas))
        return whole * sum(areas) + sum(areas[:part])

    @property
    def most_rocks(self) -> int:
        """The largest ``n_rocks`` whose footprint fits the free area."""
        areas = [math.pi * rock.radius**2 for rock in self.rock_types]
        per_round = sum(areas)
        n = len(areas) * int(self.free_area // per_round)
        covered = (n // len(areas)) * per_round
        for area in areas:
            if covered + area > self.free_area:
                break
            covered, n = covered + area, n + 1
        return n

    @property
    def rocks(self) -> tuple[RockType, ...]:
        """The type of every rock, in body order."""
        return tuple(self.rock_types[i % len(self.rock_types)] for i in range(self.n_rocks))


def _fmt(values: npt.ArrayLike) -> str:
    return " ".join(f"{v:.6g}" for v in np.asarray(values, dtype=float).ravel())


def arena_scene(params: ArenaParams, target_radius: float) -> ET.Element:
    """The arena as MJCF world elements, to be added by the robot builder's scene hook.

    Returns:
        A ``<worldbody>`` holding the floor, the four walls, the rocks (free bodies
        ``rock0``, ``rock1``, ...) and the ``target`` mocap marker.
    """
    world = ET.Element("worldbody")
    half = params.side / 2
    ET.SubElement(
        world,
        "geom",
        name="floor",
        type="plane",
        size=_fmt([half + 0.5, half + 0.5, 0.1]),
        material="grid",
    )
    t, h = params.wall_thickness, params.wall_height
    for i, (x, y, sx, sy) in enumerate(
        [
            (half + t / 2, 0, t / 2, half + t),
            (-half - t / 2, 0, t / 2, half + t),
            (0, half + t / 2, half + t, t / 2),
            (0, -half - t / 2, half + t, t / 2),
        ]
    ):
        ET.SubElement(
            world,
            "geom",
            name=f"wall{i}",
            type="box",
            pos=_fmt([x, y, h / 2]),
            size=_fmt([sx, sy, h / 2]),
            rgba=".55 .5 .45 1",
        )
    for i, rock in enumerate(params.rocks):
        body = ET.SubElement(world, "body", name=f"rock{i}", pos=_fmt([0, 0, rock.half_height]))
        ET.SubElement(body, "freejoint", name=f"rock{i}")
        ET.SubElement(
            body,
            "geom",
            name=f"rock{i}",
            type=rock.shape,
            size=_fmt(rock.size),
            density=f"{params.rock_density:.6g}",
            rgba=".5 .42 .35 1",
        )
    target = ET.SubElement(world, "body", name="target", mocap="true", pos="1 0 0")
    ET.SubElement(
        target,
        "geom",
        name="target",
        type="cylinder",
        size=_fmt([target_radius, 0.001]),
        contype="0",
        conaffinity="0",
        rgba=".9 .15 .15 .6",
    )
    return world


def obstacle_ranges(
    origin: npt.NDArray[np.float64],
    heading: npt.NDArray[np.float64],
    sectors: int,
    centres: npt.NDArray[np.float64],
    radii: npt.NDArray[np.float64],
    half_side: float,
) -> npt.NDArray[np.float64]:
    """What a ring of ``sectors`` range sensors on the floor plane would read: for each
    sector of the circle around ``origin`` (sector k centred ``2 pi k / sectors``
    counter-clockwise from ``heading``, each as wide as the next), how far the nearest
    rock or wall in it is.

    A rock is its horizontal bounding circle (``RockType.radius``), whatever its height:
    it counts in every sector that some of it lies in, at the distance of its nearest
    point (0 from inside it). A wall (inner faces at ``±half_side``) counts at the
    distance of its nearest point within the sector.

    Args:
        origin: Where the sensors sit, (N, 2) m.
        heading: The world angle of each origin's first sector, (N,) rad.
        sectors: Sensors in the ring, K.
        centres: The rocks' centres, (N, R, 2) m (R may be 0).
        radii: The rocks' bounding radii, (R,) m.
        half_side: Half the arena's side, m.

    Returns:
        (N, K) distances, m.
    """
    half = math.pi / sectors
    middle = heading[:, None] + 2 * math.pi * np.arange(sectors) / sectors  # (N, K)

    def apart(a: npt.NDArray[np.float64], b: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """The angle between directions a and b, in [0, pi]."""
        return np.abs((a - b + math.pi) % (2 * math.pi) - math.pi)

    normals = np.array([0.0, math.pi / 2, math.pi, -math.pi / 2])  # +x, +y, -x, -y walls
    perpendicular = np.stack([half_side - origin[:, 0], half_side - origin[:, 1],
                              half_side + origin[:, 0], half_side + origin[:, 1]], axis=1)
    off = np.maximum(apart(normals[None, None, :], middle[:, :, None]) - half, 0.0)
    with np.errstate(divide="ignore"):
        to_wall = np.where(off < math.pi / 2,
                           np.maximum(perpendicular, 0.0)[:, None, :] / np.cos(off), np.inf)
    distance: npt.NDArray[np.float64] = to_wall.min(axis=2)
    if centres.shape[1]:
        towards = centres - origin[:, None, :]  # (N, R, 2)
        to_centre = np.linalg.norm(towards, axis=2)
        bearing = np.arctan2(towards[..., 1], towards[..., 0])
        inside = to_centre <= radii
        spread = np.where(inside, math.pi,
                          np.arcsin(np.clip(radii / np.maximum(to_centre, 1e-12), 0.0, 1.0)))
        seen = apart(bearing[:, None, :], middle[:, :, None]) <= half + spread[:, None, :]
        gap = np.maximum(to_centre - radii, 0.0)[:, None, :]
        distance = np.minimum(distance, np.where(seen, gap, np.inf).min(axis=2))
    return distance


def scatter_rocks(
    params: ArenaParams, target: npt.NDArray[np.float64], rng: np.random.Generator
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Random rest positions and yaw orientations of the rocks around ``target``.

    Rocks lie within ``rock_spread`` of the target and inside the walls, never closer
    than ``start_clearance`` to the arena centre (where the robot starts) and at least
    ``target_clearance`` from the target. They also avoid each other (bounding circles
    apart): each rock gets up to :data:`ROCK_DRAWS` draws for a free spot and, should
    the neighbourhood be that full, takes the draw that overlaps least. Rocks that
    overlap are pushed apart by the physics at the start, which sets them rolling:
    motion no robot caused.

    Returns:
        Positions ``(n_rocks, 3)`` and quaternions ``(n_rocks, 4)`` (w, x, y, z).
    """
    rocks = params.rocks
    radii = np.array([rock.radius for rock in rocks])
    pos = np.zeros((len(rocks), 3))
    for i, rock in enumerate(rocks):
        best, best_gap = np.zeros(2), -np.inf
        for _ in range(ROCK_DRAWS // _BATCH):
            spots = _spots_near(params, rock, target, rng)
            gaps = (np.hypot(spots[:, None, 0] - pos[None, :i, 0],
                             spots[:, None, 1] - pos[None, :i, 1])
                    - radii[None, :i] - rock.radius).min(axis=1, initial=np.inf)
            free = np.flatnonzero(gaps >= 0)
            if len(free):
                best = spots[free[0]]
                break
            if gaps.max() > best_gap:
                best, best_gap = spots[int(np.argmax(gaps))], float(gaps.max())
        pos[i] = (*best, rock.half_height + 0.001)
    yaw = rng.uniform(0, 2 * math.pi, size=len(rocks))
    zero = np.zeros(len(rocks))
    return pos, np.stack([np.cos(yaw / 2), zero, zero, np.sin(yaw / 2)], axis=1)


_BATCH = 32
"""Candidate spots drawn at once."""


def _spots_near(
    params: ArenaParams, rock: RockType, target: npt.NDArray[np.float64], rng: np.random.Generator
) -> npt.NDArray[np.float64]:
    """:data:`_BATCH` spots for ``rock`` near the target, each meeting the hard
    constraints (inside the walls, clear of the start and of the target)."""
    margin = params.side / 2 - params.wall_thickness / 2 - rock.radius
    spots: list[npt.NDArray[np.float64]] = []
    for _ in range(1000):
        r = params.rock_spread * np.sqrt(rng.random(4 * _BATCH))
        a = rng.uniform(0, 2 * math.pi, 4 * _BATCH)
        xy = target[:2] + np.stack([r * np.cos(a), r * np.sin(a)], axis=1)
        ok = ((np.abs(xy).max(axis=1) <= margin)
              & (np.hypot(xy[:, 0], xy[:, 1]) >= params.start_clearance + rock.radius)
              & (np.hypot(*(xy - target[:2]).T) >= params.target_clearance + rock.radius))
        spots.append(xy[ok])
        if sum(len(s) for s in spots) >= _BATCH:
            return np.concatenate(spots)[:_BATCH]
    raise ValueError(
        f"no room for a rock within rock_spread={params.rock_spread} m of the target at "
        f"{target[:2].round(3).tolist()} outside start_clearance={params.start_clearance} m"
    )


def sample_target(rng: np.random.Generator, r_min: float, r_max: float) -> npt.NDArray[np.float64]:
    """A target uniform in area over the annulus ``r_min <= r <= r_max`` (z = 0)."""
    r = math.sqrt(rng.uniform(r_min**2, r_max**2))
    a = rng.uniform(0, 2 * math.pi)
    return np.array([r * math.cos(a), r * math.sin(a), 0.0])
