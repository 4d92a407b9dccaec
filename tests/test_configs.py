"""The evolution's configs: every experiment and every group option composes and builds
the typed objects of a run (through ``evo.main.evolve_parts``, as a run does), the
experiments hold the paper's numbers, bad values stop ``python evo/main.py`` at start
with exit code 2 and a message naming the key, and the ablation runs as a multirun.

tests/test_robot_config.py covers the robot settings (morphology) of every config; this
file covers the GA, executors, learners' method labels and the experiments.
"""

from __future__ import annotations

import itertools
import os
import subprocess
import sys
import warnings
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hydra import compose, initialize_config_dir
from hydra.errors import HydraException
from omegaconf import DictConfig, OmegaConf, open_dict

from evo.components.executors import LocalExecutor, RayExecutor, SerialExecutor
from evo.components.ga import (
    BudgetSchedule,
    Evolve,
    GAConfig,
    RandomStructures,
    ReplaceWorst,
    Roulette,
)
from evo.config import ConfigError, current, method_label, typed
from evo.edge import typed_config, warn_if_failures_cannot_end
from evo.envs.params import EnvConfig
from evo.learners.common import LearnerConfig
from evo.learners.ppo import PPO
from evo.main import (
    TASKS,
    EvolveParts,
    _check_run_dir_arg,
    _resume_in_place,
    _write_config,
    evolve_parts,
    keeping_its_method,
)
from evo.robot.operators import RotateEdge
from evo.run.records import HistoryRow
from evo.run.store import SavedState, rng_state

REPO = Path(__file__).resolve().parents[1]
CONF = REPO / "conf"
EXPERIMENTS = sorted(p.stem for p in (CONF / "exp").glob("*.yaml"))
GROUPS = sorted(p.relative_to(CONF).as_posix() for p in CONF.rglob("*")
                if p.is_dir() and p.relative_to(CONF).parts[0] not in ("exp", "hydra"))
"""Config groups, nested ones (``ga/structure``) included."""
METHODS = {"E+L", "E+R", "R+L", "R+R"}
FIFTH_ARM = ["ga.inheritance=parent", "ga.schedule.inherited=1.0"]
"""The ablation's fifth arm, E+L+I (docs/results/ablation/run.sh)."""
EXECUTORS = {"local": LocalExecutor, "serial": SerialExecutor, "ray": RayExecutor}


@pytest.fixture(scope="module")
def hydra_conf() -> Iterator[None]:
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        yield


@pytest.fixture(autouse=True)
def no_ray_start(monkeypatch: pytest.MonkeyPatch) -> None:
    """RayExecutor builds against a pretend 4-CPU cluster instead of starting Ray."""
    try:
        import ray
    except ImportError:
        return
    monkeypatch.setattr(ray, "is_initialized", lambda: True)
    monkeypatch.setattr(ray, "cluster_resources", lambda: {"CPU": 4.0})


def build(cfg: DictConfig, out: Path) -> EvolveParts:
    parts = evolve_parts(typed_config(cfg), out)
    assert isinstance(parts.ga, GAConfig)
    assert isinstance(parts.strategy, Evolve | RandomStructures)
    assert isinstance(parts.ga.replacement, ReplaceWorst)
    assert isinstance(parts.ga.schedule, BudgetSchedule)
    assert isinstance(parts.job.learner, LearnerConfig)
    assert isinstance(parts.job.env, EnvConfig)
    assert parts.job.run_dir == str(out)
    assert parts.job.method in METHODS | {"E+L+I"}
    assert isinstance(parts.executor, tuple(EXECUTORS.values()))
    assert parts.executor.workers >= 1
    return parts


def sweep(cfg: DictConfig) -> list[list[str]]:
    """Every job of a multirun experiment, as override lists: the basic sweeper's grid, or
    for Optuna's every value of each parameter alone (an interval: its ends), as the
    Optuna sweeper writes it."""
    from hydra.core.override_parser.overrides_parser import OverridesParser

    params = cfg.hydra.sweeper.get("params") or {}
    parsed = OverridesParser.create().parse_overrides([f"{k}={v}" for k, v in params.items()])
    axes = [[f"{o.key_or_group}={v}" for v in (
        [o.value().start, o.value().end] if o.is_interval_sweep()
        else o.sweep_iterator() if o.is_sweep_override()
        else [o.get_value_element_as_str()])] for o in parsed]
    if "optuna" in str(cfg.hydra.sweeper.get("_target_")):
        return [[job] for axis in axes for job in axis]
    return [list(job) for job in itertools.product(*axes)]


# ---- every option composes and builds -------------------------------------------------------


def group_options() -> list[tuple[str, str]]:
    return [(g, p.stem) for g in GROUPS for p in sorted((CONF / g).glob("*.yaml"))]


@pytest.mark.parametrize(
    ("group", "option"), group_options(), ids=[f"{g}={o}" for g, o in group_options()]
)
def test_every_group_option_builds_an_evolution(
    hydra_conf: None, tmp_path: Path, group: str, option: str
) -> None:
    cfg = compose("config", overrides=[f"{group}={option}"])
    parts = build(cfg, tmp_path)
    if group == "executor":
        assert type(parts.executor) is EXECUTORS[option]
    if group == "learner":
        assert parts.job.learner.update is (option == "ppo")
        assert parts.job.method == ("E+L" if option == "ppo" else "E+R")
    if group == "env":
        assert parts.job.env.name == option
        assert (parts.job.env.arena.n_rocks > 0) is (option == "cluttered")
    if group == "ga":
        assert isinstance(parts.strategy, Evolve)
        assert isinstance(parts.strategy.ga.selection, Roulette)
    if group == "ga/structure":
        strategy = {"evolve": Evolve, "random": RandomStructures}[option]
        assert type(parts.strategy) is strategy
        assert parts.job.method == ("E+L" if option == "evolve" else "R+L")


GIVEN = {"retrain": ["retrain.random=3"]}
"""What an experiment needs on the command line besides itself (+exp=retrain: the
structures to train)."""


@pytest.mark.parametrize("experiment", EXPERIMENTS)
def test_every_experiment_composes_and_builds(
    hydra_conf: None, tmp_path: Path, experiment: str
) -> None:
    given = GIVEN.get(experiment, [])
    cfg = compose("config", overrides=[f"+exp={experiment}", *given],
                  return_hydra_config=True)
    assert cfg.task in TASKS, f"{experiment}: unknown task {cfg.task}"
    jobs = sweep(cfg) if str(cfg.hydra.mode) == "RunMode.MULTIRUN" else [[]]
    for job in jobs:
        job_cfg = compose("config", overrides=[f"+exp={experiment}", *given, *job])
        if job_cfg.task == "evolve":
            build(job_cfg, tmp_path)
        else:  # train / evaluate: one robot, the same typed settings
            assert isinstance(typed(LearnerConfig, job_cfg.learner, "learner"), LearnerConfig)
            assert isinstance(typed(EnvConfig, job_cfg.env, "env"), EnvConfig)
            typed_config(job_cfg)
    text = (CONF / "exp" / f"{experiment}.yaml").read_text()
    assert text.startswith("# @package _global_"), "experiments are global overlays"


def test_an_unknown_group_option_names_the_group(hydra_conf: None) -> None:
    with pytest.raises(HydraException, match="learner/teleport"):
        compose("config", overrides=["learner=teleport"])


# ---- the experiments hold the paper's numbers ------------------------------------------------


def parts_of(experiment: str, out: Path, *overrides: str) -> EvolveParts:
    return build(compose("config", overrides=[f"+exp={experiment}", *overrides]), out)


@pytest.mark.parametrize(("experiment", "arena"), [("paper_clean", 0), ("paper_cluttered", 40)])
def test_paper_experiments(hydra_conf: None, tmp_path: Path, experiment: str, arena: int) -> None:
    parts = parts_of(experiment, tmp_path)
    assert (parts.ga.population_size, parts.ga.robot_budget) == (20, 100)
    budgets = [parts.ga.schedule.budget(b, 20, 100) for b in range(100)]
    assert budgets[:21] == [50_000] * 21 and budgets[99] == 250_000
    assert budgets == sorted(budgets)
    assert parts.job.learner.num_envs >= 12 and parts.job.learner.update
    assert parts.job.env.arena.n_rocks == arena
    assert parts.job.method == "E+L"
    # The arena can still be chosen on the command line.
    other = "cluttered" if arena == 0 else "clean"
    assert parts_of(experiment, tmp_path, f"env={other}").job.env.name == other


def test_smoke_and_demo_are_small_evolutions(hydra_conf: None, tmp_path: Path) -> None:
    smoke = parts_of("smoke", tmp_path)
    assert smoke.ga.robot_budget <= 10 and smoke.ga.schedule.budget(7, 4, 8) <= 5_000
    demo = parts_of("demo", tmp_path)
    size, total = demo.ga.population_size, demo.ga.robot_budget
    assert size >= 4 and total >= 2 * size, "the demo breeds at least as many as it draws"
    budgets = [demo.ga.schedule.budget(b, size, total) for b in range(total)]
    assert min(budgets) >= 20_000 and max(budgets) <= 250_000 and budgets == sorted(budgets)
    # About ten minutes on 2 cores at the ~5,000 env steps/s two workers reach.
    assert sum(budgets) <= 3_000_000, sum(budgets)
    assert demo.job.env.name == "clean" and demo.job.learner.num_envs == 32
    assert demo.job.method == "E+L"


@pytest.mark.parametrize("experiment", ["smoke", "demo", "paper_clean", "ablation_smoke"])
def test_experiments_give_every_arena_room_for_a_failed_episode(
    hydra_conf: None, tmp_path: Path, experiment: str
) -> None:
    """Fitness averages the episodes that ended: each arena must be able to end one by
    the time limit, or only successes would count (a warning names the keys)."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        parts_of(experiment, tmp_path)
    with pytest.warns(UserWarning, match=r"learner.num_envs=256 .* env.task.t_max=") as caught:
        parts_of(experiment, tmp_path, "learner.num_envs=256", "env.task.t_max=1000")
    assert "ga.schedule" in str(caught[0].message)


def test_the_deploy_experiment_is_train_with_the_deployed_controllers_levers(
    hydra_conf: None,
) -> None:
    """+exp=deploy trains as +exp=train does but for the six keys that make its mean
    action the one measured in docs/results/deployed.md; the rest is +exp=train's."""
    deploy_cfg = compose("config", overrides=["+exp=deploy"])
    train, deploy = (pd.json_normalize(OmegaConf.to_container(cfg)).iloc[0]
                     for cfg in (compose("config", overrides=["+exp=train"]), deploy_cfg))
    levers = {"learner.eval_interval": 30000, "learner.keep_best": True,
              "learner.anneal_lr": False, "env.task.observe_stall": True,
              "learner.final_log_std": -2.0, "learner.anneal_from": 0.8}
    keys = train.index.union(deploy.index)
    differ = {k for k in keys if train.get(k) != deploy.get(k)}
    assert differ == set(levers)
    assert all(deploy[k] == v for k, v in levers.items())
    assert typed(LearnerConfig, deploy_cfg.learner, "learner").keep_best


def test_one_robot_training_leaves_room_for_failed_episodes(hydra_conf: None) -> None:
    cfg = compose("config", overrides=["+exp=train"])
    learner = typed(LearnerConfig, cfg.learner, "learner")
    env = typed(EnvConfig, cfg.env, "env")
    assert learner.num_envs * learner.rollout_steps == 2048 and learner.update
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        warn_if_failures_cannot_end(learner.total_steps, "learner.total_steps", learner, env)
    with pytest.warns(UserWarning, match=r"learner.total_steps: 100,000 env steps .* 781 "):
        warn_if_failures_cannot_end(100_000, "learner.total_steps", learner, env)


@pytest.mark.parametrize(
    "experiment", ["ablation", "ablation_100k", "ablation_paper", "ablation_smoke"])
def test_ablation_is_a_multirun_of_the_four_methods(
    hydra_conf: None, tmp_path: Path, experiment: str
) -> None:
    cfg = compose("config", overrides=[f"+exp={experiment}"], return_hydra_config=True)
    assert str(cfg.hydra.mode) == "RunMode.MULTIRUN", "runs as a sweep without -m"
    assert "seed" in cfg.hydra.sweeper.params, "the GA seed is a sweep dimension"
    labels = set()
    for job in sweep(cfg):
        overrides = [f"+exp={experiment}", *job]
        parts = build(compose("config", overrides=overrides), tmp_path)
        labels.add(parts.job.method)
        job_cfg = compose("config", overrides=overrides, return_hydra_config=True)
        assert job_cfg.hydra.sweep.subdir == f"{parts.job.method}_seed{job_cfg.seed}"
        budgets = {
            parts.ga.schedule.budget(b, parts.ga.population_size, parts.ga.robot_budget)
            for b in range(parts.ga.robot_budget)
        }
        assert len(budgets) == 1, "every robot of the ablation gets the same budget"
        if experiment == "ablation_paper":  # the paper's regime, exactly
            assert budgets == {30_000} and 90 <= parts.ga.robot_budget <= 110
            assert (parts.job.learner.num_envs, parts.job.learner.rollout_steps) == (12, 128)
        if experiment == "ablation_100k":  # the regime docs/results/fitness_noise.md chose
            assert budgets == {100_000} and parts.ga.robot_budget == 100
            assert (parts.job.learner.num_envs, parts.job.learner.rollout_steps) == (32, 64)
        if experiment == "ablation":  # the noise sweep's regime (docs/results/noise_sweep/)
            learner, physics = parts.job.learner, parts.job.physics
            assert budgets == {50_000} and parts.ga.robot_budget == 100
            assert (learner.num_envs, learner.rollout_steps, learner.minibatch_size) == (
                32, 64, 1024)
            assert (learner.lmbda, learner.entropy_coeff, learner.init_log_std) == (
                0.8, 0.0, -1.0) and learner.reward_scaling
            assert (physics.timestep, parts.job.env.task.frame_skip) == (0.00625, 8)
    assert labels == METHODS
    # More seeds are a command-line choice (seed=0,1,2 there; quoted in the compose API).
    more = compose(
        "config",
        overrides=[f"+exp={experiment}", "hydra.sweeper.params.seed='0,1,2'"],
        return_hydra_config=True,
    )
    assert len(sweep(more)) == 12


def test_inheritance_adds_i_to_the_method_label_and_only_then() -> None:
    for structure, learns, label in (("E", True, "E+L"), ("R", False, "R+R")):
        assert method_label(structure, learns) == label, "the paper's four, as before"
        for off in ("off", False, None):  # as written, as YAML reads a bare off, absent
            assert method_label(structure, learns, off) == label, off
        assert method_label(structure, learns, "parent") == f"{label}+I"


def test_the_fifth_arm_is_e_l_i_in_its_own_subdir_with_room_for_failed_episodes(
    hydra_conf: None, tmp_path: Path
) -> None:
    arm = ["+exp=ablation", "ga.structure=E", "learner=ppo", "seed=3"]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        parts = build(compose("config", overrides=[*arm, *FIFTH_ARM]), tmp_path)
    assert parts.job.method == "E+L+I" and parts.ga.inheritance == "parent"
    cfg = compose("config", overrides=[*arm, *FIFTH_ARM], return_hydra_config=True)
    assert cfg.hydra.sweep.subdir == "E+L+I_seed3"
    plain = compose("config", overrides=arm, return_hydra_config=True)
    assert plain.hydra.sweep.subdir == "E+L_seed3", "the four arms keep their folders"
    # Half the budget leaves an arena about 800 control steps, under t_max: failing
    # episodes could not end, which is why the arm keeps the whole budget.
    with pytest.warns(UserWarning, match=r"ga.schedule: 25,000 env steps .* under the episode"):
        build(compose("config", overrides=[*arm, "ga.inheritance=parent",
                                           "ga.schedule.inherited=0.5"]), tmp_path)


def test_a_run_resumes_with_the_method_its_history_holds(hydra_conf: None, tmp_path: Path
                                                        ) -> None:
    """A run with inheritance on from before ``+I`` was in the label keeps ``E+L``."""
    parts = build(compose("config", overrides=FIFTH_ARM), tmp_path)
    row = HistoryRow(0, "robot-00000000", "E+L", (), "random", 1, 1, -1.0, True, "", 1, 1,
                     0.0, "", -1.0, -1.0, "trained", float("nan"))
    saved = SavedState(seed=0, next_birth=1, rng=rng_state(np.random.default_rng(0)),
                       population=[], history=[row], pending=[], wall_seconds=1.0)
    assert keeping_its_method(parts, saved).job.method == "E+L"
    assert keeping_its_method(parts, None).job.method == "E+L+I", "a new run: today's label"
    same = replace(saved, history=[replace(row, method="E+L+I")])
    assert keeping_its_method(parts, same) is parts


def test_run_sh_starts_only_the_arms_asked_for_and_resumes_them(tmp_path: Path) -> None:
    script = tmp_path / "docs" / "results" / "ablation" / "run.sh"
    script.parent.mkdir(parents=True)
    script.write_bytes((REPO / "docs" / "results" / "ablation" / "run.sh").read_bytes())
    script.chmod(0o755)
    python = tmp_path / "python"  # stands in for the virtualenv's: prints its arguments
    python.write_text('#!/usr/bin/env bash\necho "$*"\n')
    python.chmod(0o755)
    started = tmp_path / "runs" / "ablation" / "E+L+I_seed1"
    started.mkdir(parents=True)
    (started / "state.json").write_text("{}")
    env = {**os.environ, "PYTHON": str(python), "ARMS": "E+L+I", "SEEDS": "0 1"}
    done = subprocess.run([str(script)], env=env, capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    logs = sorted(p.name for p in (tmp_path / "runs").glob("*.log"))
    assert logs == ["ablation_E+L+I_seed0.log", "ablation_E+L+I_seed1.log"]
    new = (tmp_path / "runs" / "ablation_E+L+I_seed0.log").read_text().split()
    assert new[1:] == ["+exp=ablation", "hydra.mode=RUN", "ga.structure=E", "learner=ppo",
                       "seed=0", "executor=serial", "hydra.run.dir=runs/ablation/E+L+I_seed0",
                       *FIFTH_ARM]
    resumed = (tmp_path / "runs" / "ablation_E+L+I_seed1.log").read_text().split()
    assert resumed[1:] == ["resume=runs/ablation/E+L+I_seed1"]
    done = subprocess.run([str(script)], env={**env, "ARMS": "E+L+X"}, capture_output=True,
                          text=True, timeout=60)
    assert done.returncode == 2 and "ARMS: unknown arm 'E+L+X'" in done.stderr
    # The evolved side of the designer comparison: another arena, fewer robots per run.
    env = {**env, "ARMS": "E+L", "SEEDS": "2", "ARENA": "cluttered", "ROBOTS": "60"}
    done = subprocess.run([str(script)], env=env, capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    cluttered = (tmp_path / "runs" / "ablation_cluttered_E+L_seed2.log").read_text().split()
    assert cluttered[1:] == ["+exp=ablation", "hydra.mode=RUN", "ga.structure=E",
                             "learner=ppo", "seed=2", "executor=serial",
                             "hydra.run.dir=runs/ablation_cluttered/E+L_seed2",
                             "env=cluttered", "ga.robot_budget=60"]
    done = subprocess.run([str(script)], env={**env, "ARENA": "rocky"}, capture_output=True,
                          text=True, timeout=60)
    assert done.returncode == 2 and "ARENA: expected clean or cluttered, got 'rocky'" in done.stderr



def test_run_sh_jobs_keeps_at_most_n_runs_going_and_runs_them_all(tmp_path: Path) -> None:
    script = tmp_path / "docs" / "results" / "ablation" / "run.sh"
    script.parent.mkdir(parents=True)
    script.write_bytes((REPO / "docs" / "results" / "ablation" / "run.sh").read_bytes())
    script.chmod(0o755)
    going = tmp_path / "going"
    going.mkdir()
    # Stands in for the virtualenv's python: counts the runs going while it is one of them.
    python = tmp_path / "python"
    python.write_text(f'#!/usr/bin/env bash\ntouch {going}/$$\nls {going} | wc -l '
                      f'>> {tmp_path}/counts\nsleep 0.3\nrm {going}/$$\n')
    python.chmod(0o755)
    env = {**os.environ, "PYTHON": str(python), "SEEDS": "5 6", "ARMS": "E+L E+R R+L",
           "JOBS": "2"}
    done = subprocess.run([str(script)], env=env, capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    counts = [int(c) for c in (tmp_path / "counts").read_text().split()]
    assert len(counts) == 6 and max(counts) <= 2  # six runs, never more than two at once
    assert len(list((tmp_path / "runs").glob("ablation_*_seed[56].log"))) == 6
    done = subprocess.run([str(script)], env={**env, "JOBS": "two"}, capture_output=True,
                          text=True, timeout=60)
    assert done.returncode == 2 and "JOBS: expected a whole number" in done.stderr

# ---- older configs and shorthands ----------------------------------------------------------

OLD_CONFIG = REPO / "tests" / "data" / "run_58aad82" / "stopped" / "config.yaml"
"""The ``config.yaml`` evo wrote at commit 58aad82: ``ga.structure: E``, a ``learner``
with ``name`` and ``update`` and no ``_target_``."""
OLD_RUN_VALUES = [
    "ga.population_size=3", "ga.robot_budget=6", "ga.schedule.initial=256",
    "ga.schedule.first=256", "ga.schedule.last=768", "learner.num_envs=4",
    "learner.epochs=1", "learner.minibatch_size=128", "learner.hidden=[32,32]",
    "env.task.t_max=40", "executor=serial", "record=off"]
"""Today's overrides for the values of that run."""


def test_an_older_config_yaml_gives_todays_typed_config(hydra_conf: None, tmp_path: Path) -> None:
    old = OmegaConf.load(OLD_CONFIG)
    assert isinstance(old, DictConfig) and old.ga.structure == "E" and "name" in old.learner
    resumed = build(old, tmp_path / "old")
    today = build(compose("config", overrides=OLD_RUN_VALUES), tmp_path / "today")
    assert resumed.ga == today.ga and type(resumed.strategy) is Evolve
    assert resumed.job.learner == today.job.learner and type(resumed.job.learner) is PPO
    assert (resumed.job.physics, resumed.job.env) == (today.job.physics, today.job.env)
    assert resumed.job.method == today.job.method == "E+L"
    # The same run with the random structures and learner of that time: R+R.
    old.ga.structure, old.learner.name, old.learner.update = "R", "random", False
    random = build(old, tmp_path / "random")
    assert type(random.strategy) is RandomStructures and random.job.method == "R+R"
    assert random.job.learner.name == "random"
    # What today's code writes reads back as the same config.
    written = tmp_path / "written"
    written.mkdir()
    _write_config(typed_config(compose("config", overrides=OLD_RUN_VALUES)).yaml, written)
    again = build(OmegaConf.load(written / "config.yaml"), written)
    assert again.ga == today.ga and again.job.learner == today.job.learner


def test_the_shorthands_stand_for_their_classes(hydra_conf: None, tmp_path: Path) -> None:
    for letter, group, strategy in (("E", "evolve", Evolve), ("R", "random", RandomStructures)):
        by_letter = build(compose("config", overrides=[f"ga.structure={letter}"]), tmp_path)
        by_group = build(compose("config", overrides=[f"ga/structure={group}"]), tmp_path)
        assert type(by_letter.strategy) is type(by_group.strategy) is strategy
        assert by_letter.ga == by_group.ga and by_letter.job.method == f"{letter}+L"
    default = compose("config")
    assert current(default) == default, "today's form comes back as it was"
    for letter, override in ("E", "ga/structure=evolve"), ("R", "ga.structure=R"):
        cfg = compose("config", overrides=[override])
        with open_dict(cfg):
            cfg.subdir = "${evo_method:${ga.structure},${learner.update}}"
        assert cfg.subdir == f"{letter}+L", "the resolver reads either form"
    named = build(compose("config", overrides=["ga.mutation_operators=[rotate_edge]"]), tmp_path)
    assert named.ga.mutation_operators == (RotateEdge(),)
    old = OmegaConf.load(OLD_CONFIG)
    old.learner.name = "teleport"
    with pytest.raises(ConfigError, match="learner.name: unknown learner 'teleport'"):
        current(old)


def test_a_runs_method_comes_from_either_form_of_its_config(
    hydra_conf: None, tmp_path: Path
) -> None:
    from analysis.load import RunConfig, run_method

    today = OmegaConf.to_container(current(compose(
        "config", overrides=["ga/structure=random", "learner=random"])), resolve=True)
    old = {"ga": {"structure": "R"}, "learner": {"name": "random", "update": False}}
    for config in (today, old):  # a run directory without history or summary
        assert isinstance(config, dict)
        assert run_method(tmp_path, pd.DataFrame(), RunConfig.of(config)) == "R+R", config
    inherits = {"ga": {"structure": "E", "inheritance": "parent"}, "learner": {"update": True}}
    assert run_method(tmp_path, pd.DataFrame(), RunConfig.of(inherits)) == "E+L+I"


# ---- bad values stop the run at start ---------------------------------------------------------

BAD_VALUES = [
    ("ga.population_size=-1", "ga: population_size must be >= 2, got -1"),
    ("ga.population_size=1", "ga: population_size must be >= 2"),
    ("ga.robot_budget=0", "ga: robot_budget (0) must be >= population_size"),
    ("ga.structure=X", "ga.structure: expected E (evolve) or R (random), got 'X'"),
    ("ga.schedule.initial=0", "ga.schedule: initial must be >= 1 env step, got 0"),
    ("ga.schedule.last=-5", "ga.schedule: last must be >= 1 env step"),
    ("+ga.colour=red", "ga: unknown key(s) colour"),
    ("+ga.schedule.ramp=2", "ga.schedule: unknown key(s) ramp"),
    ("ga.selection.epsilon=0", "ga.selection: epsilon must be positive"),
    ("ga.selection._target_=nowhere.Nothing", "ga.selection._target_: no class"),
    ("ga.structure._target_=evo.components.ga.Roulette",
     "ga.structure._target_: expected a StructureChoice (or a subclass), got Roulette"),
    ("learner._target_=evo.components.ga.Roulette",
     "learner._target_: expected a LearnerConfig (or a subclass), got Roulette"),
    ("ga.mutation_rate=2", "ga: mutation_rate must be in [0, 1]"),
    ("ga.mutation_operators=[rotate_edge,teleport]",
     "ga.mutation_operators[1]: unknown mutation operator 'teleport'"),
    ("ga.mutation_operators=[{_target_:evo.components.ga.Roulette}]",
     "ga.mutation_operators[0]._target_: expected a Mutation (or a subclass), got Roulette"),
    ("ga.crossover_tries=many", "ga.crossover_tries: expected an integer, got 'many'"),
    ("ga.eval_timeout_s=-1", "ga: eval_timeout_s must be >= 0 (0 = none), got -1"),
    ("ga.eval_timeout_s=soon", "ga.eval_timeout_s: expected a number, got 'soon'"),
    ("executor.workers=-1", "executor: need workers >= 0"),
    ("+executor.colour=red", "executor: unknown key(s) colour"),
    ("learner.update=maybe", "learner.update: expected true or false, got 'maybe'"),
    ("learner.num_envs=0", "learner: num_envs must be >= 1"),
    ("learner.gamma=2", "learner: gamma must be in (0, 1], got 2.0"),
    ("learner.lr=-1", "learner: lr must be > 0, got -1.0"),
]


@pytest.mark.parametrize(("override", "message"), BAD_VALUES, ids=[b[0] for b in BAD_VALUES])
def test_bad_values_name_their_key(
    hydra_conf: None, tmp_path: Path, override: str, message: str
) -> None:
    cfg = compose("config", overrides=["+exp=smoke", override])
    with pytest.raises(ConfigError) as info:
        evolve_parts(typed_config(cfg), tmp_path)
    assert message in str(info.value), str(info.value)


ENV = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}


def start_main(*args: str, cwd: Path) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, str(REPO / "evo" / "main.py"), *args],
        cwd=cwd,
        env=ENV,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def fake_run_dir(path: Path, config: str = "seed: 0\n") -> Path:
    path.mkdir(parents=True)
    (path / "config.yaml").write_text(config)
    (path / "state.json").write_text("{}")
    return path


def test_main_stops_at_start_with_exit_2_naming_the_key(tmp_path: Path) -> None:
    # (command-line arguments, what stderr must say); all started at once. One of each
    # path to exit 2 (a section's check, the seed, a check across keys, resume):
    # test_bad_values_name_their_key checks the section checks' messages in-process.
    cases: list[tuple[list[str], str]] = [
        (["ga.population_size=-3"], "ga: population_size must be >= 2, got -3"),
        (["seed=-1"], "seed: expected a non-negative integer, got -1"),
        (["ga.schedule.first=4096", "ga.schedule.last=1024"],
         "ga.schedule: last (1024) must be >= first (4096)"),
        (
            [f"resume={fake_run_dir(tmp_path / 'old')}", "executor=ray"],
            "resume: a resumed run keeps the config it was started with",
        ),
    ]
    procs = []
    for i, (args, _) in enumerate(cases):
        cwd = tmp_path / f"cwd{i}"
        cwd.mkdir()
        run_dir = [] if args[0].startswith("resume=") else [f"hydra.run.dir={tmp_path / f'run{i}'}"]
        procs.append((start_main("+exp=smoke", *args, *run_dir, cwd=cwd), cwd))
    for (args, expected), (proc, cwd) in zip(cases, procs, strict=True):
        _, stderr = proc.communicate(timeout=180)
        assert proc.returncode == 2, (args, proc.returncode, stderr[-2000:])
        assert f"error: bad config: {expected}" in stderr, (args, stderr[-2000:])
        assert "Traceback" not in stderr
        assert list(cwd.iterdir()) == [], f"{args}: wrote into the working directory"
    for i in range(len(cases) - 1):  # nothing was evaluated, or recorded
        assert not (tmp_path / f"run{i}" / "robots").exists()
        assert not (tmp_path / f"run{i}" / "run.mcap").exists()


def test_resume_of_a_directory_that_is_no_run_stops_before_hydra_creates_it(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as info:
        _resume_in_place(["evo/main.py", f"resume={tmp_path / 'nowhere'}"])
    assert info.value.code == 2
    assert f"resume: {tmp_path / 'nowhere'} is not an evo run directory" in capsys.readouterr().err
    assert not (tmp_path / "nowhere").exists()
    run_dir = fake_run_dir(tmp_path / "run")
    argv = _resume_in_place(["evo/main.py", f"resume={run_dir}"])
    assert f"hydra.run.dir={run_dir}" in argv and "hydra.output_subdir=null" in argv


def test_a_run_directory_that_cannot_be_one_stops_before_hydra(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    afile = tmp_path / "afile"
    afile.write_text("")
    for run_dir, expected in ((afile, "exists and is not a directory"),
                              (afile / "sub", "cannot be created")):
        with pytest.raises(SystemExit) as info:
            _check_run_dir_arg([f"hydra.run.dir={run_dir}"])
        assert info.value.code == 2
        err = capsys.readouterr().err
        assert f"error: bad config: hydra.run.dir: {run_dir} {expected}" in err, err
    _check_run_dir_arg([f"hydra.run.dir={tmp_path / 'new' / 'run'}"])  # fine, and made


def test_a_new_run_in_a_run_directory_must_have_its_config(
    hydra_conf: None, tmp_path: Path
) -> None:
    cfg = compose("config", overrides=["+exp=smoke"])
    fresh = tmp_path / "fresh"
    fresh.mkdir()
    _write_config(OmegaConf.to_yaml(cfg, resolve=True), fresh)
    saved = (fresh / "config.yaml").read_text()
    assert OmegaConf.create(saved) == OmegaConf.create(OmegaConf.to_yaml(cfg, resolve=True))
    (fresh / "state.json").write_text("{}")
    _write_config(OmegaConf.to_yaml(cfg, resolve=True), fresh)  # the same command again
    other = compose("config", overrides=["+exp=smoke", "seed=5"])
    with pytest.raises(ConfigError, match=f"hydra.run.dir: {fresh} already holds a run"):
        _write_config(OmegaConf.to_yaml(other, resolve=True), fresh)
    assert (fresh / "config.yaml").read_text() == saved, "the run's config was replaced"
