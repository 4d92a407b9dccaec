"""The defaults of the config groups, read from the dataclasses the groups build.

A config default is written once: as the default of the dataclass field its key builds,
whose class docstring says what the field means and its unit. Before Hydra composes a
config, :func:`register_schemas` stores one node per such group option in Hydra's
``ConfigStore``, under ``evo/`` (:data:`ROOT`), made from the class's field defaults.
The option's YAML file starts from that node and says only what it chooses, its
``_target_``, and the values that differ::

    # conf/learner/ppo.yaml
    defaults:
      - /evo/learner/ppo@_here_
      - _self_
    _target_: evo.learners.ppo.PPO

A node holds each default as YAML would: a tuple as a list, a nested dataclass as a
nested node, with ``_target_`` first at the top where the option chooses a class (the
learner, the executors) and in every swappable part (:data:`evo.config.SWAPPABLE`:
``ga.selection``, ``ga.mutation_operators``, ...). A field the constructor does not take
(``init=False``) is no config key. The nodes are plain mappings, not structured
configs: Hydra checks no types, and :func:`evo.config.typed` checks every value as it
checks one a YAML file sets, naming its key.

``python evo/main.py`` and :func:`evo.edge.compose_config` register before they compose,
and so must anything else that composes ``conf/`` (the tests do, in ``conftest.py``).
``python evo/main.py --cfg job`` prints the composed config: every key and its value.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Collection
from typing import Any

from evo.config import swappable

ROOT = "evo"
"""The ``ConfigStore`` group that holds the nodes: ``/evo/<group>/<option>`` in a
defaults list (``/evo/retrain`` for the ``retrain`` node of ``+exp=retrain``)."""


def class_path(cls: type) -> str:
    """The dotted path ``_target_`` names ``cls`` by."""
    return f"{cls.__module__}.{cls.__qualname__}"


def defaults_node(cls: type, *, target: bool = False,
                  omit: Collection[str] = ()) -> dict[str, Any]:
    """The config node of dataclass ``cls`` with every field at its default.

    Args:
        cls: The dataclass; every field the constructor takes needs a default.
        target: Start the node with ``_target_: <cls>`` (the option chooses the class).
        omit: Fields left out (another config group sets them).

    Raises:
        TypeError: For a field without a default: a config key needs one.
    """
    node: dict[str, Any] = {"_target_": class_path(cls)} if target else {}
    for field in dataclasses.fields(cls):
        if field.init and field.name not in omit:
            node[field.name] = _plain(_default(cls, field), swappable(field))
    return node


def _default(cls: type, field: dataclasses.Field[Any]) -> Any:
    """A field's default, without building the class (whose checks may start things)."""
    if field.default is not dataclasses.MISSING:
        return field.default
    if field.default_factory is not dataclasses.MISSING:
        return field.default_factory()
    raise TypeError(f"{cls.__name__}.{field.name} has no default; a config key needs one")


def _plain(value: Any, named: bool) -> Any:
    """``value`` as a config holds it; ``named``: a dataclass names its class."""
    if isinstance(value, tuple | list):
        return [_plain(item, named) for item in value]
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        node: dict[str, Any] = {"_target_": class_path(type(value))} if named else {}
        for field in dataclasses.fields(value):
            if field.init:
                node[field.name] = _plain(getattr(value, field.name), swappable(field))
        return node
    return value


def schemas() -> dict[str, dict[str, Any]]:
    """Every node :func:`register_schemas` stores, by its path under :data:`ROOT`: the
    option of ``conf/<group>/`` it is the defaults of, or a node of the experiments.
    The classes are imported here, so that importing this module costs nothing."""
    from evo.components.executors import LocalExecutor, RayExecutor, SerialExecutor
    from evo.components.ga import GAConfig
    from evo.envs.params import EnvConfig
    from evo.envs.tasks.locomotion import Locomotion
    from evo.envs.tasks.push import Push
    from evo.envs.tasks.reach import Reach
    from evo.envs.tasks.rough import Rough
    from evo.learners.ppo import PPO
    from evo.record.config import RecordConfig
    from evo.retrain import RetrainConfig
    from evo.robot.builder import PhysicsParams
    from evo.robot.operators import GeneratorParams
    from evo.robot.validate import Limits

    return {
        "morphology/default": {"generator": defaults_node(GeneratorParams),
                               "limits": defaults_node(Limits),
                               "physics": defaults_node(PhysicsParams)},
        # env.task is the conf/env/task group's choice.
        "env/clean": defaults_node(EnvConfig, omit=("task",)),
        "env/task/reach": defaults_node(Reach, target=True),
        "env/task/locomotion": defaults_node(Locomotion, target=True),
        "env/task/push": defaults_node(Push, target=True),
        "env/task/rough": defaults_node(Rough, target=True),
        "learner/ppo": defaults_node(PPO, target=True),
        # ga.structure is the conf/ga/structure group's choice.
        "ga/steady_state": defaults_node(GAConfig, omit=("structure",)),
        "executor/local": defaults_node(LocalExecutor, target=True),
        "executor/ray": defaults_node(RayExecutor, target=True),
        "executor/serial": defaults_node(SerialExecutor, target=True),
        "record/default": defaults_node(RecordConfig),
        "retrain": defaults_node(RetrainConfig),
    }


def register_schemas() -> None:
    """Store :func:`schemas` in Hydra's ``ConfigStore`` (again: the same nodes), so that
    the ``conf/`` files that start from them compose."""
    from hydra.core.config_store import ConfigStore

    store = ConfigStore.instance()
    for path, node in schemas().items():
        group, _, name = f"{ROOT}/{path}".rpartition("/")
        store.store(name=name, node=node, group=group, provider="evo")
