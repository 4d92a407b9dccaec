"""Replays as rerun files: episodes played back from a saved policy (``evo.replay``).

Any episode record with ``time``, ``xpos``, ``xquat``, ``target``, ``rewards`` and
``success`` (the environment's traced episodes) is written like an evaluation's
recorded episodes: same entities, same blueprint, one after another on ``replay``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Protocol

import mujoco
import numpy as np
import numpy.typing as npt

from evo.record.base import Episode
from evo.record.rrd import RerunRecorder
from evo.robot.tree import Robot

F64 = npt.NDArray[np.float64]


class Played(Protocol):
    """One played episode (``evo.envs.task.Trajectory`` fits)."""

    @property
    def time(self) -> F64: ...

    @property
    def xpos(self) -> F64: ...

    @property
    def xquat(self) -> F64: ...

    @property
    def target(self) -> F64: ...

    @property
    def rewards(self) -> Mapping[str, F64]: ...

    @property
    def success(self) -> bool: ...


def as_episode(played: Played, index: int, env_step: int = 0) -> Episode:
    """``played`` as a recorder ``Episode`` numbered ``index``."""
    return Episode(
        index=index,
        env_step=env_step,
        time=np.asarray(played.time, dtype=np.float64),
        xpos=np.asarray(played.xpos, dtype=np.float64),
        xquat=np.asarray(played.xquat, dtype=np.float64),
        target=np.asarray(played.target, dtype=np.float64),
        rewards={k: np.asarray(v, dtype=np.float64) for k, v in played.rewards.items()},
        success=bool(played.success),
    )


def write_replay_rrd(
    model: mujoco.MjModel, robot: Robot | None, episodes: Sequence[Played], path: str | Path
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
        for i, played in enumerate(episodes):
            rec.episode(as_episode(played, i))
    return Path(path)
