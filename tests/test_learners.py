"""Learners: PPO learns, the random learner does not, results are consistent and seeded."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import torch

from evo.components.inheritance import policy_start
from evo.edge import compose_config, typed_config
from evo.envs.params import EnvConfig, observation_size
from evo.envs.tasks.reach import Reach
from evo.learners.common import (
    Inheritance,
    LearnerConfig,
    load_checkpoint,
    make_policy,
    save_checkpoint,
)
from evo.learners.ppo import PPO
from evo.learners.ppo import train as train_ppo
from evo.learners.rollouts import evaluate_policy
from evo.robot import load_robot, parse_robot
from evo.robot.builder import PhysicsParams
from evo.robot.operators import surviving_origins

FOUR_WHEELER = load_robot("robots/four_wheeler.json")
OBS = observation_size(FOUR_WHEELER, Reach())
PHYSICS = PhysicsParams()
# A shorter task than the paper's (nearer targets, 200-step episodes) so that learning
# shows within a test-sized budget; the full task is exercised by bench/train_throughput.py.
NEAR = EnvConfig(task=Reach(t_max=200, target_min=0.3, target_max=0.6))
BUDGET = 60_000  # env steps: three seeds tried all reach 100% deterministic success
SMALL = PPO(num_envs=16, rollout_steps=64, epochs=10, minibatch_size=512)


def curve_without_time(curve: pd.DataFrame) -> pd.DataFrame:
    return curve.drop(columns=["wall_seconds"])


pytestmark = pytest.mark.usefixtures("one_thread")


@pytest.fixture(scope="module")
def ppo_run():  # noqa: ANN201
    return train_ppo(FOUR_WHEELER, physics=PHYSICS, env=NEAR, config=SMALL, budget=BUDGET, seed=1)


@pytest.fixture(scope="module")
def random_run():  # noqa: ANN201
    random = dataclasses.replace(SMALL, update=False)  # conf/learner/random
    return random.train_function()(
        FOUR_WHEELER, physics=PHYSICS, env=NEAR, config=random, budget=BUDGET, seed=1
    )


def test_ppo_clearly_beats_the_random_learner(ppo_run, random_run) -> None:  # noqa: ANN001
    assert ppo_run.fitness > random_run.fitness + 0.3, (ppo_run.fitness, random_run.fitness)
    ppo_eval = evaluate_policy(
        FOUR_WHEELER, ppo_run.policy, physics=PHYSICS, env=NEAR, episodes=20, seed=99
    )
    random_eval = evaluate_policy(
        FOUR_WHEELER, random_run.policy, physics=PHYSICS, env=NEAR, episodes=20, seed=99
    )
    assert ppo_eval.success_rate >= 0.6, ppo_eval
    assert ppo_eval.success_rate >= random_eval.success_rate + 0.4, (ppo_eval, random_eval)
    late = ppo_run.curve["train/success_rate"].iloc[-4:].mean()
    early = ppo_run.curve["train/success_rate"].iloc[:4].mean()
    assert late > early, f"success rate did not rise during training: {early} -> {late}"


def test_fitness_is_the_mean_of_completed_episode_returns(ppo_run, random_run) -> None:  # noqa: ANN001
    for run in (ppo_run, random_run):
        curve = run.curve.dropna(subset=["train/mean_return"])
        expected = ((curve["train/mean_return"] * curve["train/episodes"]).sum()
                    / curve["train/episodes"].sum())
        assert run.fitness == pytest.approx(expected, rel=1e-5)
        assert run.episodes == int(run.curve["train/episodes"].sum())


def test_budget_is_respected_within_one_batch(ppo_run) -> None:  # noqa: ANN001
    batch = SMALL.frames_per_batch
    assert BUDGET <= ppo_run.env_steps < BUDGET + batch
    assert ppo_run.curve["env_steps"].tolist() == [
        float(batch * (i + 1)) for i in range(len(ppo_run.curve))
    ]


def learner_of(overrides: list[str]) -> LearnerConfig:
    """The learner ``python evo/main.py <overrides>`` trains with."""
    return typed_config(compose_config(overrides)).learner


@pytest.mark.parametrize(
    "overrides", [["+exp=train"], ["+exp=paper_clean"]], ids=["one-robot learner", "paper learner"]
)
def test_same_seed_same_curve_different_seed_different_curve(overrides: list[str]) -> None:
    """At the one-robot learner's settings (``+exp=train``: 128 arenas x 16 steps) and the
    paper's (12 x 128, minibatch 512), two batches each: the seed alone fixes the curve."""
    config = learner_of(overrides)
    budget = 2 * config.frames_per_batch
    runs = [
        train_ppo(FOUR_WHEELER, physics=PHYSICS, env=NEAR, config=config, budget=budget, seed=s)
        for s in (5, 5, 6)
    ]
    assert len(runs[0].curve) == 2
    pd.testing.assert_frame_equal(
        curve_without_time(runs[0].curve), curve_without_time(runs[1].curve)
    )
    assert not curve_without_time(runs[0].curve).equals(curve_without_time(runs[2].curve))


def test_reloaded_checkpoint_acts_identically(ppo_run, tmp_path: Path) -> None:  # noqa: ANN001
    path = save_checkpoint(ppo_run.policy, tmp_path / "policy.pt", SMALL)
    state = torch.load(path, weights_only=True)  # the checkpoint is plain tensors and numbers
    assert state["obs_size"] == OBS
    loaded = load_checkpoint(path)
    obs = torch.randn(64, OBS) * 3
    torch.testing.assert_close(
        loaded.mean_action(obs), ppo_run.policy.mean_action(obs), rtol=0, atol=0
    )


def test_bad_checkpoint_is_named(tmp_path: Path) -> None:
    bad = tmp_path / "bad.pt"
    torch.save({"something": 1}, bad)
    with pytest.raises(ValueError, match="bad.pt: not an evo policy checkpoint"):
        load_checkpoint(bad)
    with pytest.raises(ValueError, match="no such checkpoint"):
        load_checkpoint(tmp_path / "missing.pt")


def test_random_learner_never_changes_its_weights(ppo_run, random_run) -> None:  # noqa: ANN001
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(1)
        initial = make_policy(OBS, FOUR_WHEELER.n_actuators, SMALL)
    start, after_random = initial.state_dict(), random_run.policy.state_dict()
    for part in ("actor", "critic"):
        for key, value in start[part].items():
            torch.testing.assert_close(after_random[part][key], value, rtol=0, atol=0)
    # The same comparison does see PPO's training.
    trained = ppo_run.policy.state_dict()["actor"]
    assert any(not torch.equal(trained[k], v) for k, v in start["actor"].items())
    assert np.isnan(random_run.curve["train/loss/objective"]).all()


def test_mean_action_is_the_deterministic_action(ppo_run) -> None:  # noqa: ANN001
    """``mean_action`` is what TorchRL's actor gives in deterministic exploration mode."""
    from tensordict import TensorDict
    from torchrl.envs.utils import ExplorationType, set_exploration_type

    obs = torch.randn(32, OBS) * 3
    with torch.no_grad(), set_exploration_type(ExplorationType.DETERMINISTIC):
        actor = ppo_run.policy.actor(TensorDict({"observation": obs}, batch_size=[32]))
    torch.testing.assert_close(ppo_run.policy.mean_action(obs), actor["action"], rtol=0, atol=0)


def test_collector_sampler_draws_from_the_actor_distribution_with_its_log_prob() -> None:
    from tensordict import TensorDict

    policy = make_policy(6, 3, LearnerConfig(init_log_std=-0.7))
    policy.norm.update(torch.randn(50, 6) * 3 + 1)
    observation = torch.randn(4, 6).repeat(5000, 1)
    with torch.no_grad():
        out = policy.sampler()(TensorDict({"observation": observation}, batch_size=[20000]))
        dist = policy.actor.get_dist(TensorDict({"observation": observation}, batch_size=[20000]))
        expected = dist.log_prob(out["action"])
    torch.testing.assert_close(out["action_log_prob"], expected, rtol=1e-5, atol=1e-5)
    torch.testing.assert_close(out["loc"], dist.base_dist.loc)
    # The draws follow the actor's Gaussian: per observation, mean loc and std exp(-0.7).
    actions = out["action"].reshape(5000, 4, 3)
    torch.testing.assert_close(actions.mean(0), out["loc"][:4], atol=0.03, rtol=0)
    torch.testing.assert_close(actions.std(0), torch.full((4, 3), np.exp(-0.7)), atol=0.02,
                               rtol=0)


def test_an_inherited_offspring_starts_better_than_a_fresh_policy(ppo_run) -> None:  # noqa: ANN001
    """An offspring of the trained four-wheeler (the same modules, and a passive block
    grown on the brain's side) that starts from the parent's policy gains more reward in
    its first collector batch than a fresh policy on the same body, under the same seed."""
    child = parse_robot({**FOUR_WHEELER.to_dict(), "root": {**FOUR_WHEELER.to_dict()["root"],
                         "children": [*FOUR_WHEELER.to_dict()["root"]["children"],
                                      {"face": 2, "rotation": 0, "module": {"type": "main"}}]}},
                        source="child")
    start = policy_start("parent", child, [("parent", FOUR_WHEELER)],
                         surviving_origins(FOUR_WHEELER, child))
    assert start is not None and start.actuators == (0, 1, 2)

    def first_batch(inheritance: Inheritance | None) -> pd.Series:
        result = train_ppo(child, physics=PHYSICS, env=NEAR, config=SMALL,
                           budget=SMALL.frames_per_batch, seed=4, start=inheritance)
        return result.curve.iloc[0]

    inherited = first_batch(Inheritance(ppo_run.policy, start.actuators))
    fresh = first_batch(None)
    reward = [sum(row[f"train/reward/{t}"] for t in ("time", "approach", "success"))
              for row in (inherited, fresh)]
    assert reward[0] > reward[1] + 1e-3, (reward, inherited["train/episodes"])
    assert inherited["train/reward/approach"] > 2 * fresh["train/reward/approach"], (
        inherited["train/reward/approach"], fresh["train/reward/approach"])
