"""The config edge: Hydra's ``DictConfig`` in, typed dataclasses out.

Below ``evo/main.py`` nothing sees a ``DictConfig``. ``typed`` builds one dataclass from
one config node and turns every mistake (an unknown key, a wrong type, a value a
dataclass rejects) into a ``ConfigError`` that names the full key, so a bad value fails
at start with a message a user can act on.

Every swappable part (learner, structure strategy, selection, replacement, schedule,
mutation operators, executor) is chosen one way: its node names a frozen dataclass with
``_target_`` and its other keys are that class's fields. ``typed`` builds such a node
wherever it meets one, as the class the field (or the caller) expects or a subclass of
it. ``current`` turns the forms older evo wrote into a run directory's ``config.yaml``
into today's, and keeps them as shorthands of the command line (``ga.structure=E|R``,
mutation operators by name).
"""

from __future__ import annotations

import copy
import dataclasses
import types
import typing
from collections.abc import Mapping
from pathlib import Path
from typing import Any, TypeVar

from omegaconf import DictConfig, ListConfig, OmegaConf, open_dict

T = TypeVar("T")

CONF_DIR = Path(__file__).resolve().parents[1] / "conf"
"""The Hydra config tree (``conf/`` at the repository root)."""


class ConfigError(ValueError):
    """A config value is missing, unknown or out of range; the message names the key."""


def _number(value: Any, key: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ConfigError(f"{key}: expected a number, got {value!r}")
    return float(value)


def _integer(value: Any, key: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise ConfigError(f"{key}: expected an integer, got {value!r}")
    return value


def _flag(value: Any, key: str) -> bool:
    if not isinstance(value, bool):
        raise ConfigError(f"{key}: expected true or false, got {value!r}")
    return value


def _text(value: Any, key: str) -> str:
    if not isinstance(value, str):
        raise ConfigError(f"{key}: expected a string, got {value!r}")
    return value


SCALARS: dict[Any, Any] = {float: _number, int: _integer, bool: _flag, str: _text}
"""The check and conversion of each scalar type a dataclass field may declare."""


def _items(value: Any, hint: Any, key: str) -> tuple[Any, ...]:
    """A list as the tuple a ``tuple[...]`` field declares, each item coerced."""
    if not isinstance(value, list | tuple):
        raise ConfigError(f"{key}: expected a list, got {value!r}")
    args = typing.get_args(hint)
    if len(args) > 1 and args[1] is not Ellipsis:  # tuple[int, float]: one hint each
        if len(value) != len(args):
            raise ConfigError(f"{key}: expected {len(args)} values, got {len(value)}")
        hints = list(args)
    else:  # tuple[int, ...]
        hints = [args[0] if args else Any] * len(value)
    return tuple(_coerce(v, h, f"{key}[{i}]") for i, (v, h) in enumerate(zip(value, hints,
                                                                              strict=True)))


def _coerce(value: Any, hint: Any, key: str) -> Any:
    """Turn a plain config value into the type a dataclass field declares: a dataclass,
    a tuple, one of :data:`SCALARS`, or an optional one of them (``None`` or it)."""
    if isinstance(value, DictConfig | ListConfig):
        value = OmegaConf.to_container(value, resolve=True)
    if dataclasses.is_dataclass(hint) and isinstance(hint, type):
        return value if isinstance(value, hint) else typed(hint, value, key)
    if typing.get_origin(hint) is tuple:
        return _items(value, hint, key)
    if isinstance(hint, types.UnionType) and type(None) in typing.get_args(hint):
        if value is None:
            return None
        inner = [a for a in typing.get_args(hint) if a is not type(None)]
        return _coerce(value, inner[0], key) if len(inner) == 1 else value
    check = SCALARS.get(hint)
    return value if check is None else check(value, key)


def typed(cls: type[T], node: DictConfig | Mapping[str, Any] | None, key: str) -> T:
    """Build dataclass ``cls`` from the config ``node`` found at ``key``.

    A node with ``_target_`` is built as the class it names (:func:`instantiate`),
    which must be ``cls`` or a subclass; so is every nested one.

    Args:
        cls: A dataclass whose fields all have defaults or appear in ``node``.
        node: The config mapping (``None`` means all defaults).
        key: Dotted path of ``node`` in the whole config, used in error messages.

    Returns:
        The dataclass instance.

    Raises:
        ConfigError: naming ``key.field`` for an unknown key, a wrong type, or a value
            that the dataclass's own checks reject.
    """
    if isinstance(node, DictConfig | Mapping) and "_target_" in node:
        return _built(cls, node, key)
    raw: dict[str, object] = {}
    if node is not None:
        plain = OmegaConf.to_container(node, resolve=True) if isinstance(node, DictConfig) else node
        if not isinstance(plain, Mapping):
            raise ConfigError(f"{key}: expected a mapping, got {plain!r}")
        raw = {str(k): v for k, v in plain.items()}
    assert dataclasses.is_dataclass(cls)
    fields = {f.name: f for f in dataclasses.fields(cls)}
    unknown = sorted(set(raw) - set(fields))
    if unknown:
        raise ConfigError(
            f"{key}: unknown key(s) {', '.join(unknown)}; expected some of {', '.join(fields)}"
        )
    hints = typing.get_type_hints(cls)
    kwargs = {name: _coerce(v, hints[name], f"{key}.{name}") for name, v in raw.items()}
    try:
        return cls(**kwargs)
    except ConfigError:
        raise
    except (ValueError, TypeError) as err:
        # "field: what is wrong" from the dataclass's own checks names key.field
        name = str(err).partition(":")[0]
        raise ConfigError(f"{key}.{err}" if name in fields else f"{key}: {err}") from None


def _built(cls: type[T], node: DictConfig | Mapping[str, Any], key: str) -> T:
    """The object ``node`` names with ``_target_``: ``cls`` or a subclass of it, its
    fields from the node's other keys."""
    from hydra.utils import get_class

    target = node.get("_target_")
    if not isinstance(target, str):
        raise ConfigError(f"{key}: expected a mapping with a _target_ class")
    try:
        named = get_class(target)
    except Exception:  # noqa: BLE001 - hydra raises several kinds for a bad path
        raise ConfigError(f"{key}._target_: no class {target!r}") from None
    if not issubclass(named, cls):
        raise ConfigError(f"{key}._target_: expected a {cls.__name__} (or a subclass), "
                          f"got {named.__name__}")
    plain = OmegaConf.to_container(node, resolve=True) if isinstance(node, DictConfig) else node
    assert isinstance(plain, Mapping)
    built: T = typed(named, {str(k): v for k, v in plain.items() if k != "_target_"}, key)
    return built


def instantiate(node: DictConfig | Mapping[str, Any], key: str) -> Any:
    """The object a config node with ``_target_`` describes, built through ``typed``.

    The class comes from ``_target_`` (a dataclass); the other keys are its fields, so
    mistakes are reported as for ``typed``, naming ``key.field``.
    """
    if not isinstance(node, DictConfig | Mapping):
        raise ConfigError(f"{key}: expected a mapping with a _target_ class")
    return _built(object, node, key)


STRUCTURE_LETTERS: dict[str, str] = {
    "E": "evo.components.ga.EvolveChoice",
    "R": "evo.components.ga.RandomChoice",
}
"""The letters ``ga.structure`` may also be given as (the method name's first letter:
``ga.structure=R`` on the command line, the ablation's sweep, an older ``config.yaml``)
and the class each stands for."""

def structure_letter(structure: Any) -> str:
    """The letter of a ``ga.structure`` value in either form (a letter, or a node whose
    ``_target_`` is a class of :data:`STRUCTURE_LETTERS`; ``?`` for another class)."""
    if isinstance(structure, DictConfig | Mapping):
        letters = {target: letter for letter, target in STRUCTURE_LETTERS.items()}
        return letters.get(str(structure.get("_target_")), "?")
    return str(structure)


def inherits(inheritance: object) -> bool:
    """Whether a ``ga.inheritance`` value turns policy inheritance on: anything but
    ``"off"``, or what YAML and an older config make of it (a bare ``off`` reads as
    false; a config from before the key, None)."""
    return inheritance not in ("off", False, None)


def method_label(structure: str, learns: bool, inheritance: object = "off") -> str:
    """The ablation's method name (paper section 8): ``E+L``, ``E+R``, ``R+L`` or ``R+R``,
    from the structure's letter (:func:`structure_letter`) and whether the policy learns;
    ``+I`` after it (``E+L+I``) when offspring inherit a parent's policy.

    Args:
        structure: The structure's letter, ``E`` or ``R``.
        learns: Whether the policy learns (``learner.update``).
        inheritance: ``ga.inheritance`` (:func:`inherits`); the default, off, gives the
            four labels of the paper, so runs made before inheritance keep theirs.
    """
    return f"{structure}+{'L' if learns else 'R'}{'+I' if inherits(inheritance) else ''}"


OLD_LEARNERS: dict[str, str] = {"ppo": "evo.learners.ppo.PPO", "random": "evo.learners.ppo.PPO"}
"""The ``learner.name`` of an older ``config.yaml`` and the class it stands for (its
``update`` key, kept, says whether the policy learns)."""


def current(cfg: DictConfig) -> DictConfig:
    """``cfg`` in today's form: a run directory's ``config.yaml`` written by an older evo
    resumes, and the shorthands ``ga.structure=E|R`` and
    ``ga.mutation_operators=[<name>, ...]`` keep working.

    * ``ga.structure`` given as a letter of :data:`STRUCTURE_LETTERS` becomes
      ``{_target_: <its class>}``;
    * ``ga.mutation_operators`` given by name (a key of
      :data:`evo.robot.operators.MUTATIONS`) become ``{_target_: <its class>}``;
    * a ``learner`` without ``_target_`` (``name: ppo|random`` and ``update``) becomes
      the class :data:`OLD_LEARNERS` names, with its other keys, ``update`` included;
    * a ``noise_ceiling`` node (the retrain task's keys before they were ``retrain``'s)
      becomes ``retrain``, without ``resamples`` (the report's, not the trainings');
    * an ``env.task`` without ``_target_`` (before tasks were plug-ins) is the reach
      task, :data:`OLD_TASK`.

    A config in today's form comes back as it was (a copy; ``cfg`` is left alone).

    Raises:
        ConfigError: For a letter or name that stands for nothing.
    """
    out = copy.deepcopy(cfg)
    with open_dict(out):
        ga = out.get("ga")
        if isinstance(ga, DictConfig) and isinstance(ga.get("structure"), str):
            letter = ga.structure
            if letter not in STRUCTURE_LETTERS:
                raise ConfigError(f"ga.structure: expected E (evolve) or R (random), got "
                                  f"{letter!r}")
            ga.structure = {"_target_": STRUCTURE_LETTERS[letter]}
        if isinstance(ga, DictConfig) and isinstance(ga.get("mutation_operators"), ListConfig):
            ga.mutation_operators = [_mutation(op, f"ga.mutation_operators[{i}]")
                                     for i, op in enumerate(ga.mutation_operators)]
        learner = out.get("learner")
        if isinstance(learner, DictConfig) and "_target_" not in learner:
            name = learner.pop("name", "ppo")
            if name not in OLD_LEARNERS:
                raise ConfigError(f"learner.name: unknown learner {name!r}; expected one of "
                                  f"{', '.join(OLD_LEARNERS)}")
            learner._target_ = OLD_LEARNERS[name]
        env = out.get("env")
        if isinstance(env, DictConfig) and isinstance(env.get("task"), DictConfig) and (
                "_target_" not in env.task):
            env.task._target_ = OLD_TASK
        older = out.pop(OLD_RETRAIN, None)
        if isinstance(older, DictConfig) and "retrain" not in out:
            older.pop("resamples", None)
            out.retrain = older
    return out


OLD_TASK = "evo.envs.tasks.reach.Reach"
"""The task of an ``env.task`` node without ``_target_`` (a config of before tasks were
plug-ins)."""

OLD_RETRAIN = "noise_ceiling"
"""The retrain task's config node before it was ``retrain`` (an older ``config.yaml``,
and the command line's older spelling: ``noise_ceiling.random=24``)."""


def older_overrides(overrides: list[str]) -> list[str]:
    """The command line with the older spelling of the retrain task's keys in today's:
    ``noise_ceiling.<key>=...`` becomes ``retrain.<key>=...``; ``noise_ceiling.resamples``,
    the report's, is dropped (``python -m analysis.noise_ceiling DIR --resamples R``)."""
    kept = []
    for override in overrides:
        key, sep, value = override.partition("=")
        if sep and key.startswith(f"{OLD_RETRAIN}."):
            if key == f"{OLD_RETRAIN}.resamples":
                continue
            override = f"retrain.{key.removeprefix(OLD_RETRAIN + '.')}={value}"
        kept.append(override)
    return kept


def _mutation(op: Any, key: str) -> Any:
    """A mutation operator of ``ga.mutation_operators``: a name becomes the node of its
    class; a node is left as it is."""
    from evo.robot.operators import MUTATIONS

    if not isinstance(op, str):
        return op
    if op not in MUTATIONS:
        raise ConfigError(f"{key}: unknown mutation operator {op!r}; expected one of "
                          f"{', '.join(MUTATIONS)}")
    cls = type(MUTATIONS[op])
    return {"_target_": f"{cls.__module__}.{cls.__qualname__}"}


def swappable(field: dataclasses.Field[Any]) -> bool:
    """Whether a dataclass field is a swappable part (:data:`SWAPPABLE`)."""
    return bool(field.metadata.get("swappable", False))
