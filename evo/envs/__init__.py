"""Simulation environments: the tasks over a batch of arenas (SPEC sections 3 and 3b).

Importing this package registers a gymnasium id per task (``evo.envs.gym_env.TaskGymEnv``):
``evo/Reach-v0`` (the paper's task), ``evo/Locomotion-v0`` (in the open arena),
``evo/Push-v0`` and ``evo/Rough-v0``. The
batched TorchRL env is ``evo.envs.torchrl_env.TaskEnv``; both run the batched core of
``evo.envs.core`` under a task of ``evo.envs.tasks``.
"""

import gymnasium

from evo.envs.arena import ArenaParams
from evo.envs.tasks.locomotion import Locomotion
from evo.envs.tasks.push import Push
from evo.envs.tasks.rough import Rough

ENV_ID = "evo/Reach-v0"

TASK_IDS: dict[str, dict[str, object]] = {
    ENV_ID: {},
    "evo/Locomotion-v0": {"task": Locomotion(), "arena": "open"},
    "evo/Push-v0": {"task": Push()},
    "evo/Rough-v0": {"task": Rough(), "arena": ArenaParams(wall_height=0.2)},
}
"""Each task's gymnasium id and the keyword arguments it starts from."""

for _id, _kwargs in TASK_IDS.items():
    if _id not in gymnasium.registry:
        gymnasium.register(id=_id, entry_point="evo.envs.gym_env:TaskGymEnv", kwargs=_kwargs)
