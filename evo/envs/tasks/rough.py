"""Reach the target over rough ground (SPEC section 3b; ``evo/Rough-v0``): the reach task
on a MuJoCo height field of bumps and steps.

The ground is one map, ``terrain_size`` m across, made from ``terrain_seed`` when the
scene is built: ``bumps`` smooth bumps (up to ``bump_height`` m high, about
``bump_radius`` m wide) and ``steps`` raised rectangles (``step_height`` m, with
vertical edges), flattened in a disc of ``pad_radius`` m around each of a grid of
start pads. The map is a mocap body: each episode lays a different part of it under
the arena, turned by a random angle, with a random pad under the robot's start, so a
policy meets a new stretch of ground every episode and cannot learn one map. The
observation, reward terms and success are reach's (``evo.envs.tasks.reach``).
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from evo.checks import at_least, positive
from evo.envs.arena import ArenaParams
from evo.envs.tasks.base import F64, Arenas, Rules
from evo.envs.tasks.reach import Reach, ReachRules

if TYPE_CHECKING:
    import mujoco


@dataclass(frozen=True, slots=True)
class Rough(Reach):
    """Reach over rough ground: reach's settings and the terrain's.

    Attributes:
        bump_height: Height of the highest bump, m (0: none).
        bump_radius: Typical half-width of a bump, m.
        bumps: Bumps on the whole map.
        step_height: Height of the raised rectangles, m (0: none).
        steps: Raised rectangles on the whole map (0.2 to 1 m a side).
        terrain_size: Side of the square map, m; at least the arena's diagonal plus
            the spread of the start pads.
        resolution: Side of one height-field cell, m.
        pad_radius: The ground is flat (at the floor's height) within this distance of
            each start pad, m: the robot starts on level ground.
        pad_spacing: Distance between neighbouring start pads of the map's grid, m.
        terrain_seed: Seed of the map (the episodes' draws come from the run's seed).
    """

    bump_height: float = 0.02
    bump_radius: float = 0.15
    bumps: int = 800
    step_height: float = 0.015
    steps: int = 200
    terrain_size: float = 14.0
    resolution: float = 0.05
    pad_radius: float = 0.3
    pad_spacing: float = 2.0
    terrain_seed: int = 0

    def __post_init__(self) -> None:
        Reach.__post_init__(self)
        at_least(self, 0, "bump_height", "bumps", "step_height", "steps", "terrain_seed")
        positive(self, "bump_radius", "terrain_size", "resolution", "pad_radius",
                 "pad_spacing")
        if self.terrain_size / self.resolution > 1000:
            raise ValueError(f"terrain_size / resolution must be <= 1000 cells a side, got "
                             f"{self.terrain_size / self.resolution:g}")

    def check_arena(self, arena: ArenaParams) -> None:
        Reach.check_arena(self, arena)
        if self.pad_reach(arena) < 0:
            raise ValueError(
                f"terrain_size ({self.terrain_size} m) must cover the arena (side "
                f"{arena.side} m) turned any way around a start pad: at least "
                f"{2 * math.sqrt(2) * (arena.side / 2 + arena.wall_thickness):g} m")

    def pad_reach(self, arena: ArenaParams) -> float:
        """How far from the map's centre a start pad may lie, m (the map still covers
        the arena, turned any way around it)."""
        return self.terrain_size / 2 - math.sqrt(2) * (arena.side / 2 + arena.wall_thickness)

    def pads(self, arena: ArenaParams) -> F64:
        """The start pads (x, y) on the map, m: a grid of ``pad_spacing`` within
        :meth:`pad_reach` of its centre."""
        reach = max(0.0, self.pad_reach(arena))
        k = int(reach // self.pad_spacing)
        ticks = np.arange(-k, k + 1) * self.pad_spacing
        grid: F64 = np.stack(np.meshgrid(ticks, ticks), axis=-1).reshape(-1, 2)
        return grid

    def heights(self, arena: ArenaParams) -> F64:
        """The map's heights, (cells, cells) m, rows along y, from ``terrain_seed``."""
        rng = np.random.default_rng(self.terrain_seed)
        n = int(round(self.terrain_size / self.resolution))
        ticks = (np.arange(n) + 0.5) * self.resolution - self.terrain_size / 2
        height = np.zeros((n, n))

        def window(cx: float, cy: float, hx: float, hy: float) -> tuple[slice, slice]:
            """The cells within hx, hy of (cx, cy): rows along y, columns along x."""
            rows = np.searchsorted(ticks, [cy - hy, cy + hy])
            cols = np.searchsorted(ticks, [cx - hx, cx + hx])
            return slice(*rows), slice(*cols)

        for _ in range(self.bumps):
            cx, cy = rng.uniform(-self.terrain_size / 2, self.terrain_size / 2, 2)
            width = self.bump_radius * rng.uniform(0.5, 1.5)
            rows, cols = window(cx, cy, 3 * width, 3 * width)
            dy, dx = np.meshgrid(ticks[rows] - cy, ticks[cols] - cx, indexing="ij")
            height[rows, cols] += self.bump_height * rng.uniform(0.3, 1.0) * np.exp(
                -(dx**2 + dy**2) / (2 * width**2))
        for _ in range(self.steps):
            cx, cy = rng.uniform(-self.terrain_size / 2, self.terrain_size / 2, 2)
            hx, hy = rng.uniform(0.1, 0.5, 2)
            height[window(cx, cy, hx, hy)] += self.step_height
        height = np.minimum(height, self.bump_height + self.step_height)
        y, x = np.meshgrid(ticks, ticks, indexing="ij")
        for px, py in self.pads(arena):
            height[np.hypot(x - px, y - py) < self.pad_radius] = 0.0
        return height

    def scene(self, root: ET.Element, arena: ArenaParams) -> None:
        """The map: a height field ``terrain`` on the mocap body ``terrain``, its zero
        level a hair below the floor (the floor carries what rests on level ground)."""
        heights = self.heights(arena)
        top = float(heights.max()) or 1e-3
        world, asset = root.find("worldbody"), root.find("asset")
        assert world is not None and asset is not None
        n = heights.shape[0]
        ET.SubElement(asset, "hfield", name="terrain", nrow=str(n), ncol=str(n),
                      size=f"{self.terrain_size / 2:.6g} {self.terrain_size / 2:.6g} "
                           f"{top:.6g} 0.05",
                      elevation=" ".join(f"{v:.4g}" for v in (heights / top).ravel()))
        body = ET.SubElement(world, "body", name="terrain", mocap="true", pos="0 0 -0.0005")
        ET.SubElement(body, "geom", name="terrain", type="hfield", hfield="terrain",
                      rgba=".62 .58 .5 1")

    def rules(self, core: Arenas) -> Rules:
        return RoughRules(self, core)


class RoughRules(ReachRules):
    """Reach's rules, with each episode's stretch of the map laid under the arena."""

    task: Rough

    def __init__(self, task: Rough, core: Arenas) -> None:
        super().__init__(task, core)
        self.pads = task.pads(core.arena)
        self.terrain = core.mocap_index("terrain")

    def draw(self, arena: int, rng: np.random.Generator, data: mujoco.MjData) -> F64:
        target = super().draw(arena, rng, data)
        pad = self.pads[rng.integers(len(self.pads))]
        turn = rng.uniform(0, 2 * math.pi)
        c, s = math.cos(turn), math.sin(turn)
        data.mocap_pos[self.terrain, :2] = -np.array([c * pad[0] - s * pad[1],
                                                      s * pad[0] + c * pad[1]])
        data.mocap_quat[self.terrain] = [math.cos(turn / 2), 0.0, 0.0, math.sin(turn / 2)]
        target[2] = self.task.bump_height + self.task.step_height  # the marker above the map
        return target
