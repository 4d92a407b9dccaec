"""Replays as rerun files: episodes played back from a saved policy (``evo.replay``).

Played episodes (``evo.learners.rollouts.play``) are written like an evaluation's
recorded episodes: same entities, same blueprint, one after another on ``replay``,
numbered in the order given.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from pathlib import Path

import mujoco

from evo.episode import Episode
from evo.record.rrd import RerunRecorder
from evo.robot.tree import Robot


def write_replay_rrd(
    model: mujoco.MjModel, robot: Robot | None, episodes: Sequence[Episode], path: str | Path
) -> Path:
    """Write ``episodes`` of ``robot`` in the scene ``model`` to the ``.rrd`` file ``path``.

    Args:
        model: The compiled scene the episodes were played in.
        robot: The robot (its name and JSON go into the metadata), if known.
        episodes: The played episodes, in order.
        path: The file to create.

    Returns:
        The path written.
    """
    metadata = {} if robot is None else {"name": robot.name, "robot": robot.to_json()}
    with RerunRecorder(path, model, metadata, still_tolerance=0.0) as rec:
        for i, episode in enumerate(episodes):
            rec.episode(dataclasses.replace(episode, index=i))
    return Path(path)
