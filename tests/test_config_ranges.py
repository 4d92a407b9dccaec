"""Every numeric key of every config group has a range, checked at start.

The keys come from the composed configs themselves (every executor, the cluttered
arena), so a new key without an entry in :data:`BAD` fails
:func:`test_every_numeric_key_has_a_bad_value_in_the_table`. Each bad value stops the
run at start with a ``ConfigError`` naming its key, checked in-process through the
functions ``python evo/main.py`` calls; two subprocess runs check the exit code 2 and
the one line without a traceback. Keys whose range depends on others are checked
together (:data:`TOGETHER`).
"""

from __future__ import annotations

import re
import subprocess
import warnings
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from hydra import compose, initialize_config_dir
from omegaconf import DictConfig, OmegaConf
from test_evolution import ENV, main_cmd

from evo.config import ConfigError
from evo.edge import typed_config
from evo.main import evolve_parts

CONF = Path(__file__).resolve().parents[1] / "conf"
CONFIGS = {
    "local": ["+exp=smoke", "env=cluttered"],
    "ray": ["+exp=smoke", "env=cluttered", "executor=ray"],
    "serial": ["+exp=smoke", "env=cluttered", "executor=serial"],
    "locomotion": ["+exp=smoke", "env/task=locomotion"],
    "push": ["+exp=smoke", "env/task=push"],
    "rough": ["+exp=smoke", "env/task=rough"],
}
"""Composed configs whose numeric keys are enumerated (every executor option; the other
groups' options share their keys)."""

BAD: dict[str, Any] = {
    "morphology.generator.max_depth": 0,
    "morphology.generator.p_empty": 1.0,
    "morphology.generator.p_passive_wheels": 1.5,
    "morphology.generator.type_weights[]": -1.0,
    "morphology.generator.max_tries": 0,
    "morphology.limits.max_depth": 0,
    "morphology.limits.max_modules": 3,
    "morphology.physics.module_size": 0.0,
    "morphology.physics.module_gap": -0.001,
    "morphology.physics.brain_mass": 0.0,
    "morphology.physics.module_mass": 0.0,
    "morphology.physics.wheel_mass": 0.0,
    "morphology.physics.wheel_radius": 0.02,
    "morphology.physics.wheel_width": 0.0,
    "morphology.physics.friction[]": -1.0,
    "morphology.physics.body_damping": -1.0,
    "morphology.physics.motor_max_speed": 0.0,
    "morphology.physics.motor_max_torque": 0.0,
    "morphology.physics.motor_kv": 0.0,
    "morphology.physics.motor_armature": -1.0,
    "morphology.physics.passive_wheel_damping": -1.0,
    "morphology.physics.passive_wheel_armature": -1.0,
    "morphology.physics.pivot_range": 91.0,
    "morphology.physics.pivot_kp": 0.0,
    "morphology.physics.pivot_kd": -1.0,
    "morphology.physics.pivot_max_torque": 0.0,
    "morphology.physics.pivot_armature": -1.0,
    "morphology.physics.timestep": 0.0,
    "env.nthread": 0,
    "env.arena.side": 0.0,
    "env.arena.wall_height": 0.0,
    "env.arena.wall_thickness": 0.0,
    "env.arena.n_rocks": -1,
    "env.arena.rock_types[].size[]": 0.0,
    "env.arena.rock_density": 0.0,
    "env.arena.rock_spread": 0.0,
    "env.arena.start_clearance": -1.0,
    "env.arena.target_clearance": -1.0,
    "env.task.t_max": 0,
    "env.task.frame_skip": 0,
    "env.task.success_radius": 0.0,
    "env.task.target_min": -1.0,
    "env.task.target_max": 0.1,
    "env.task.max_height": 0.0,
    "env.task.stall_radius": 0.0,
    "env.task.stall_seconds": -1.0,
    "env.task.range_sectors": 0,
    "env.task.range_max": 0.0,
    "env.task.clock_period": 0.0,
    "env.task.heading_range": 181.0,
    "env.task.success_distance": 0.0,
    "env.task.box_size": 0.0,
    "env.task.box_mass": 0.0,
    "env.task.box_min": 0.1,
    "env.task.box_max": 0.1,
    "env.task.goal_min": -1.0,
    "env.task.goal_max": 0.1,
    "env.task.goal_radius": 0.0,
    "env.task.near_weight": -1.0,
    "env.task.push_weight": -1.0,
    "env.task.bump_height": -1.0,
    "env.task.bump_radius": 0.0,
    "env.task.bumps": -1,
    "env.task.step_height": -1.0,
    "env.task.steps": -1,
    "env.task.terrain_size": 4.0,
    "env.task.resolution": 0.0,
    "env.task.pad_radius": 0.0,
    "env.task.pad_spacing": 0.0,
    "env.task.terrain_seed": -1,
    "learner.total_steps": 0,
    "learner.num_envs": 0,
    "learner.rollout_steps": 0,
    "learner.epochs": 0,
    "learner.minibatch_size": 0,
    "learner.lr": 0.0,
    "learner.gamma": 0.0,
    "learner.lmbda": 1.5,
    "learner.clip_epsilon": 0.0,
    "learner.entropy_coeff": -1.0,
    "learner.critic_coeff": -1.0,
    "learner.max_grad_norm": 0.0,
    "learner.hidden[]": 0,
    "learner.init_log_std": 5.0,
    "learner.policy_out_gain": -1.0,
    "learner.eval_episodes": -1,
    "learner.eval_interval": -1,
    "learner.eval_interval_episodes": 0,
    "learner.anneal_from": 1.0,
    "ga.population_size": 1,
    "ga.robot_budget": 2,
    "ga.selection.epsilon": 0.0,
    "ga.schedule.initial": 0,
    "ga.schedule.first": 0,
    "ga.schedule.last": 0,
    "ga.schedule.inherited": 0.0,
    "ga.crossover_tries": 0,
    "ga.parent_tries": 0,
    "ga.mutation_rate": 1.5,
    "ga.eval_timeout_s": -1.0,
    "ga.early_rejection.checkpoints[]": 1.5,
    "ga.early_rejection.margin": -1.0,
    "ga.early_rejection.last": 0,
    "executor.workers": -1,
    "executor.threads": 0,
    "executor.retries": -1,
    "record.episodes.every": -1,
    "record.frame_stride": 0,
    "record.still_tolerance": -1.0,
    "record.flush_every": 0,
    "seed": -1,
    "torch_threads": 0,
    "robots.count": 0,
}
"""One out-of-range value per numeric key (``[]`` stands for any list index)."""

IN_MAIN: set[str] = set()
"""Keys ``evo/main.py``'s ``main`` checks itself: covered by the subprocess test."""

TOGETHER = [
    (["learner.minibatch_size=4096", "learner.num_envs=2", "learner.rollout_steps=4"],
     "learner: minibatch_size (4096) must be <= the batch, num_envs x rollout_steps = 2 x 4"),
    (["env.arena.n_rocks=100000"], "env.arena: n_rocks (100000) do not fit"),
    (["env.arena.n_rocks=200"], "(at most 104 rocks of these types)"),
    (["env.arena.rock_spread=2"], "env.arena: rock_spread (2.0 m) must be below half the arena"),
    (["ga.schedule.initial=4", "ga.schedule.first=4"],
     "ga.schedule: 4 env steps give each of learner.num_envs=8 arenas no control step"),
    (["learner.num_envs=4096"], "ga.schedule: 2,048 env steps give each of"),
    (["env.task.target_max=1.96"], "env.task: target_max (1.96 m) must be below half the arena"),
    (["env/task=push", "env.task.box_max=1.2", "env.task.goal_max=1.0"],
     "env.task: box_max + goal_max (2.2 m) must be below half the arena side less a wall"),
    (["env/task=rough", "env.task.terrain_size=50", "env.task.resolution=0.01"],
     "env.task: terrain_size / resolution must be <= 1000 cells a side"),
    (["env/task=locomotion", "env.arena.side=2"],
     "env.task: success_distance (1.0 m) must be below half the arena side less a wall"),
    (["ga.robot_budget=3"], "ga: robot_budget (3) must be >= population_size (4)"),
]
"""Values out of range only together with others: (overrides, what the error says)."""


@pytest.fixture(scope="module")
def hydra_conf() -> Iterator[None]:
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        yield


@pytest.fixture(scope="module", autouse=True)
def no_ray_start() -> Iterator[None]:
    """RayExecutor builds against a pretend 4-CPU cluster instead of starting Ray."""
    ray = pytest.importorskip("ray")
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(ray, "is_initialized", lambda: True)
        patch.setattr(ray, "cluster_resources", lambda: {"CPU": 4.0})
        yield


def numeric_keys(node: Any, prefix: str = "") -> Iterator[str]:
    """Dotted paths (``a.b[0].c``) of the numeric leaves of a plain config."""
    if isinstance(node, dict):
        for key, value in node.items():
            yield from numeric_keys(value, f"{prefix}.{key}" if prefix else str(key))
    elif isinstance(node, list):
        for i, value in enumerate(node):
            yield from numeric_keys(value, f"{prefix}[{i}]")
    elif isinstance(node, int | float) and not isinstance(node, bool):
        yield prefix


def pattern(key: str) -> str:
    return re.sub(r"\[\d+\]", "[]", key)


def cases() -> list[tuple[str, str]]:
    """(config, key) for every numeric key; executor keys once per executor."""
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        seen: set[str] = set()
        found = []
        for name, overrides in CONFIGS.items():
            plain = OmegaConf.to_container(compose("config", overrides=overrides), resolve=True)
            for key in numeric_keys(plain):
                if key not in seen or key.startswith("executor."):
                    seen.add(key)
                    found.append((name, key))
    return found


CASES = cases()


def test_every_numeric_key_has_a_bad_value_in_the_table() -> None:
    keys = {pattern(key) for _, key in CASES}
    assert keys - set(BAD) == set(), "numeric keys without a bad value (and a range?)"
    assert set(BAD) - keys == set(), "table entries for keys the configs no longer have"
    assert len(CASES) >= 100


def start_checks(cfg: DictConfig, key: str, out: Path) -> None:
    """What ``python evo/main.py`` checks at start, for ``key``."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        evolve_parts(typed_config(cfg), out)


@pytest.fixture(scope="module")
def composed(hydra_conf: None, no_ray_start: None) -> dict[str, DictConfig]:
    """:data:`CONFIGS`, composed once and checked valid as they are."""
    configs = {name: compose("config", overrides=o) for name, o in CONFIGS.items()}
    for cfg in configs.values():
        start_checks(cfg, "", Path("unused"))
    return configs


@pytest.mark.parametrize(("config", "key"), [c for c in CASES if pattern(c[1]) not in IN_MAIN],
                         ids=[f"{c}:{k}" for c, k in CASES if pattern(k) not in IN_MAIN])
def test_an_out_of_range_value_stops_the_run_naming_its_key(
    composed: dict[str, DictConfig], tmp_path: Path, config: str, key: str
) -> None:
    cfg = composed[config].copy()
    OmegaConf.update(cfg, key, BAD[pattern(key)])
    with pytest.raises(ConfigError) as info:
        start_checks(cfg, key, tmp_path)
    message = str(info.value)
    parent, _, leaf = re.sub(r"\[\d+\]$", "", key).rpartition(".")
    leaf = re.sub(r"\[\d+\]", "", leaf)
    assert leaf in message and (not parent or message.startswith(parent)), (key, message)
    assert "\n" not in message, message


@pytest.mark.parametrize(("overrides", "expected"), TOGETHER,
                         ids=[" ".join(o) for o, _ in TOGETHER])
def test_keys_whose_range_depends_on_others_are_checked_together(
    hydra_conf: None, tmp_path: Path, overrides: list[str], expected: str
) -> None:
    cfg = compose("config", overrides=[*CONFIGS["local"], *overrides])
    with pytest.raises(ConfigError) as info:
        start_checks(cfg, "", tmp_path)
    assert expected in str(info.value), str(info.value)


def test_main_refuses_them_at_once_with_exit_2_and_one_line(tmp_path: Path) -> None:
    runs = [["torch_threads=0"], ["env=cluttered", "env.arena.n_rocks=100000"]]
    procs = [subprocess.Popen(main_cmd("+exp=smoke", *args, f"hydra.run.dir={tmp_path / str(i)}"),
                              cwd=tmp_path, env=ENV, stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True) for i, args in enumerate(runs)]
    for args, proc in zip(runs, procs, strict=True):
        _, err = proc.communicate(timeout=300)
        group, _, leaf = args[-1].split("=")[0].rpartition(".")
        last = err.strip().splitlines()[-1]
        assert proc.returncode == 2 and "Traceback" not in err, (args, err[-2000:])
        assert last.startswith(f"error: bad config: {group}") and leaf in last, last
