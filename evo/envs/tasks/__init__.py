"""The tasks: what an episode asks of a robot (SPEC sections 3 and 3b).

A task is a frozen dataclass of its settings, a subclass of :class:`Task`
(``evo.envs.tasks.base``), chosen in YAML by ``_target_`` (``conf/env/task/``), and the
:class:`~evo.envs.tasks.base.Rules` it plays by over a batch of arenas: what an
episode's reset draws, the task's observation values, its named reward terms, success
and termination, and what it adds to the scene. The batched core
(``evo.envs.core.TaskCore``) and its TorchRL and gymnasium faces are shared by every task.

* ``reach`` (:class:`~evo.envs.tasks.reach.Reach`): reach a target on flat ground (the
  paper's task, ``evo/Reach-v0``);
* ``locomotion`` (:class:`~evo.envs.tasks.locomotion.Locomotion`): travel as far as
  possible along a heading in a fixed time (``evo/Locomotion-v0``);
* ``push`` (:class:`~evo.envs.tasks.push.Push`): push a box to a goal (``evo/Push-v0``);
* ``rough`` (:class:`~evo.envs.tasks.rough.Rough`): reach the target over a height field
  of bumps and steps (``evo/Rough-v0``).
"""
