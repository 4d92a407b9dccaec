"""Every config default is written once, as a dataclass field's default (``evo.schemas``).

The ``conf/`` files of the groups that build dataclasses start from the node
``evo.schemas`` makes of the class's defaults (``/evo/<group>/<option>`` in their defaults
list, or another option of their group that does) and say only what they choose:
``_target_``s, and values that differ. :func:`restatements` reads the files as they are,
so a default copied back into one fails :func:`test_no_conf_file_restates_a_default`.
Files that start from no node set values on purpose and are not checked: the
experiments pin their regimes, and ``physics_step=dt5ms_x10`` names today's pair.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from hydra import compose, initialize_config_dir
from hydra.errors import ConfigCompositionException
from omegaconf import DictConfig, OmegaConf

from evo.components.executors import LocalExecutor, RayExecutor, SerialExecutor
from evo.components.ga import GAConfig
from evo.config import typed
from evo.envs.params import EnvConfig
from evo.learners.ppo import PPO
from evo.record.config import RecordConfig
from evo.retrain import RetrainConfig
from evo.robot.builder import PhysicsParams
from evo.robot.operators import GeneratorParams
from evo.robot.validate import Limits
from evo.schemas import ROOT, defaults_node, schemas

CONF = Path(__file__).resolve().parents[1] / "conf"


@pytest.fixture(scope="module")
def hydra_conf() -> Iterator[None]:
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        yield


# ---- the check --------------------------------------------------------------------------


def bases(path: Path, nodes: dict[str, Any]) -> list[tuple[str, str, Any]]:
    """(package, node path, node) of every ``evo.schemas`` node the file at ``path``
    starts from: named in its defaults list (``/evo/learner/ppo@_here_``), or through
    another option of its own group it names (``ppo``). The package is relative to the
    file's own ("" for ``_here_``)."""
    doc = OmegaConf.load(path)
    found = []
    for entry in doc.get("defaults", []) if isinstance(doc, DictConfig) else []:
        if not isinstance(entry, str) or entry == "_self_":
            continue  # a group's option ({structure: evolve}, {override ...: ...})
        name, _, package = entry.partition("@")
        package = "" if package in ("", "_here_") else package
        if name.startswith(f"/{ROOT}/"):
            node_path = name.removeprefix(f"/{ROOT}/")
            found.append((package, node_path, nodes[node_path]))
        elif "/" not in name:  # another option of the same group, which may start from one
            found += [(".".join(p for p in (package, inner) if p), node_path, node)
                      for inner, node_path, node in bases(path.with_name(f"{name}.yaml"), nodes)]
    return found


def _names_classes_only(value: Any) -> bool:
    """A node that only names a class, or a list of them (``mutation_operators``): a
    choice the file makes visible, not a copied default."""
    if isinstance(value, list):
        return bool(value) and all(_names_classes_only(item) for item in value)
    return isinstance(value, dict) and set(value) == {"_target_"}


def restated(mine: Any, default: Any, where: str) -> Iterator[str]:
    """``where: value`` of every value of ``mine`` equal to ``default``'s at its place."""
    if isinstance(mine, dict) and isinstance(default, dict):
        if mine.get("_target_", default.get("_target_")) != default.get("_target_"):
            return  # another class: its defaults are not these
        for key, value in mine.items():
            if key != "_target_" and key in default:
                yield from restated(value, default[key], f"{where}.{key}" if where else key)
    elif not _names_classes_only(mine) and mine == default:
        yield f"{where}: {mine!r}"


def restatements(conf: Path, nodes: dict[str, Any]) -> list[str]:
    """Every value a file of ``conf`` sets to the default of the node it starts from."""
    found = []
    for path in sorted(conf.rglob("*.yaml")):
        own = OmegaConf.to_container(OmegaConf.load(path))
        assert isinstance(own, dict)
        own.pop("defaults", None)
        for package, node_path, node in bases(path, nodes):
            mine = OmegaConf.select(OmegaConf.create(own), package) if package else own
            if isinstance(mine, DictConfig):
                mine = OmegaConf.to_container(mine)
            found += [f"{path.relative_to(conf)}: {line} (the default in /{ROOT}/{node_path})"
                      for line in restated(mine, node, package)]
    return found


def test_the_check_finds_a_restated_default(tmp_path: Path) -> None:
    nodes = {"learner/ppo": {"_target_": "x.PPO", "lr": 3e-4, "hidden": [128, 128],
                             "part": {"_target_": "x.A", "k": 1}}}
    (tmp_path / "learner").mkdir()
    (tmp_path / "learner" / "ppo.yaml").write_text(
        "defaults:\n  - /evo/learner/ppo@_here_\n  - _self_\n_target_: x.PPO\n"
        "lr: 3.0e-4\nhidden: [64, 64]\npart: {_target_: x.A, k: 1}\n")
    (tmp_path / "learner" / "slow.yaml").write_text(
        "defaults:\n  - ppo\n  - _self_\nlr: 1.0e-4\nhidden: [128, 128]\n"
        "part: {_target_: x.B, k: 1}\n")
    assert restatements(tmp_path, nodes) == [
        "learner/ppo.yaml: lr: 0.0003 (the default in /evo/learner/ppo)",
        "learner/ppo.yaml: part.k: 1 (the default in /evo/learner/ppo)",
        "learner/slow.yaml: hidden: [128, 128] (the default in /evo/learner/ppo)",
    ]


# ---- conf/ as it is ---------------------------------------------------------------------


def test_no_conf_file_restates_a_default() -> None:
    found = restatements(CONF, schemas())
    assert found == [], ("conf/ files that restate a dataclass default (drop the key: the "
                         "default is the field's, in evo.schemas' node):\n" + "\n".join(found))


def test_every_option_of_a_group_with_defaults_starts_from_them() -> None:
    nodes = schemas()
    groups = {path.rpartition("/")[0] for path in nodes} - {""}
    for group in sorted(groups):
        for path in sorted((CONF / group).glob("*.yaml")):
            assert bases(path, nodes), (f"conf/{group}/{path.name} starts from no node of "
                                        f"evo.schemas (- /{ROOT}/{group}/<option>@_here_)")
    used = {node_path for path in CONF.rglob("*.yaml") for _, node_path, _ in bases(path, nodes)}
    assert used == set(nodes), f"nodes no conf/ file starts from: {set(nodes) - used}"


def test_the_nodes_hold_the_dataclass_defaults() -> None:
    nodes = schemas()
    morphology = nodes["morphology/default"]
    for key, cls in (("generator", GeneratorParams), ("limits", Limits),
                     ("physics", PhysicsParams)):
        assert typed(cls, morphology[key], key) == cls(), key
    assert typed(EnvConfig, nodes["env/clean"], "env") == EnvConfig()
    assert typed(PPO, nodes["learner/ppo"], "learner") == PPO()
    assert typed(GAConfig, nodes["ga/steady_state"], "ga") == GAConfig()
    assert typed(RecordConfig, nodes["record/default"], "record") == RecordConfig()
    # Swappable parts name their class, first; other nested nodes do not.
    ga = nodes["ga/steady_state"]
    assert list(ga["selection"]) == ["_target_", "epsilon", "distinct"]
    assert [op["_target_"] for op in ga["mutation_operators"]][-1].endswith(".ChangeType")
    assert "_target_" not in ga["early_rejection"] and "structure" not in ga
    assert list(nodes["executor/serial"]) == ["_target_", "threads"]  # workers: init=False


ROOTS: tuple[type, ...] = (PPO, EnvConfig, GeneratorParams, Limits, PhysicsParams, GAConfig,
                           RecordConfig, LocalExecutor, RayExecutor, SerialExecutor,
                           RetrainConfig)
"""The classes the nodes are made from."""


def config_classes() -> set[type]:
    """:data:`ROOTS` and every dataclass their defaults hold (the arena, the GA's parts)."""
    found: set[type] = set()
    todo = list(ROOTS)
    while todo:
        cls = todo.pop()
        found.add(cls)
        for field in dataclasses.fields(cls):
            default = (field.default_factory() if field.default_factory is not dataclasses.MISSING
                       else field.default)
            for value in default if isinstance(default, tuple) else (default,):
                if dataclasses.is_dataclass(value) and type(value) not in found:
                    todo.append(type(value))
    return found


def test_every_config_key_is_described_in_its_class_docstring() -> None:
    # STYLE rule 9: the docstring is the one place a key's meaning and unit are written.
    for cls in sorted(config_classes(), key=lambda c: c.__qualname__):
        text = "".join(c.__doc__ or "" for c in cls.__mro__)
        for field in dataclasses.fields(cls):
            if field.init:
                assert f"{field.name}:" in text, f"{cls.__qualname__}.{field.name} is undescribed"


def test_a_config_key_needs_a_default() -> None:
    @dataclasses.dataclass(frozen=True)
    class Needs:
        size: int

    with pytest.raises(TypeError, match="Needs.size has no default"):
        defaults_node(Needs)


def test_options_and_overrides_work_on_keys_from_the_nodes(hydra_conf: None) -> None:
    cfg = compose("config", overrides=["learner=random", "learner.lr=0.1", "env=cluttered"])
    plain = OmegaConf.to_container(cfg, resolve=True)
    assert isinstance(plain, dict)
    learner, arena = plain["learner"], plain["env"]["arena"]
    assert learner["update"] is False and learner["lr"] == 0.1
    assert learner["gamma"] == PPO().gamma, "a key the file does not set"
    assert (arena["n_rocks"], arena["side"]) == (40, EnvConfig().arena.side)
    assert list(learner)[0] == "_target_" and list(plain["ga"])[0] == "structure"
    with pytest.raises(ConfigCompositionException, match="Could not override 'learner.teleport'"):
        compose("config", overrides=["learner.teleport=1"])
