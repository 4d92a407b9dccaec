"""One episode of one arena, frame by frame: what the task traces and the recorders write.

The environment's tracer (``TaskCore.watch``) and the replays (``evo.learners.rollouts.play``)
produce episodes; the MCAP and rerun recorders write them, ``evo.record.read_episodes``
reads them back, and ``evo.replay`` redraws them from ``qpos``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

F64 = npt.NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class Episode:
    """One episode of one arena, at control-step resolution (frame 0 = the reset).

    Compared by identity (its fields are arrays); compare fields with numpy.

    Attributes:
        index: Episode number within the evaluation (0 = first).
        env_step: The learner's env-step counter when the episode ended.
        time: (T,) sim time of every frame, s, strictly increasing unless ``unstable``.
        xpos: (T, nbody, 3) every body's world position (MuJoCo ``data.xpos``).
        xquat: (T, nbody, 4) every body's orientation, w x y z (``data.xquat``).
        target: (3,) target position in the world, m.
        rewards: Reward term name -> (T,) value of that term at each frame (0 at frame 0).
        success: Whether the episode reached the target.
        qpos: (T, nq) joint positions, when traced: with the target, enough to redraw
            every frame. Recordings do not keep them (``None`` when read back).
        unstable: The episode ended in a numerical blow-up (MuJoCo reset the arena, so
            time jumps back at the last frame); such episodes are counted, never recorded.
    """

    index: int
    env_step: int
    time: F64
    xpos: F64
    xquat: F64
    target: F64
    rewards: Mapping[str, F64] = field(default_factory=dict)
    success: bool = False
    qpos: F64 | None = None
    unstable: bool = False

    def __post_init__(self) -> None:
        t = self.time.shape[0] if self.time.ndim == 1 else -1
        if t < 1:
            raise ValueError(f"episode {self.index}: time must be a non-empty (T,) array")
        if self.xpos.ndim != 3 or self.xpos.shape[0] != t or self.xpos.shape[2] != 3:
            raise ValueError(
                f"episode {self.index}: xpos must be (T={t}, nbody, 3), got {self.xpos.shape}"
            )
        if self.xquat.shape != (*self.xpos.shape[:2], 4):
            raise ValueError(
                f"episode {self.index}: xquat must be {(*self.xpos.shape[:2], 4)},"
                f" got {self.xquat.shape}"
            )
        if np.shape(self.target) != (3,):
            raise ValueError(
                f"episode {self.index}: target must be (3,), got {np.shape(self.target)}"
            )
        for name, values in self.rewards.items():
            if np.shape(values) != (t,):
                raise ValueError(
                    f"episode {self.index}: reward {name!r} must be (T={t},), got "
                    f"{np.shape(values)}"
                )
        if self.qpos is not None and (self.qpos.ndim != 2 or self.qpos.shape[0] != t):
            raise ValueError(
                f"episode {self.index}: qpos must be (T={t}, nq), got {self.qpos.shape}"
            )
        if t > 1 and not self.unstable and not np.all(np.diff(self.time) > 0):
            raise ValueError(f"episode {self.index}: time must be strictly increasing")

    @property
    def frames(self) -> int:
        """Number of frames T."""
        return int(self.time.shape[0])

    @property
    def nbody(self) -> int:
        """Number of bodies (world included)."""
        return int(self.xpos.shape[1])

    @property
    def total_return(self) -> float:
        """Sum of every reward term over the episode."""
        return float(sum(np.sum(v) for v in self.rewards.values()))

    def strided(self, stride: int) -> Episode:
        """Every ``stride``-th frame, the last frame always kept.

        Each kept frame carries the rewards summed over the frames since the previous
        kept one, so the episode's return and its final success bonus are preserved.

        Args:
            stride: Keep one frame in ``stride`` (1 returns ``self``).
        """
        if stride < 1:
            raise ValueError(f"frame stride must be >= 1, got {stride}")
        if stride == 1 or self.frames <= 1:
            return self
        keep = np.arange(0, self.frames, stride)
        if keep[-1] != self.frames - 1:
            keep = np.append(keep, self.frames - 1)
        starts = np.concatenate(([0], keep[:-1] + 1))
        rewards = {
            k: np.add.reduceat(np.asarray(v, np.float64), starts) for k, v in self.rewards.items()
        }
        return Episode(
            self.index,
            self.env_step,
            self.time[keep],
            self.xpos[keep],
            self.xquat[keep],
            self.target,
            rewards,
            self.success,
            None if self.qpos is None else self.qpos[keep],
            self.unstable,
        )
