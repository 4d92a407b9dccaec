"""Learners of the inner loop (SPEC section 4): what a learner is, and which exist.

A learner trains one robot's behaviour for a budget of env steps and returns its
fitness, learning curve and policy (:class:`Learner`). A ``conf/learner/<name>.yaml``
names its learner's config class with ``_target_``, a subclass of
:class:`evo.learners.common.LearnerConfig` whose ``train_function`` is the learner:

* ``ppo``: :class:`evo.learners.ppo.PPO`, PPO through TorchRL;
* ``random``: the same class with ``update: false``: the network at its seeded
  initialisation, never trained (the "R" behaviour of the paper's ablations).

To add a learner, write a module with a ``train`` function of the :class:`Learner`
signature and a frozen dataclass subclassing ``LearnerConfig`` whose
``train_function`` returns it and whose ``name`` labels it (new settings are its new
fields), and give it a ``conf/learner/<name>.yaml`` whose ``_target_`` names that class.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Protocol

if TYPE_CHECKING:
    from evo.envs.params import EnvConfig
    from evo.envs.scene import Scene
    from evo.episode import Episode
    from evo.learners.common import Inheritance, LearnerConfig, TrainResult
    from evo.robot.builder import PhysicsParams
    from evo.robot.tree import Robot

CurveHook = Callable[[dict[str, float]], bool | None]
"""Called with every learning-curve row as soon as it exists (recorders, progress, early
rejection); returning True asks training to stop after this batch."""

EpisodeHook = Callable[["Episode"], None]
"""Called with every finished episode of arena 0 (numbered, with the env-step count at
its end)."""


class Learner(Protocol):
    """Trains ``robot``'s behaviour for ``budget`` env steps; randomness only from
    ``seed``. ``on_curve`` gets every curve row, ``on_episode`` every episode of arena 0;
    with ``start`` the networks begin as a parent's (``ga.inheritance``). ``scene`` is the
    robot's arena compiled by the caller (``evo.evaluation`` compiles it once for its
    recorders, the learner and the recorded episode); a learner compiles its own when it
    is None."""

    def __call__(
        self,
        robot: Robot,
        *,
        physics: PhysicsParams,
        env: EnvConfig,
        config: LearnerConfig,
        budget: int,
        seed: int,
        on_curve: CurveHook | None = None,
        on_episode: EpisodeHook | None = None,
        start: Inheritance | None = None,
        scene: Scene | None = None,
    ) -> TrainResult: ...
