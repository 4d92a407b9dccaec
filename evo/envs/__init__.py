"""Simulation environments: the reach-the-target task (SPEC section 3).

Importing this package registers the gymnasium id ``evo/Reach-v0``
(``evo.envs.gym_env.ReachGymEnv``). The batched TorchRL env is
``evo.envs.reach.ReachEnv``; both run the task code of ``evo.envs.task``.
"""

import gymnasium

ENV_ID = "evo/Reach-v0"

if ENV_ID not in gymnasium.registry:
    gymnasium.register(id=ENV_ID, entry_point="evo.envs.gym_env:ReachGymEnv")
