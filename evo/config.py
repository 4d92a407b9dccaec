"""The config edge: Hydra's ``DictConfig`` in, typed dataclasses out.

Below ``evo/main.py`` nothing sees a ``DictConfig``. ``typed`` builds one dataclass from
one config node and turns every mistake (an unknown key, a wrong type, a value a
dataclass rejects) into a ``ConfigError`` that names the full key, so a bad value fails
at start with a message a user can act on.
"""

from __future__ import annotations

import dataclasses
import typing
from collections.abc import Mapping
from typing import Any, TypeVar

from omegaconf import DictConfig, ListConfig, OmegaConf

T = TypeVar("T")


class ConfigError(ValueError):
    """A config value is missing, unknown or out of range; the message names the key."""


def _coerce(value: Any, hint: Any, key: str) -> Any:
    """Turn a plain config value into the type a dataclass field declares."""
    if isinstance(value, DictConfig | ListConfig):
        value = OmegaConf.to_container(value, resolve=True)
    if dataclasses.is_dataclass(hint) and isinstance(hint, type):
        if isinstance(value, hint):
            return value
        if isinstance(value, Mapping) and "_target_" in value:
            built = instantiate(value, key)
            if not isinstance(built, hint):
                raise ConfigError(f"{key}._target_: expected a {hint.__name__} (or a "
                                  f"subclass), got {type(built).__name__}")
            return built
        return typed(hint, value, key)
    origin = typing.get_origin(hint)
    if origin is tuple:
        if not isinstance(value, list | tuple):
            raise ConfigError(f"{key}: expected a list, got {value!r}")
        args = typing.get_args(hint)
        inner = args[0] if args else Any
        if len(args) > 1 and args[1] is not Ellipsis:
            if len(value) != len(args):
                raise ConfigError(f"{key}: expected {len(args)} values, got {len(value)}")
            return tuple(
                _coerce(v, a, f"{key}[{i}]")
                for i, (v, a) in enumerate(zip(value, args, strict=True))
            )
        return tuple(_coerce(v, inner, f"{key}[{i}]") for i, v in enumerate(value))
    if hint is float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ConfigError(f"{key}: expected a number, got {value!r}")
        return float(value)
    if hint is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{key}: expected an integer, got {value!r}")
        return value
    if hint is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"{key}: expected true or false, got {value!r}")
        return value
    if hint is str and not isinstance(value, str):
        raise ConfigError(f"{key}: expected a string, got {value!r}")
    return value


def typed(cls: type[T], node: DictConfig | Mapping[str, Any] | None, key: str) -> T:
    """Build dataclass ``cls`` from the config ``node`` found at ``key``.

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
    raw: dict[str, Any] = {}
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


def instantiate(node: DictConfig | Mapping[str, Any], key: str) -> Any:
    """The object a config node with ``_target_`` describes, built through ``typed``.

    The class comes from ``_target_`` (a dataclass); the other keys are its fields, so
    mistakes are reported as for ``typed``, naming ``key.field``.
    """
    from hydra.utils import get_class

    target = node.get("_target_") if isinstance(node, DictConfig | Mapping) else None
    if not isinstance(target, str):
        raise ConfigError(f"{key}: expected a mapping with a _target_ class")
    try:
        cls = get_class(target)
    except Exception:  # noqa: BLE001 - hydra raises several kinds for a bad path
        raise ConfigError(f"{key}._target_: no class {target!r}") from None
    plain = OmegaConf.to_container(node, resolve=True) if isinstance(node, DictConfig) else node
    assert isinstance(plain, Mapping)
    fields = {str(k): v for k, v in plain.items() if k != "_target_"}
    return typed(cls, fields, key)
