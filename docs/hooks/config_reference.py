"""MkDocs hook: the configuration reference, generated when the site is built.

The page ``guide/config-reference.md`` holds the marker ``<!-- config-reference -->``;
this hook puts there, for every key of the config ``python evo/main.py`` composes
(``conf/``, and each task's keys with ``env/task=<name>``): its default, the range its
dataclass's checks accept and what it means (the ``Attributes:`` of the dataclass that
the key builds, units included). The range is read from the checks themselves: the key
is set far below and far above its default and the message each value is refused with
is quoted (:func:`evo.edge.typed_config`), so the page cannot say other than the code.
"""

from __future__ import annotations

import dataclasses
import inspect
import re
import warnings
from collections.abc import Iterator
from typing import Any

MARKER = "<!-- config-reference -->"
TASKS = ("reach", "locomotion", "push", "rough")
SKIPPED = ("hydra", "yaml", "training_yaml")
"""Top-level keys that are no settings (Hydra's own, and the texts a run writes)."""


def on_page_markdown(markdown: str, **_: Any) -> str:
    """Fill the marker with the reference tables (the libraries' warnings on import,
    which MkDocs would print with their stacks, are not the site's)."""
    if MARKER not in markdown:
        return markdown
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return markdown.replace(MARKER, reference())


def reference() -> str:
    """The reference: one table per top-level group, then one per task's keys."""
    from evo.edge import compose_config, typed_config

    base = compose_config([])
    rows = list(_rows(base, typed_config(base), exclude="env.task."))
    parts = []
    for group in dict.fromkeys(_group(key) for key, *_ in rows):
        mine = [r for r in rows if _group(r[0]) == group]
        parts.append(_table(f"`{group}`" if group else "Top level", mine))
    for task in TASKS:
        cfg = compose_config([f"env/task={task}"])
        mine = list(_rows(cfg, typed_config(cfg), only="env.task."))
        parts.append(_table(f"`env.task` with `env/task={task}`", mine))
    return "\n".join(parts)


def _group(key: str) -> str:
    """A key's group: its first part, or "" for a top-level key."""
    return key.split(".")[0] if "." in key else ""


def _table(title: str, rows: list[tuple[str, str, str, str]]) -> str:
    lines = [f"## {title}", "", "| key | default | range | meaning |", "|---|---|---|---|"]
    lines += [f"| `{k}` | `{d}` | {r} | {m} |" for k, d, r, m in rows]
    return "\n".join(lines) + "\n"


def _rows(cfg: Any, typed: Any, exclude: str = "",
          only: str = "") -> Iterator[tuple[str, str, str, str]]:
    """(key, default, range, meaning) of every leaf of ``cfg`` (those under ``only``,
    none under ``exclude``)."""
    for key, value in _leaves(cfg):
        if (key.split(".")[0] in SKIPPED or (exclude and key.startswith(exclude))
                or not key.startswith(only)):
            continue
        yield (key, _shown(value), _range(cfg, key, value),
               _meaning(typed, key).replace("|", "\\|").replace("\n", " "))


def _leaves(node: Any, prefix: str = "") -> Iterator[tuple[str, Any]]:
    from omegaconf import DictConfig

    for k, v in node.items():
        if isinstance(v, DictConfig) and v:
            yield from _leaves(v, f"{prefix}{k}.")
        elif k != "_target_" or not prefix.count("."):
            yield f"{prefix}{k}", v


def _shown(value: Any) -> str:
    from omegaconf import OmegaConf

    if OmegaConf.is_config(value):
        value = OmegaConf.to_container(value)
    return str(value).replace("|", "\\|")


def _range(cfg: Any, key: str, value: Any) -> str:
    """What the checks say of a value far below and far above the default (numbers):
    the messages about this key (a check of two keys together is kept where it names
    this one; one about another key that this value upsets is not this key's range)."""
    from omegaconf import OmegaConf

    from evo.config import ConfigError
    from evo.edge import typed_config

    if isinstance(value, bool) or not isinstance(value, int | float):
        return ""
    said = []
    for probe in (-(10**9), 10**9):
        changed = cfg.copy()
        OmegaConf.update(changed, key, probe if isinstance(value, int) else float(probe))
        try:
            typed_config(changed)
        except (ConfigError, ValueError) as err:
            text = re.sub(r"^[\w.]+: ", "", str(err).splitlines()[0])
            name = key.rsplit(".", 1)[-1]
            if text.startswith(name) or (text.startswith("need") and name in text):
                text = re.sub(r" \(-?1000000000(\.0)?( m)?\)", "", text)  # the probe
                said.append(re.sub(r",? got .*$", "", text))
    return "; ".join(dict.fromkeys(said)).replace("|", "\\|") or "any"


def _meaning(typed: Any, key: str) -> str:
    """The ``Attributes:`` entry of the field ``key`` names, from its dataclass."""
    path = key.split(".")
    for start in (0, 1):  # morphology.physics.x is the typed config's physics.x
        owner = typed
        try:
            for name in path[start:-1]:
                owner = getattr(owner, name)
        except AttributeError:
            continue
        if dataclasses.is_dataclass(owner):
            return _attributes(type(owner)).get(path[-1], "")
    return ""


def _attributes(cls: type) -> dict[str, str]:
    """Field name -> its description, from the Google-style docstrings of ``cls`` and
    the classes it inherits from (the nearest first)."""
    from griffe import Docstring

    found: dict[str, str] = {}
    for klass in cls.__mro__:
        doc = inspect.getdoc(klass) if klass.__doc__ else None
        if not doc or klass is object:
            continue
        for section in Docstring(doc).parse("google", warnings=False):
            if section.kind.value == "attributes":
                for item in section.value:
                    found.setdefault(item.name, item.description)
    return found
