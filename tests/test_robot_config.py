"""Every Hydra config composes, the robot settings become typed objects, bad values name
their key, and the robots task runs end to end in a subprocess.

The compose test walks ``conf/`` as it is, so config groups added later are covered
without editing this file.
"""

from __future__ import annotations

import importlib
import os
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from hydra import compose, initialize_config_dir
from omegaconf import DictConfig, OmegaConf

from evo.config import ConfigError, typed
from evo.robot import GeneratorParams, Limits, load_robot
from evo.robot.builder import PhysicsParams

REPO = Path(__file__).resolve().parents[1]
CONF = REPO / "conf"
ROBOT_SECTIONS: dict[str, type] = {
    "generator": GeneratorParams,
    "limits": Limits,
    "physics": PhysicsParams,
}
"""The robot settings and the dataclass each becomes at the config edge."""
OTHER_SECTIONS: dict[str, tuple[str, str]] = {
    "env": ("evo.envs.params", "EnvConfig"),
    "learner": ("evo.learners.common", "LearnerConfig"),
}
"""Other top-level sections ``evo/main.py`` types, and the dataclass of each (module, name)."""


def defaulted_groups() -> set[str]:
    """Config groups named in some defaults list (chosen with ``group=option``); a group
    file's entries are relative to its own group (``ga/``'s ``structure`` is
    ``ga/structure``) unless they start with ``/``."""
    groups: set[str] = set()
    for path in CONF.rglob("*.yaml"):
        doc = OmegaConf.load(path)
        defaults = doc.get("defaults", []) if isinstance(doc, DictConfig) else []
        here = path.parent.relative_to(CONF)
        inside = "" if here.parts[:1] in ((), ("exp",)) else f"{here.as_posix()}/"
        for entry in defaults:
            if isinstance(entry, DictConfig):
                for key in entry:
                    name = str(key).removeprefix("override ")
                    groups.add(name[1:] if name.startswith("/") else f"{inside}{name}")
    return groups


def every_option() -> list[list[str]]:
    """One override list per option of every config group under conf/."""
    defaulted = defaulted_groups()
    options: list[list[str]] = [[]]  # the base config alone
    for path in sorted(CONF.rglob("*.yaml")):
        group = path.parent.relative_to(CONF).as_posix()
        if group == ".":
            continue
        plus = "" if group in defaulted else "+"
        options.append([f"{plus}{group}={path.stem}"])
    return options


@pytest.fixture(scope="module")
def hydra_conf() -> Iterator[None]:
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        yield


def robot_key(cfg: DictConfig) -> str:
    """The top-level key holding the robot settings (generator, limits, physics)."""
    keys = [
        str(k)
        for k, v in cfg.items()
        if isinstance(v, DictConfig) and set(ROBOT_SECTIONS) <= set(v.keys())
    ]
    assert len(keys) == 1, f"expected one section with {sorted(ROBOT_SECTIONS)}, found {keys}"
    return keys[0]


def robot_settings(cfg: DictConfig) -> dict[str, Any]:
    key = robot_key(cfg)
    return {
        name: typed(cls, cfg[key][name], f"{key}.{name}") for name, cls in ROBOT_SECTIONS.items()
    }


@pytest.mark.parametrize("overrides", every_option(), ids=lambda o: " ".join(o) or "config")
def test_every_config_composes_and_types(hydra_conf: None, overrides: list[str]) -> None:
    cfg = compose("config", overrides=overrides)
    plain = OmegaConf.to_container(cfg, resolve=True)
    assert isinstance(plain, dict) and "task" in plain and "seed" in plain
    settings = robot_settings(cfg)
    assert isinstance(settings["generator"], GeneratorParams)
    assert isinstance(settings["limits"], Limits)
    assert isinstance(settings["physics"], PhysicsParams)
    for key, (module, name) in OTHER_SECTIONS.items():
        if key in cfg:
            cls = getattr(importlib.import_module(module), name)
            assert isinstance(typed(cls, cfg[key], key), cls)


def test_config_defaults_match_the_dataclass_defaults(hydra_conf: None) -> None:
    # The composed config lists every field, at the code's defaults (evo.schemas).
    cfg = compose("config")
    key = robot_key(cfg)
    for name, cls in ROBOT_SECTIONS.items():
        assert typed(cls, cfg[key][name], f"{key}.{name}") == cls(), f"{key}.{name}"
        fields = set(cls.__dataclass_fields__)  # type: ignore[attr-defined]
        assert set(cfg[key][name].keys()) == fields, f"{key}.{name} lists other fields"


@pytest.mark.parametrize(
    ("override", "where", "message"),
    [
        ("physics.wheel_radius=0.01", "physics", "wheel_radius must lie between"),
        ("generator.p_empty=2", "generator", "p_empty must be a probability"),
        ("+generator.colour=red", "generator", "unknown key(s) colour"),
        ("limits.max_depth=deep", "limits.max_depth", "expected an integer, got 'deep'"),
        ("limits.max_modules=true", "limits.max_modules", "expected an integer, got True"),
        ("physics.friction=[1.0,0.1]", "physics.friction", "expected 3 values, got 2"),
        ("physics.module_mass=heavy", "physics.module_mass", "expected a number"),
        ("generator.type_weights=[1,1,-1]", "generator", "type_weights must be 3"),
    ],
)
def test_bad_robot_values_name_their_key(
    hydra_conf: None, override: str, where: str, message: str
) -> None:
    key = robot_key(compose("config"))
    plus = "+" if override.startswith("+") else ""
    cfg = compose("config", overrides=[f"{plus}{key}.{override.removeprefix('+')}"])
    with pytest.raises(ConfigError) as info:
        robot_settings(cfg)
    text = str(info.value)
    assert text.startswith(f"{key}.{where}"), text
    assert message in text, text


def run_main(*overrides: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, str(REPO / "evo" / "main.py"), *overrides],
        capture_output=True,
        text=True,
        cwd=cwd,
        env={**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")},
        timeout=300,
    )


def test_robots_task_writes_valid_robots_to_its_run_dir(tmp_path: Path) -> None:
    run_dir, cwd = tmp_path / "run", tmp_path / "cwd"
    cwd.mkdir()
    done = run_main("task=robots", "robots.count=3", f"hydra.run.dir={run_dir}", cwd=cwd)
    assert done.returncode == 0, done.stderr
    assert "Traceback" not in done.stderr
    files = sorted((run_dir / "robots").glob("*.json"))
    assert len(files) == 3, files
    for path in files:
        robot = load_robot(path)
        assert path.name == f"{robot.name}.json"
    assert (run_dir / ".hydra" / "config.yaml").is_file()
    assert list(cwd.iterdir()) == [], "the run wrote outside its run directory"
    if "no pictures" not in done.stdout:
        assert (run_dir / "robots" / "robots.png").stat().st_size > 1000


def test_main_rejects_a_bad_value_with_one_line(hydra_conf: None, tmp_path: Path) -> None:
    key = robot_key(compose("config"))
    done = run_main(
        "robots.count=1",
        "robots.render=false",
        f"{key}.generator.p_empty=2",
        f"hydra.run.dir={tmp_path / 'run'}",
        cwd=tmp_path,
    )
    assert done.returncode == 2
    assert "Traceback" not in done.stderr
    assert f"error: bad config: {key}.generator: p_empty must be a probability" in done.stderr
