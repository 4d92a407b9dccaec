"""Offscreen pictures of robots with MuJoCo's renderer.

MuJoCo picks its OpenGL backend from ``MUJOCO_GL``; on a machine without a display use
``MUJOCO_GL=egl`` (or ``osmesa``). When no backend works, ``RenderError`` says so.
"""

from __future__ import annotations

import os
from pathlib import Path

import mujoco
import numpy as np
import numpy.typing as npt

from evo.robot.builder import PhysicsParams, build
from evo.robot.tree import Robot


class RenderError(RuntimeError):
    """No OpenGL context could be made for offscreen rendering."""


def make_renderer(model: mujoco.MjModel, width: int, height: int) -> mujoco.Renderer:
    """A MuJoCo renderer, or ``RenderError`` naming ``MUJOCO_GL`` when GL is missing."""
    model.vis.global_.offwidth = max(model.vis.global_.offwidth, width)
    model.vis.global_.offheight = max(model.vis.global_.offheight, height)
    try:
        return mujoco.Renderer(model, height=height, width=width)
    except Exception as err:  # noqa: BLE001 - GL failures surface as many exception types
        backend = os.environ.get("MUJOCO_GL", "(unset)")
        raise RenderError(
            f"no OpenGL context for offscreen rendering (MUJOCO_GL={backend}): {err}. "
            "Try MUJOCO_GL=egl or MUJOCO_GL=osmesa."
        ) from None


def look_at(model: mujoco.MjModel, data: mujoco.MjData) -> mujoco.MjvCamera:
    """A free camera looking at the robot from the front-left, above."""
    robot_bodies = [
        i for i in range(1, model.nbody) if model.body_rootid[i] == model.body("brain").id
    ]
    points = data.xpos[robot_bodies]
    centre = points.mean(axis=0)
    extent = float(np.max(np.linalg.norm(points - centre, axis=1))) + 0.08
    camera = mujoco.MjvCamera()
    camera.type = mujoco.mjtCamera.mjCAMERA_FREE
    camera.lookat[:] = centre
    camera.distance = max(0.35, 3.2 * extent)
    camera.azimuth = 135.0
    camera.elevation = -28.0
    return camera


def render_image(
    robot: Robot,
    width: int = 640,
    height: int = 480,
    params: PhysicsParams | None = None,
    settle_seconds: float = 0.5,
) -> npt.NDArray[np.uint8]:
    """An RGB picture of the robot resting on the floor after ``settle_seconds``."""
    model = build(robot, params).compile()
    data = mujoco.MjData(model)
    for _ in range(int(settle_seconds / model.opt.timestep)):
        mujoco.mj_step(model, data)
    renderer = make_renderer(model, width, height)
    try:
        renderer.update_scene(data, camera=look_at(model, data))
        image: npt.NDArray[np.uint8] = renderer.render().copy()
        return image
    finally:
        renderer.close()


def render_png(robot: Robot, out: Path, width: int = 640, height: int = 480) -> Path:
    """Save a picture of the robot as PNG and return its path."""
    import matplotlib.image

    out.parent.mkdir(parents=True, exist_ok=True)
    matplotlib.image.imsave(out, render_image(robot, width, height))
    return out
