"""What a compiled MuJoCo scene looks like, as simple primitives both file writers draw.

Foxglove and rerun know boxes, cylinders and ellipsoids (a sphere is an ellipsoid with
equal semi-axes); MuJoCo geoms map onto them as follows:

* box, cylinder, ellipsoid, sphere: one primitive each;
* capsule: a cylinder and two end spheres (Foxglove has no capsule);
* plane (the floor): a thin box 1 cm thick whose top is the plane, as large as the
  plane (10 m square when the plane is infinite);
* height field (a task's terrain): a grid of at most :data:`HFIELD_BLOCKS` a side of
  boxes standing on its zero level, each as high as the highest cell it covers (cells
  at zero draw nothing);
* mesh and other shapes: their bounding box (``geom_aabb``), so nothing vanishes.

Geoms in groups 3..5 (hidden in MuJoCo's viewer by default) and fully transparent
geoms are left out. Colours follow MuJoCo: a geom's own ``rgba`` unless it kept the
default grey and has a material, then the material's.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
import numpy.typing as npt

F64 = npt.NDArray[np.float64]

BOX, CYLINDER, ELLIPSOID = "box", "cylinder", "ellipsoid"
KINDS = (BOX, CYLINDER, ELLIPSOID)

PLANE_THICKNESS = 0.01
"""Thickness of the box that stands in for a plane, m."""

INFINITE_PLANE_HALF = 5.0
"""Half side of the box that stands in for an infinite plane, m."""

HFIELD_BLOCKS = 48
"""Blocks a side of the boxes that draw a height field."""

_DEFAULT_RGBA = np.array([0.5, 0.5, 0.5, 1.0])


@dataclass(frozen=True, slots=True)
class Geometry:
    """Primitives of a scene, each attached to one body and placed in that body's frame.

    Attributes:
        body_names: Name of every body of the model, by body id (``body<i>`` where
            MuJoCo has none); ``body_names[0]`` is the world.
        kind: (n,) ``box``, ``cylinder`` or ``ellipsoid``.
        body: (n,) body id each primitive moves with (0 = world, static).
        pos: (n, 3) centre in the body frame, m.
        quat: (n, 4) orientation in the body frame, w x y z.
        half_size: (n, 3) half extents, m: box half sides; cylinder (radius, radius,
            half length along its z); ellipsoid semi-axes.
        rgba: (n, 4) colour, each channel in [0, 1].
        geom: (n,) the MuJoCo geom each primitive stands for.
    """

    body_names: tuple[str, ...]
    kind: tuple[str, ...]
    body: npt.NDArray[np.int64]
    pos: F64
    quat: F64
    half_size: F64
    rgba: F64
    geom: npt.NDArray[np.int64]

    def __len__(self) -> int:
        return len(self.kind)

    def select(self, mask: npt.NDArray[np.bool_]) -> Geometry:
        """The primitives where ``mask`` is true (same body names)."""
        index = np.flatnonzero(mask)
        return Geometry(
            body_names=self.body_names,
            kind=tuple(self.kind[i] for i in index),
            body=self.body[index],
            pos=self.pos[index],
            quat=self.quat[index],
            half_size=self.half_size[index],
            rgba=self.rgba[index],
            geom=self.geom[index],
        )

    def of_body(self, body: int) -> Geometry:
        """The primitives attached to ``body``."""
        return self.select(self.body == body)

    def of_kind(self, kind: str) -> Geometry:
        """The primitives of one ``kind``."""
        return self.select(np.array([k == kind for k in self.kind], dtype=bool))

    def posed(self, xpos: F64, xquat: F64) -> Geometry:
        """The same primitives in the world frame, every body at ``xpos``/``xquat``.

        Args:
            xpos: (nbody, 3) body positions (MuJoCo ``data.xpos``).
            xquat: (nbody, 4) body orientations, w x y z (``data.xquat``).

        Returns:
            A ``Geometry`` whose ``pos``/``quat`` are world poses (``body`` kept).
        """
        pos = np.empty_like(self.pos)
        quat = np.empty_like(self.quat)
        for i, b in enumerate(self.body):
            mujoco.mju_rotVecQuat(pos[i], self.pos[i], xquat[b])
            pos[i] += xpos[b]
            mujoco.mju_mulQuat(quat[i], xquat[b], self.quat[i])
        return Geometry(
            self.body_names, self.kind, self.body, pos, quat, self.half_size, self.rgba, self.geom
        )


def body_names(model: mujoco.MjModel) -> tuple[str, ...]:
    """Every body's name by id; unnamed bodies are called ``body<id>``."""
    names = []
    for b in range(model.nbody):
        name = model.body(b).name
        names.append(name if name else f"body{b}")
    if len(set(names)) != len(names):
        raise ValueError("body names of the model are not unique; recording needs unique names")
    return tuple(names)


def rest_pose(model: mujoco.MjModel) -> tuple[F64, F64]:
    """Body positions and orientations (w x y z) in the model's reference pose ``qpos0``."""
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    return data.xpos.copy(), data.xquat.copy()


def geom_rgba(model: mujoco.MjModel, geom: int) -> F64:
    """A geom's colour as MuJoCo shows it (own rgba, else its material's)."""
    rgba = np.asarray(model.geom_rgba[geom], dtype=np.float64)
    mat = int(model.geom_matid[geom])
    if mat >= 0 and np.allclose(rgba, _DEFAULT_RGBA):
        return np.asarray(model.mat_rgba[mat], dtype=np.float64)
    return rgba


def _shift(pos: F64, quat: F64, local: F64) -> F64:
    """``pos`` plus the vector ``local`` given in the frame rotated by ``quat``."""
    out = np.zeros(3)
    mujoco.mju_rotVecQuat(out, local, quat)
    return pos + out


def _pieces(model: mujoco.MjModel, g: int) -> list[tuple[str, F64, F64, F64]]:
    """The primitives (kind, pos, quat, half_size) standing in for geom ``g``."""
    size = np.asarray(model.geom_size[g], dtype=np.float64)
    pos = np.asarray(model.geom_pos[g], dtype=np.float64)
    quat = np.asarray(model.geom_quat[g], dtype=np.float64)
    gtype = int(model.geom_type[g])
    t = mujoco.mjtGeom
    if gtype == t.mjGEOM_BOX:
        return [(BOX, pos, quat, size.copy())]
    if gtype == t.mjGEOM_CYLINDER:
        return [(CYLINDER, pos, quat, np.array([size[0], size[0], size[1]]))]
    if gtype == t.mjGEOM_ELLIPSOID:
        return [(ELLIPSOID, pos, quat, size.copy())]
    if gtype == t.mjGEOM_SPHERE:
        return [(ELLIPSOID, pos, quat, np.full(3, size[0]))]
    if gtype == t.mjGEOM_CAPSULE:
        r, h = size[0], size[1]
        ends = [
            (ELLIPSOID, _shift(pos, quat, np.array([0.0, 0.0, s * h])), quat, np.full(3, r))
            for s in (-1.0, 1.0)
        ]
        return [(CYLINDER, pos, quat, np.array([r, r, h])), *ends]
    if gtype == t.mjGEOM_PLANE:
        hx = size[0] if size[0] > 0 else INFINITE_PLANE_HALF
        hy = size[1] if size[1] > 0 else INFINITE_PLANE_HALF
        centre = _shift(pos, quat, np.array([0.0, 0.0, -PLANE_THICKNESS / 2]))
        return [(BOX, centre, quat, np.array([hx, hy, PLANE_THICKNESS / 2]))]
    if gtype == t.mjGEOM_HFIELD:
        return _hfield_boxes(model, g, pos, quat)
    aabb = np.asarray(model.geom_aabb[g], dtype=np.float64)
    return [(BOX, _shift(pos, quat, aabb[:3]), quat, aabb[3:].copy())]


def _hfield_boxes(model: mujoco.MjModel, g: int, pos: F64,
                  quat: F64) -> list[tuple[str, F64, F64, F64]]:
    """The boxes that draw height-field geom ``g``: its cells in blocks, each box as
    high as the block's highest cell (MuJoCo's rows run along y, columns along x)."""
    h = int(model.geom_dataid[g])
    rows, cols = int(model.hfield_nrow[h]), int(model.hfield_ncol[h])
    rx, ry, top, _ = (float(v) for v in model.hfield_size[h])
    adr = int(model.hfield_adr[h])
    heights = np.asarray(model.hfield_data[adr:adr + rows * cols]).reshape(rows, cols) * top
    row_edges = np.linspace(0, rows, min(rows, HFIELD_BLOCKS) + 1).astype(int)
    col_edges = np.linspace(0, cols, min(cols, HFIELD_BLOCKS) + 1).astype(int)
    out = []
    for r0, r1 in zip(row_edges[:-1], row_edges[1:], strict=True):
        for c0, c1 in zip(col_edges[:-1], col_edges[1:], strict=True):
            high = float(heights[r0:r1, c0:c1].max())
            if high <= 1e-3:
                continue
            x = -rx + rx * (c0 + c1) / cols  # the block's centre in the geom's frame
            y = -ry + ry * (r0 + r1) / rows
            half = np.array([rx * (c1 - c0) / cols, ry * (r1 - r0) / rows, high / 2])
            out.append((BOX, _shift(pos, quat, np.array([x, y, high / 2])), quat, half))
    return out


def scene_geometry(model: mujoco.MjModel) -> Geometry:
    """All visible geoms of ``model`` as primitives in their bodies' frames.

    Args:
        model: A compiled MuJoCo model (a robot alone or a whole arena).

    Returns:
        The scene's ``Geometry``.
    """
    kinds: list[str] = []
    bodies: list[int] = []
    poses: list[F64] = []
    quats: list[F64] = []
    halves: list[F64] = []
    colours: list[F64] = []
    geoms: list[int] = []
    for g in range(model.ngeom):
        rgba = geom_rgba(model, g)
        if model.geom_group[g] >= 3 or rgba[3] <= 0:
            continue
        for kind, pos, quat, half in _pieces(model, g):
            kinds.append(kind)
            bodies.append(int(model.geom_bodyid[g]))
            poses.append(pos)
            quats.append(quat)
            halves.append(half)
            colours.append(rgba)
            geoms.append(g)
    n = len(kinds)
    return Geometry(
        body_names=body_names(model),
        kind=tuple(kinds),
        body=np.array(bodies, dtype=np.int64),
        pos=np.array(poses, dtype=np.float64).reshape(n, 3),
        quat=np.array(quats, dtype=np.float64).reshape(n, 4),
        half_size=np.array(halves, dtype=np.float64).reshape(n, 3),
        rgba=np.array(colours, dtype=np.float64).reshape(n, 4),
        geom=np.array(geoms, dtype=np.int64),
    )
