"""The deployed controller: periodic deterministic evaluations, the policy kept at the
best of them, a mean bounded to the action box and an annealed spread (SPEC section 4)."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import torch

from evo.envs.params import EnvConfig, observation_size
from evo.envs.tasks.reach import Reach
from evo.learners.common import load_checkpoint, make_policy, save_checkpoint
from evo.learners.ppo import PPO
from evo.learners.ppo import train as train_ppo
from evo.learners.rollouts import evaluate_policy
from evo.robot import load_robot
from evo.robot.builder import PhysicsParams

FOUR_WHEELER = load_robot("robots/four_wheeler.json")
PHYSICS = PhysicsParams()
# tests/test_learners.py's small case: near targets, 200-step episodes, 60k env steps.
NEAR = EnvConfig(task=Reach(t_max=200, target_min=0.3, target_max=0.6))
BUDGET = 60_000
SMALL = PPO(num_envs=16, rollout_steps=64, epochs=10, minibatch_size=512)
WATCHED = dataclasses.replace(SMALL, eval_interval=12_000, eval_interval_episodes=8,
                              keep_best=True)
SEED = 1


pytestmark = pytest.mark.usefixtures("one_thread")


@pytest.fixture(scope="module")
def watched():  # noqa: ANN201
    """The small case trained with periodic evaluations and the best policy kept."""
    return train_ppo(FOUR_WHEELER, physics=PHYSICS, env=NEAR, config=WATCHED, budget=BUDGET,
                     seed=SEED)


def test_the_evaluations_leave_the_training_as_it_was(watched) -> None:  # noqa: ANN001
    """They take no random numbers and no env steps of the training's: with them on, the
    curve up to two batches past the first evaluation is the one without them."""
    batches = WATCHED.eval_interval // SMALL.frames_per_batch + 2
    plain = train_ppo(FOUR_WHEELER, physics=PHYSICS, env=NEAR, config=SMALL, budget=BUDGET,
                      seed=SEED, on_curve=lambda row: row["env_steps"] >= batches
                      * SMALL.frames_per_batch)
    assert len(plain.curve) == batches
    first = watched.curve.iloc[:batches]
    assert first["eval/success_rate"].notna().any(), "an evaluation among them"
    train_keys = [c for c in plain.curve.columns if c != "wall_seconds"]
    pd.testing.assert_frame_equal(first[train_keys].reset_index(drop=True),
                                  plain.curve[train_keys])
    assert watched.env_steps == math.ceil(BUDGET / SMALL.frames_per_batch) * (
        SMALL.frames_per_batch)


def test_evaluations_come_at_each_interval_and_after_the_last_batch(watched) -> None:  # noqa: ANN001
    curve = watched.curve
    evaluated = curve.dropna(subset=["eval/success_rate"])
    steps = evaluated["env_steps"].to_numpy()
    final, interval = int(curve["env_steps"].iloc[-1]), WATCHED.eval_interval
    crossed = final // interval > (final - SMALL.frames_per_batch) // interval
    assert len(evaluated) == final // interval + (0 if crossed else 1), steps
    assert steps[-1] == final, "one after the last batch"
    # Each is the first batch at or past its multiple of the interval.
    for k, at in enumerate(steps[:-1], start=1):
        assert at >= k * WATCHED.eval_interval > at - SMALL.frames_per_batch
    assert curve["eval/mean_return"].notna().sum() == len(evaluated)
    assert ((curve["train/mean_outside"] >= 0) & (curve["train/mean_outside"] <= 1)).all()
    assert (curve["train/action_std"] > 0).all()


def test_the_kept_policy_is_the_one_that_scored_best(watched) -> None:  # noqa: ANN001
    """Evaluated again on the periodic evaluations' episodes (seed + 2), the handed-back
    policy scores the best row of the curve, and its env steps are that row's."""
    evaluated = watched.curve.dropna(subset=["eval/success_rate"])
    again = evaluate_policy(FOUR_WHEELER, watched.policy, physics=PHYSICS, env=NEAR,
                            episodes=WATCHED.eval_interval_episodes, seed=SEED + 2)
    scores = list(zip(evaluated["eval/success_rate"], evaluated["eval/mean_return"],
                      strict=True))
    best = max(range(len(scores)), key=lambda i: scores[i])  # the first of equals
    assert (again.success_rate, again.mean_return) == pytest.approx(scores[best])
    assert watched.kept_at == evaluated["env_steps"].iloc[best]


def test_the_kept_policy_is_written_and_read_back_as_it_acts(watched, tmp_path: Path) -> None:  # noqa: ANN001
    """What a run writes to ``policy.pt`` (and a resumed run, an offspring or a replay
    reads) is the kept policy."""
    loaded = load_checkpoint(save_checkpoint(watched.policy, tmp_path / "p.pt", WATCHED))
    obs = torch.randn(64, observation_size(FOUR_WHEELER, NEAR.task)) * 3
    torch.testing.assert_close(loaded.mean_action(obs), watched.policy.mean_action(obs),
                               rtol=0, atol=0)


def test_deterministic_success_matches_the_noisy_policys(watched) -> None:  # noqa: ANN001
    """A robot that can do the task: the deployed (mean) action succeeds as often as the
    policy with its noise, within 0.05, on 20 episodes neither was chosen on."""
    deterministic, noisy = (
        evaluate_policy(FOUR_WHEELER, watched.policy, physics=PHYSICS, env=NEAR, episodes=20,
                        seed=99, stochastic=stochastic) for stochastic in (False, True))
    assert noisy.success_rate >= 0.6, noisy
    assert deterministic.success_rate >= noisy.success_rate - 0.05, (deterministic, noisy)


def test_a_stochastic_evaluation_is_seeded_and_leaves_torchs_generator_alone(watched) -> None:  # noqa: ANN001
    state = torch.random.get_rng_state()
    runs = [evaluate_policy(FOUR_WHEELER, watched.policy, physics=PHYSICS, env=NEAR, episodes=4,
                            seed=s, stochastic=True) for s in (7, 7)]
    assert runs[0] == runs[1]
    assert torch.equal(torch.random.get_rng_state(), state)


def test_a_bounded_mean_stays_in_the_action_box_and_survives_its_checkpoint(
    tmp_path: Path,
) -> None:
    config = PPO(bound_mean=True, policy_out_gain=50.0)  # a mean far outside, unbounded
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(0)
        policy = make_policy(12, 3, config)
        torch.manual_seed(0)
        unbounded = make_policy(12, 3, dataclasses.replace(config, bound_mean=False))
    obs = torch.randn(256, 12) * 3
    assert policy.mean_action(obs).abs().max() <= 1
    assert unbounded.mean_action(obs).abs().max() > 1
    torch.testing.assert_close(policy.mean_action(obs), torch.tanh(unbounded.mean_action(obs)))
    loaded = load_checkpoint(save_checkpoint(policy, tmp_path / "p.pt", config))
    torch.testing.assert_close(loaded.mean_action(obs), policy.mean_action(obs), rtol=0, atol=0)


@pytest.mark.parametrize("anneal_from", [0.0, 0.5])
def test_an_annealed_spread_stays_under_its_bound(anneal_from: float) -> None:
    """The batches' standard deviation is at most the bound, which stays at
    ``init_log_std`` until ``anneal_from`` of the budget and then falls linearly to
    ``final_log_std`` at its end."""
    config = dataclasses.replace(SMALL, init_log_std=-0.5, final_log_std=-2.0,
                                 anneal_from=anneal_from)
    budget = 4 * SMALL.frames_per_batch
    result = train_ppo(FOUR_WHEELER, physics=PHYSICS, env=NEAR, config=config, budget=budget,
                       seed=3)
    before = (result.curve["env_steps"] - SMALL.frames_per_batch).to_numpy()
    start = anneal_from * budget
    bound = np.exp(-0.5 + (-2.0 + 0.5) * np.clip(before - start, 0, None) / (budget - start))
    stds = result.curve["train/action_std"].to_numpy()
    assert (stds <= bound + 1e-6).all(), (stds, bound)
    assert stds[-1] < stds[0] and stds[-1] == pytest.approx(bound[-1], rel=1e-5)


@pytest.mark.parametrize("anneal_lr", [True, False])
def test_the_learning_rate_falls_to_zero_only_when_annealed(anneal_lr: bool) -> None:
    """Annealed, each batch's update runs at ``lr`` times the share of the budget left
    before the batch; held, at ``lr`` to the last batch (the deployed controller's
    setting: the mean action learns later than the noisy policy)."""
    config = dataclasses.replace(SMALL, lr=1e-3, anneal_lr=anneal_lr)
    budget = 4 * SMALL.frames_per_batch
    result = train_ppo(FOUR_WHEELER, physics=PHYSICS, env=NEAR, config=config, budget=budget,
                       seed=3)
    before = (result.curve["env_steps"] - SMALL.frames_per_batch).to_numpy()
    expected = 1e-3 * (1 - before / budget) if anneal_lr else np.full(len(before), 1e-3)
    np.testing.assert_allclose(result.curve["train/lr"].to_numpy(), expected, rtol=1e-6)


def test_the_handed_back_actor_is_the_mean_of_the_weights_after_each_update_averaged() -> None:
    """``average_from``: the training acts as without it (the same curve), and hands back
    the actor whose weights are the mean of those after each update from that share of
    the budget on: here the last two of four batches, the last policies of the same
    training stopped after three batches and run to the end without averaging."""
    config = dataclasses.replace(SMALL, anneal_lr=False, eval_interval=SMALL.frames_per_batch,
                                 eval_interval_episodes=2)
    batch = SMALL.frames_per_batch

    def trained(budget: int, **fields: object):  # noqa: ANN202
        return train_ppo(FOUR_WHEELER, physics=PHYSICS, env=NEAR, budget=budget, seed=3,
                         config=dataclasses.replace(config, **fields))  # type: ignore[arg-type]

    averaged, plain, third = trained(4 * batch, average_from=0.75), trained(4 * batch), \
        trained(3 * batch)
    keys = [c for c in plain.curve.columns if c.startswith("train/") or c == "env_steps"]
    pd.testing.assert_frame_equal(averaged.curve[keys], plain.curve[keys])
    assert averaged.fitness == plain.fitness
    mine = dict(averaged.policy.actor.named_parameters())
    before = dict(third.policy.actor.named_parameters())
    for name, last in plain.policy.actor.named_parameters():
        torch.testing.assert_close(mine[name], (before[name] + last) / 2)
    assert any(not torch.equal(mine[name], last)
               for name, last in plain.policy.actor.named_parameters()), "not the last policy"
    # the periodic evaluations of the averaged batches are of the averaged actor
    last = evaluate_policy(FOUR_WHEELER, averaged.policy, physics=PHYSICS, env=NEAR,
                           episodes=2, seed=3 + 2)
    assert averaged.curve["eval/mean_return"].iloc[-1] == pytest.approx(last.mean_return)
    assert averaged.evaluation == (last.success_rate, last.mean_return)


@pytest.mark.parametrize(("fields", "message"), [
    (dict(keep_best=True), "keep_best needs periodic evaluations"),
    (dict(eval_interval=-1), "eval_interval must be >= 0"),
    (dict(eval_interval_episodes=0), "eval_interval_episodes must be >= 1"),
    (dict(final_log_std=3.0), "final_log_std must be in"),
    (dict(anneal_from=1.0), "anneal_from must be in"),
    (dict(average_from=1.0), "average_from must be in"),
])
def test_bad_settings_name_their_key(fields: dict[str, object], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        PPO(**fields)  # type: ignore[arg-type]


def test_a_runs_history_carries_the_deterministic_evaluation_beside_the_fitness(
    tmp_path: Path,
) -> None:
    """With ``learner.eval_interval`` every trained robot's row has the success rate and
    return of its handed-back policy's periodic evaluation; without it the cells are
    empty (a run of before reads the same)."""
    from test_evolution import TINY, main_cmd, run

    from evo.run.records import read_history

    run_dir = tmp_path / "run"
    done = run(main_cmd(*TINY, "executor=serial", "learner.eval_interval=256",
                        "learner.eval_interval_episodes=2", "learner.keep_best=true",
                        f"hydra.run.dir={run_dir}"), tmp_path)
    assert done.returncode == 0, done.stderr[-3000:]
    history = read_history(run_dir / "history.csv")
    assert history["eval_success_rate"].between(0, 1).all(), history
    assert history["eval_mean_return"].notna().all()
    # analysis reads both: the robots table carries them and the report shows them
    from analysis.ablation.report import deployed_table
    from analysis.load import load_runs

    robots = load_runs([run_dir]).robots
    assert robots["eval_success_rate"].tolist() == history["eval_success_rate"].tolist()
    (row,) = deployed_table(robots).itertuples()
    assert row.evaluated == len(history)
    assert row.eval_success_rate == pytest.approx(history["eval_success_rate"].mean())
    assert row.fitness == pytest.approx(history["fitness"].mean())


def test_a_controller_that_observes_its_stall_ranges_and_clock_deploys_only_where_they_are_given(
    tmp_path: Path,
) -> None:
    """``env.task.observe_stall`` adds one input to the policy, ``observe_range``
    ``range_sectors``, ``observe_clock`` two; the checkpoint runs in an env that gives
    them and is refused, naming the keys, by one that does not."""
    task = dataclasses.replace(NEAR.task, observe_stall=True, observe_range=True, range_sectors=4,
                               observe_clock=True)
    sensing = dataclasses.replace(NEAR, task=task)
    plain_size = observation_size(FOUR_WHEELER, NEAR.task)
    result = train_ppo(FOUR_WHEELER, physics=PHYSICS, env=sensing, config=SMALL,
                       budget=4 * SMALL.frames_per_batch, seed=SEED)
    assert result.policy.head.mlp[0].in_features == plain_size + 1 + 4 + 2
    path = save_checkpoint(result.policy, tmp_path / "p.pt", SMALL)
    loaded = load_checkpoint(path, obs_size=observation_size(FOUR_WHEELER, task))
    evaluation = evaluate_policy(FOUR_WHEELER, loaded, physics=PHYSICS, env=sensing,
                                 episodes=2, seed=0)
    assert len(evaluation.returns) == 2
    with pytest.raises(ValueError, match="observe_stall 1, env.task.observe_range"):
        load_checkpoint(path, obs_size=plain_size)
