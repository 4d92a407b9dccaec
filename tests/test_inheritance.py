"""Lamarckian policy inheritance (``ga.inheritance``): module correspondence through
crossover and mutation, slot-mapped networks, the GA's records, budgets and resume.

The networks' tests use real policies (``make_policy``) whose weights and observation
statistics are drawn at random, so every slot holds a value of its own and a slot
mapped to the wrong place shows.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest
import torch
from test_evolution import TINY as EVOLUTION_TINY
from test_evolution import comparable, killed, main_cmd
from test_evolution import read_history as read_evolution_history
from test_evolution import run as run_main

from evo.components.executors import LocalExecutor, SerialExecutor
from evo.components.ga import BudgetSchedule, Evolve, GAConfig
from evo.components.inheritance import actuator_origins, policy_start
from evo.early_rejection import EarlyRejection
from evo.envs.params import EnvConfig, observation_origins, observation_size
from evo.envs.tasks.reach import Reach
from evo.evaluation import Job, Outcome, evaluate
from evo.evolution import Evolution
from evo.learners.common import (
    Inheritance,
    LearnerConfig,
    Policy,
    inherit,
    load_checkpoint,
    make_policy,
)
from evo.learners.ppo import PPO
from evo.record import RecordConfig
from evo.robot import parse_robot, random_robots
from evo.robot.builder import PhysicsParams, build
from evo.robot.operators import crossover, surviving_origins
from evo.robot.tree import ModuleType, Robot, walk
from evo.run.records import Candidate, HistoryRow
from evo.run.store import RunStore

CONFIG = PPO(hidden=(16, 16))


def motor() -> dict[str, Any]:
    return {"type": "motor", "children": [{"face": 2, "rotation": 0, "module": {"type": "wheel"}},
                                          {"face": 3, "rotation": 0, "module": {"type": "wheel"}}]}


def robot_of(children: list[dict[str, Any]]) -> Robot:
    return parse_robot({"format": "evo.robot/1", "root": {"type": "brain", "children": children}},
                       source="test")


def edge(face: int, module: dict[str, Any], rotation: int = 0) -> dict[str, Any]:
    return {"face": face, "rotation": rotation, "module": module}


# A parent with motors on faces 0 and 1 and a pivot carrying a motor on face 2: actuators
# (motors in depth-first order, then the pivot) = [m0, m1, m2/0, p2].
PARENT = robot_of([edge(0, motor()), edge(1, motor()),
                   edge(2, {"type": "pivot", "children": [edge(0, motor())]})])


def trained_looking(obs: int, act: int, seed: int) -> Policy:
    """A policy whose every weight, log std and statistic is a distinct random number."""
    torch.manual_seed(seed)
    policy = make_policy(obs, act, CONFIG)
    with torch.no_grad():
        for p in [*policy.actor.parameters(), *policy.critic.parameters()]:
            p.copy_(torch.randn_like(p) * 0.5)
    policy.norm.update(torch.randn(64, obs) * 3 + torch.arange(obs))
    return policy


def sizes(robot: Robot) -> tuple[int, int]:
    return observation_size(robot, Reach()), robot.n_actuators


# ---- the networks -----------------------------------------------------------------------


def test_inheriting_onto_the_same_body_reproduces_the_parent_exactly() -> None:
    obs, act = sizes(PARENT)
    parent = trained_looking(obs, act, seed=1)
    child = make_policy(obs, act, CONFIG)
    inherit(child, Inheritance(parent, tuple(range(act))))
    x = torch.randn(32, obs) * 2
    assert torch.equal(child.norm(x), parent.norm(x))
    assert torch.equal(child.mean_action(x), parent.mean_action(x))
    assert torch.equal(child.value_head(x), parent.value_head(x))
    torch.manual_seed(5)
    sampled = child.sampler().sample(x)
    torch.manual_seed(5)
    for mine, theirs in zip(sampled, parent.sampler().sample(x), strict=True):
        assert torch.equal(mine, theirs)
    for key, value in parent.state_dict()["actor"].items():
        assert torch.equal(child.state_dict()["actor"][key], value), key


def test_a_child_with_its_actuators_in_another_order_acts_the_same_per_module() -> None:
    """The same four modules, listed in another order: every module's command and the
    value are the parent's when every module observes what it observed there."""
    obs, act = sizes(PARENT)
    parent = trained_looking(obs, act, seed=2)
    order = (2, 0, 3, 1)  # the child's actuator j is the parent's order[j]
    child = make_policy(obs, act, CONFIG)
    inherit(child, Inheritance(parent, order))
    x = torch.randn(16, obs)
    slots = observation_origins(order, act, obs)
    assert sorted(slots) == list(range(obs)) and slots != list(range(obs))
    seen = x[:, slots]  # the child's observation of the same state
    torch.testing.assert_close(child.mean_action(seen), parent.mean_action(x)[:, list(order)],
                               rtol=1e-5, atol=1e-6)
    torch.testing.assert_close(child.value_head(seen), parent.value_head(x), rtol=1e-5,
                               atol=1e-6)
    assert torch.equal(child.norm(seen), parent.norm(x)[:, slots])
    # A wrong map does not act the same: the test can fail.
    wrong = make_policy(obs, act, CONFIG)
    inherit(wrong, Inheritance(parent, tuple(range(act))))
    assert not torch.allclose(wrong.mean_action(seen), parent.mean_action(x)[:, list(order)])


def test_slots_without_a_counterpart_start_as_a_fresh_module() -> None:
    obs, act = sizes(PARENT)
    parent = trained_looking(obs, act, seed=3)
    torch.manual_seed(9)
    fresh = make_policy(obs + 2, act + 1, CONFIG)
    torch.manual_seed(9)
    child = make_policy(obs + 2, act + 1, CONFIG)
    actuators = (0, -1, 1, 2, 3)
    inherit(child, Inheritance(parent, actuators))
    first, p_first = child.head.mlp[0].weight, parent.head.mlp[0].weight
    assert torch.equal(first[:, 11:13], fresh.head.mlp[0].weight[:, 11:13])  # new actuator 1
    assert torch.equal(child.head.mlp[-1].weight[1], fresh.head.mlp[-1].weight[1])
    assert torch.equal(child.norm.mean[11:13], torch.zeros(2))
    assert torch.equal(first[:, 13:15], p_first[:, 11:13])  # child's 2 is the parent's 1
    assert torch.equal(child.head.mlp[-1].weight[4], parent.head.mlp[-1].weight[3])
    assert child.norm.count == parent.norm.count


def test_inherit_refuses_policies_that_do_not_fit() -> None:
    obs, act = sizes(PARENT)
    parent = trained_looking(obs, act, seed=4)
    with pytest.raises(ValueError, match="hidden layers"):
        inherit(make_policy(obs, act, LearnerConfig(hidden=(8, 8))),
                Inheritance(parent, tuple(range(act))))
    with pytest.raises(ValueError, match="observe_up"):
        inherit(make_policy(obs + 3, act, CONFIG), Inheritance(parent, tuple(range(act))))
    with pytest.raises(ValueError, match="does not map"):
        inherit(make_policy(obs, act, CONFIG), Inheritance(parent, (0, 1, 2, 7)))


# ---- correspondence through crossover and mutation --------------------------------------


def test_actuator_paths_are_the_models_actuator_order() -> None:
    built = build(PARENT, PhysicsParams())
    index = {p.path: i for i, p in enumerate(walk(PARENT.root))}
    names = [f"{'motor' if i < PARENT.n_motors else 'pivot'}{index[path]}"
             for i, path in enumerate(PARENT.actuator_paths())]
    assert tuple(names) == built.actuators


def test_a_crossover_childs_inherited_slots_equal_the_parent_slots_they_came_from() -> None:
    rng = np.random.default_rng(0)
    robots = random_robots(rng, 24)
    donors = 0  # children that took an actuator from the parent whose brain they lost
    for a, b in zip(robots[::2], robots[1::2], strict=True):
        result = crossover(a, b, rng)
        for child, origins in zip(result.offspring, result.origins, strict=True):
            placed = {p.path: p.node.type for p in walk(child.root)}
            assert set(origins) == set(placed)
            for path, (which, there) in origins.items():
                source = {p.path: p.node.type for p in walk((a, b)[which].root)}
                assert source[there] is placed[path], (path, which, there)
            start = policy_start("parent", child, [("a", a), ("b", b)], origins)
            assert start is not None
            parent_robot = a if start.parent == "a" else b
            donors += start.parent != ("a", "b")[origins[()][0]]
            check_slots(child, parent_robot, start.actuators)
    assert donors > 0, "no child inherited from the parent that gave the subtree"


def check_slots(child: Robot, parent_robot: Robot, actuators: tuple[int, ...]) -> None:
    """Each inherited slot of the child's networks holds the parent's value of the module
    it came from (same type, same slot)."""
    obs, act = sizes(child)
    parent = trained_looking(*sizes(parent_robot), seed=7)
    policy = make_policy(obs, act, CONFIG)
    inherit(policy, Inheritance(parent, actuators))
    kinds = [child.count(ModuleType.MOTOR) > j for j in range(act)]
    p_kinds = [parent_robot.count(ModuleType.MOTOR) > k for k in range(parent_robot.n_actuators)]
    for j, k in enumerate(actuators):
        if k < 0:
            continue
        assert kinds[j] == p_kinds[k], "a motor's slots went to a pivot or back"
        assert torch.equal(policy.head.mlp[-1].weight[j], parent.head.mlp[-1].weight[k])
        assert policy.head.log_std[j] == parent.head.log_std[k]
        for i in range(2):
            assert torch.equal(policy.head.mlp[0].weight[:, 9 + 2 * j + i],
                               parent.head.mlp[0].weight[:, 9 + 2 * k + i])
            assert torch.equal(policy.value_head.mlp[0].weight[:, 9 + 2 * j + i],
                               parent.value_head.mlp[0].weight[:, 9 + 2 * k + i])
            assert policy.norm.mean[9 + 2 * j + i] == parent.norm.mean[9 + 2 * k + i]


def test_modules_survive_a_mutation_unless_their_type_changes() -> None:
    changed = robot_of([edge(0, {"type": "main", "children": []}), edge(1, motor()),
                        edge(2, {"type": "pivot", "children": [edge(0, motor())]})])
    origins = surviving_origins(PARENT, changed)
    assert (0,) not in origins  # the motor turned main
    assert origins[(2, 0)] == (0, (2, 0)) and origins[(1,)] == (0, (1,))
    assert actuator_origins(changed, origins, 0, PARENT) == (1, 2, 3)
    grown = robot_of([edge(0, motor()), edge(1, motor()),
                      edge(2, {"type": "pivot", "children": [edge(0, motor())]}),
                      edge(3, motor(), rotation=90)])
    assert actuator_origins(grown, surviving_origins(PARENT, grown), 0, PARENT) == (0, 1, 2, -1, 3)


def test_the_start_is_the_parent_that_gave_most_actuators() -> None:
    other = robot_of([edge(0, motor())])
    origins = {p.path: (1, p.path) for p in walk(PARENT.root)}  # all from parent 1 ...
    origins[()] = (0, ())  # ... but the brain of parent 0
    start = policy_start("parent", PARENT, [("x", other), ("y", PARENT)], origins)
    assert start is not None and start.parent == "y" and start.actuators == (0, 1, 2, 3)
    origins[(0,)] = (0, (0,))  # motor 0 from x: 1 actuator against 3, still y
    start = policy_start("parent", PARENT, [("x", other), ("y", PARENT)], origins)
    assert start is not None and start.parent == "y" and start.actuators == (-1, 1, 2, 3)
    # A tie (one actuator from each) goes to the parent whose brain the child kept.
    tie = {(): (0, ()), (0,): (0, (0,)), (1,): (1, (1,))}
    one = robot_of([edge(0, motor()), edge(1, motor())])
    start = policy_start("parent", one, [("x", other), ("y", PARENT)], tie)
    assert start is not None and start.parent == "x" and start.actuators == (0, -1)
    assert policy_start("off", PARENT, [("x", other), ("y", PARENT)], origins) is None
    assert policy_start("parent", PARENT, [], {}) is None


# ---- the GA: records, budgets -----------------------------------------------------------


def fitness_of(candidate: Candidate, job: Job) -> Outcome:
    """A seeded fitness of the robot, no physics."""
    value = (hash((candidate.robot, candidate.seed)) % 1000) / 1000 - 1
    return Outcome(candidate.birth, candidate.name, fitness=value, env_steps=candidate.budget,
                   episodes=1)


def ga_of(inheritance: str, inherited: float = 1.0, population: int = 4,
          budget: int = 12) -> GAConfig:
    return GAConfig(population, budget, inheritance=inheritance,
                    schedule=BudgetSchedule(100, 200, 1000, inherited=inherited))


def history_of(run_dir: Path, ga: GAConfig, evaluate: Any = fitness_of,
               learner: LearnerConfig = CONFIG, env: EnvConfig | None = None) -> pd.DataFrame:
    job = Job(PhysicsParams(), env or EnvConfig(), learner, str(run_dir),
              record=RecordConfig(mcap=False, rerun=False))
    Evolution(RunStore(run_dir), ga=ga, strategy=Evolve(ga), job=job, executor=SerialExecutor(),
              seed=5, evaluate=evaluate).run()
    return pd.read_csv(run_dir / "history.csv", dtype={"inherited_from": str},
                       keep_default_na=False)


def test_inheriting_offspring_are_recorded_with_their_parent_and_smaller_budget(
    tmp_path: Path,
) -> None:
    off = history_of(tmp_path / "off", ga_of("off"))
    on = history_of(tmp_path / "on", ga_of("parent", inherited=0.5))
    assert (off["inherited_from"] == "").all()
    bred = on[on["parents"] != ""]
    assert len(bred) > 0 and (on[on["parents"] == ""]["inherited_from"] == "").all()
    assert all(row.inherited_from in row.parents.split(";") for row in bred.itertuples())
    # The same structures and seeds either way (inheritance draws no random numbers) ...
    assert off["name"].tolist()[:5] == on["name"].tolist()[:5]
    assert off["seed"].tolist() == on["seed"].tolist()
    # ... and an inheriting offspring gets half its scheduled budget.
    scheduled = ga_of("off").budgets()
    for row in on.itertuples():
        expected = scheduled[row.birth] // 2 if row.inherited_from else scheduled[row.birth]
        assert abs(row.budget - expected) <= 1, row


def test_mutated_offspring_inherit_the_modules_that_survived(tmp_path: Path) -> None:
    """Every offspring is also mutated: each actuator slot it inherits is a parent's
    actuator of the same type, and some are inherited."""
    seen: list[Candidate] = []

    def recording(candidate: Candidate, job: Job) -> Outcome:
        seen.append(candidate)
        return fitness_of(candidate, job)

    history_of(tmp_path, dataclasses.replace(ga_of("parent"), mutation_rate=1.0),
               evaluate=recording)
    mutated = [c for c in seen if c.operator == "crossover+mutation"]
    assert mutated and all(c.inherit in c.parents for c in mutated)
    store = RunStore(tmp_path)
    inherited = 0
    for c in mutated:
        child, parent = store.load_robot(c.name), store.load_robot(c.inherit)
        assert len(c.inherit_actuators) == child.n_actuators
        for j, k in enumerate(c.inherit_actuators):
            if k >= 0:
                inherited += 1
                assert (j < child.n_motors) == (k < parent.n_motors), (c.name, j, k)
    assert inherited > 0


def test_history_rows_of_older_runs_read_as_not_inherited() -> None:
    row = HistoryRow(0, "r", "E+L", (), "random", 1, 1, -1.0, True, "", 1, 1, 0.0, "", -1.0,
                     -1.0, "trained", float("nan"))
    record = row.record()
    assert record["inherited_from"] == ""
    del record["inherited_from"]
    assert HistoryRow.from_record(record) == row


def test_bad_inheritance_settings_are_named() -> None:
    with pytest.raises(ValueError, match="inheritance: expected one of off, parent"):
        GAConfig(inheritance="lamarck")
    with pytest.raises(ValueError, match="inherited must be in"):
        BudgetSchedule(inherited=0.0)
    on, off = ga_of("parent", inherited=0.25), ga_of("off", inherited=0.25)
    assert off.expected_budgets() == off.budgets() and min(off.budgets()) == 100
    assert on.expected_budgets()[:4] == on.budgets()[:4] and min(on.expected_budgets()) == 50


# ---- real training: the worker reads the parent's checkpoint; resume --------------------

TINY = PPO(num_envs=4, rollout_steps=32, epochs=1, minibatch_size=64, hidden=(16, 16))
SHORT = EnvConfig(task=Reach(t_max=40))


MAIN_TINY = [*EVOLUTION_TINY, "ga.inheritance=parent",
             "ga.schedule.inherited=0.5", "executor=serial", "record=off"]
"""A real, tiny serial evolution through ``python evo/main.py`` with inheritance on."""


@pytest.mark.slow
def test_a_sigkilled_run_resumes_an_inherited_evaluation_to_the_uninterrupted_history(
    tmp_path: Path,
) -> None:
    """SIGKILL at the end of the first offspring's training, before its policy is saved
    (``bench/kill_resume.py``'s driver); the resumed run trains it again from the same
    inherited start and ends with the uninterrupted run's history."""
    whole = tmp_path / "whole"
    done = run_main(main_cmd(*MAIN_TINY, f"hydra.run.dir={whole}"), tmp_path)
    assert done.returncode == 0, done.stderr[-3000:]
    run_dir = tmp_path / "killed"
    killed("checkpoint", 4, *MAIN_TINY, f"hydra.run.dir={run_dir}", cwd=tmp_path)
    (in_flight,) = json.loads((run_dir / "state.json").read_text())["pending"]
    assert in_flight["birth"] == 3 and in_flight["inherit"], in_flight
    done = run_main(main_cmd(f"resume={run_dir}"), tmp_path)
    assert done.returncode == 0, done.stderr[-3000:]
    expected, history = comparable(read_evolution_history(whole)), comparable(
        read_evolution_history(run_dir))
    inherited = expected[expected["inherited_from"] != ""]["name"]
    assert len(inherited) >= 1
    pd.testing.assert_frame_equal(history, expected)
    for name in inherited:  # trained again from the same start: the same weights
        a, b = (load_checkpoint(d / "evals" / f"{name}.pt") for d in (whole, run_dir))
        for key, value in a.state_dict()["actor"].items():
            assert torch.equal(value, b.state_dict()["actor"][key]), (name, key)


@pytest.mark.slow
def test_worker_processes_inherit_through_the_run_directory_with_early_rejection(
    tmp_path: Path,
) -> None:
    """Two spawned workers (``executor=local``) read the parents' checkpoints from the run
    directory; with early rejection on, every inheriting offspring is either trained
    or stopped against its own (halved) budget, none fails."""
    ga = dataclasses.replace(ga_of("parent", inherited=0.5, population=3, budget=5),
                             schedule=BudgetSchedule(128, 256, 256, inherited=0.5))
    job = Job(PhysicsParams(), SHORT, TINY, str(tmp_path),
              record=RecordConfig(mcap=False, rerun=False),
              early=EarlyRejection(enabled=True, checkpoints=(0.5,), margin=0.0, last=1))
    Evolution(RunStore(tmp_path), ga=ga, strategy=Evolve(ga), job=job,
              executor=LocalExecutor(workers=2), seed=5).run()
    history = pd.read_csv(tmp_path / "history.csv", dtype={"inherited_from": str},
                          keep_default_na=False)
    assert (history["error"] == "").all(), history["error"].tolist()
    inherited = history[history["inherited_from"] != ""]
    assert len(inherited) > 0, "no offspring inherited"
    assert set(inherited["status"]) <= {"trained", "stopped-early"}
    assert (inherited["budget"] == 128).all(), inherited["budget"].tolist()
    assert (inherited["env_steps"] <= inherited["budget"] + TINY.frames_per_batch).all()


def test_a_missing_parent_checkpoint_fails_the_evaluation_with_its_path(tmp_path: Path) -> None:
    candidate = Candidate(3, PARENT.name, PARENT.canonical_json(), 128, 1, ("gone", "x"),
                          "crossover", inherit="gone", inherit_actuators=(0, 1, 2, 3))
    job = Job(PhysicsParams(), SHORT, TINY, str(tmp_path),
              record=RecordConfig(mcap=False, rerun=False))
    outcome = evaluate(candidate, job)
    assert outcome.error is not None and "gone.pt: no such checkpoint" in outcome.error


CONF = Path(__file__).resolve().parents[1] / "conf"


@pytest.mark.parametrize("exp", sorted(p.stem for p in (CONF / "exp").glob("*.yaml")))
def test_inheritance_is_off_in_paper_and_ablation_configs_and_on_in_its_experiment(
    exp: str,
) -> None:
    from hydra import compose, initialize_config_dir

    with initialize_config_dir(config_dir=str(CONF), version_base=None):
        cfg = compose("config", overrides=[f"+exp={exp}"])
    ga = cfg.ga
    if exp.startswith(("paper", "ablation")):
        assert ga.inheritance == "off" and ga.schedule.inherited == 1.0
    if exp == "inheritance":
        assert ga.inheritance == "parent" and ga.schedule.inherited < 1.0
        paper = CONF / "exp" / "paper_clean.yaml"
        assert "paper_clean" in (CONF / "exp" / "inheritance.yaml").read_text() and paper.exists()
