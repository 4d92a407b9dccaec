"""PPO on the batched ``TaskEnv`` through TorchRL: collector, GAE and ``ClipPPOLoss``.

``train`` reads top to bottom: build the env and networks, then for every collector
batch compute advantages, run ``epochs`` passes of minibatch updates, fold the batch
into the observation statistics, and append one learning-curve row. With
``update=False`` the same loop only collects: that is the random learner (the "R"
behaviour of the paper's ablations), which takes the same env steps so its fitness is
comparable.

Learning-curve row (one per collector batch; every value a float):

* ``env_steps``: env steps taken so far; ``wall_seconds``: since the start of training
  (the two axes, unprefixed);
* ``train/episodes``: episodes completed in the batch;
* ``train/mean_return``, ``train/success_rate``, ``train/episode_length``: over the
  episodes completed in the batch (NaN when none completed);
* ``train/reward/<term>``: mean per env step of each reward term in the batch;
* ``train/loss/objective``, ``train/loss/critic``, ``train/loss/entropy``,
  ``train/entropy``, ``train/kl``, ``train/clip_fraction``, ``train/lr``: means over the
  batch's minibatch updates (NaN when the learner does not update);
* ``train/action_std``: the policy's standard deviation in the batch (mean over action
  dimensions); ``train/mean_outside``: the share of the batch's mean actions outside the
  action box [-1, 1], where the env clips every action the same;
* with ``eval_interval``: ``eval/success_rate`` and ``eval/mean_return`` of the periodic
  deterministic evaluation after the batch's update (NaN in the rows without one).
"""

from __future__ import annotations

import copy
import math
import time
from collections.abc import Iterable, Iterator
from contextlib import contextmanager, nullcontext
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd
import torch
from tensordict import TensorDictBase
from torch.optim.swa_utils import AveragedModel
from torchrl.collectors import Collector
from torchrl.objectives import ClipPPOLoss
from torchrl.objectives.value import GAE

from evo.envs.params import EnvConfig
from evo.envs.scene import Scene, compile_scene
from evo.envs.torchrl_env import TaskEnv, make_env
from evo.learners import CurveHook, EpisodeHook, Learner
from evo.learners.common import (
    Inheritance,
    LearnerConfig,
    Policy,
    RunningNorm,
    TrainResult,
    inherit,
    make_policy,
)
from evo.learners.rollouts import evaluate_policy
from evo.robot.builder import PhysicsParams
from evo.robot.tree import Robot

_LOSS_KEYS = {
    "train/loss/objective": "loss_objective",
    "train/loss/critic": "loss_critic",
    "train/loss/entropy": "loss_entropy",
    "train/entropy": "entropy",
    "train/kl": "kl_approx",
    "train/clip_fraction": "clip_fraction",
}
"""Curve keys of the update's statistics and the ClipPPOLoss outputs they average."""


def _completed(batch: TensorDictBase) -> dict[str, torch.Tensor]:
    """Return, success and length of every episode that ended in ``batch``."""
    nxt = batch["next"]
    done = nxt["done"].squeeze(-1)
    return {
        "return": nxt["episode_return"].squeeze(-1)[done],
        "success": nxt["success"].squeeze(-1)[done].float(),
        "length": nxt["episode_length"].squeeze(-1)[done].float(),
    }


def _episode_stats(episodes: dict[str, torch.Tensor]) -> dict[str, float]:
    n = int(episodes["return"].numel())
    nan = float("nan")
    return {
        "train/episodes": float(n),
        "train/mean_return": float(episodes["return"].mean()) if n else nan,
        "train/success_rate": float(episodes["success"].mean()) if n else nan,
        "train/episode_length": float(episodes["length"].mean()) if n else nan,
    }


def _update(
    batch: TensorDictBase,
    loss: ClipPPOLoss,
    optimizer: torch.optim.Optimizer,
    config: LearnerConfig,
) -> dict[str, float]:
    """``epochs`` passes of shuffled minibatch PPO updates over ``batch``."""
    # Only the keys the loss reads: indexing a minibatch then costs a handful of tensors,
    # not the collector's thirty.
    keys = loss.tensor_keys
    flat = batch.select(*loss.in_keys, keys.advantage, keys.value_target, strict=False)
    flat = flat.reshape(-1)
    sums: dict[str, float] = dict.fromkeys(_LOSS_KEYS, 0.0)
    count = 0
    for _ in range(config.epochs):
        for index in torch.split(torch.randperm(flat.numel()), config.minibatch_size):
            out = loss(flat[index])
            total = out["loss_objective"] + out["loss_critic"] + out["loss_entropy"]
            optimizer.zero_grad()
            total.backward()
            torch.nn.utils.clip_grad_norm_(loss.parameters(), config.max_grad_norm)
            optimizer.step()
            for name, key in _LOSS_KEYS.items():
                if key in out:
                    sums[name] += float(out[key].detach().mean())
            count += 1
    return {name: value / count for name, value in sums.items()}


@dataclass(frozen=True, slots=True)
class PPO(LearnerConfig):
    """PPO's settings (``conf/learner/ppo.yaml``, ``_target_: evo.learners.ppo.PPO``): the
    fields of :class:`~evo.learners.common.LearnerConfig`; with ``update`` false the
    random learner (``conf/learner/random.yaml``)."""

    @property
    def name(self) -> str:
        """``ppo``, or ``random`` for the policy never updated."""
        return "ppo" if self.update else "random"

    def train_function(self) -> Learner:
        return train


def train(
    robot: Robot,
    *,
    physics: PhysicsParams,
    env: EnvConfig,
    config: LearnerConfig,
    budget: int,
    seed: int,
    on_curve: CurveHook | None = None,
    on_episode: EpisodeHook | None = None,
    start: Inheritance | None = None,
    scene: Scene | None = None,
) -> TrainResult:
    """Train ``robot``'s behaviour for ``budget`` env steps (or only collect, if
    ``config.update`` is false) and return its fitness, curve and policy.

    Randomness comes only from ``seed`` (targets, rocks, network initialisation, action
    noise, minibatch order); torch's global generator is left as it was. ``on_curve``
    gets every curve row (and stops training after a batch when it returns True),
    ``on_episode`` every episode of arena 0 frame by frame. With ``start`` the networks
    begin as a parent's, slot-mapped onto this body (``evo.learners.common.inherit``);
    the fresh networks are drawn first all the same, so the rest of the seed's random
    numbers do not depend on it. ``scene`` is the robot's compiled arena when the caller
    has it (compiled here otherwise).
    """
    if budget < 1:
        raise ValueError(f"budget must be >= 1 env step, got {budget}")
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        return _train(robot, physics, env, config, budget, seed, on_curve, on_episode, start,
                      scene)


def _objective(
    policy: Policy, config: LearnerConfig
) -> tuple[ClipPPOLoss, GAE, torch.optim.Optimizer]:
    """The clipped PPO loss (paper Eqs. 6-7), its advantage estimator and optimiser."""
    loss = ClipPPOLoss(
        policy.actor,
        policy.critic,
        clip_epsilon=config.clip_epsilon,
        entropy_coeff=config.entropy_coeff,
        critic_coeff=config.critic_coeff,
        loss_critic_type="l2",
        normalize_advantage=True,
        functional=False,  # plain modules: the same numbers without per-call parameter swaps
    )
    gae = GAE(
        gamma=config.gamma, lmbda=config.lmbda, value_network=policy.critic, deactivate_vmap=True
    )
    # foreach: one vectorised Adam step over all parameters, the same numbers as the loop.
    return loss, gae, torch.optim.Adam(loss.parameters(), lr=config.lr, foreach=True)


class RewardScale:
    """Rewards divided by the running standard deviation of the discounted return
    (``reward_scaling``; Engstrom et al. 2020, CleanRL's ``NormalizeReward``).

    The discounted return of every arena runs on across batches and restarts when an
    episode ends; the update sees the scaled rewards, the curve the env's own.
    """

    def __init__(self, num_envs: int, gamma: float) -> None:
        self.gamma = gamma
        self.returns = torch.zeros(num_envs, 1)
        self.stats = RunningNorm(1)

    def __call__(self, batch: TensorDictBase) -> None:
        """Scale ``batch``'s rewards (arenas x time x 1) in place."""
        reward, done = batch["next", "reward"], batch["next", "done"]
        seen = torch.empty_like(reward)
        for t in range(reward.shape[-2]):
            self.returns = self.returns * self.gamma + reward[..., t, :]
            seen[..., t, :] = self.returns
            self.returns = torch.where(done[..., t, :], 0.0, self.returns)
        self.stats.update(seen)
        batch.set(("next", "reward"), reward / torch.sqrt(self.stats.var + 1e-8))


def _batch_row(batch: TensorDictBase, steps: int, episodes: dict[str, torch.Tensor],
               terms: tuple[str, ...]) -> dict[str, float]:
    """The curve row's env-step count, episode statistics, reward terms (the task's
    ``terms``) and the policy's spread and mean actions of a batch."""
    row = {"env_steps": float(steps), **_episode_stats(episodes)}
    for term in terms:
        row[f"train/reward/{term}"] = float(batch["next", "reward_terms", term].mean())
    row["train/action_std"] = float(batch["scale"].mean())
    row["train/mean_outside"] = float((batch["loc"].abs() > 1).float().mean())
    return row


class PeriodicEvaluation:
    """The periodic deterministic evaluations of one training (``eval_interval``), and
    with ``keep_best`` a copy of the policy that scored best (success, then return).

    Each runs ``eval_interval_episodes`` episodes under ``seed + 2`` in arenas of their
    own (``evo.learners.rollouts.evaluate_policy``): the same targets every time, and no
    random numbers of the training's.
    """

    KEYS = ("eval/success_rate", "eval/mean_return")

    def __init__(self, robot: Robot, physics: PhysicsParams, env: EnvConfig,
                 config: LearnerConfig, seed: int, scene: Scene) -> None:
        self.robot, self.physics, self.env, self.scene = robot, physics, env, scene
        self.config, self.seed = config, seed
        self.done = 0  # evaluations so far
        self.best: tuple[float, float] | None = None
        self.last: tuple[float, float] | None = None
        self.best_state: dict[str, Any] | None = None
        self.best_steps = 0
        self.seconds = 0.0

    def __call__(self, policy: Policy, steps: int, last: bool) -> dict[str, float]:
        """The row's ``eval/`` values: an evaluation's when ``steps`` reached the next
        multiple of the interval or the batch is the last, NaN otherwise."""
        if steps // self.config.eval_interval <= self.done and not last:
            return dict.fromkeys(self.KEYS, float("nan"))
        tick = time.perf_counter()
        self.done = max(self.done + 1, steps // self.config.eval_interval)
        result = evaluate_policy(self.robot, policy, physics=self.physics, env=self.env,
                                 episodes=self.config.eval_interval_episodes,
                                 seed=self.seed + 2, scene=self.scene)
        score = self.last = (result.success_rate, result.mean_return)
        if self.config.keep_best and (self.best is None or score > self.best):
            self.best, self.best_steps = score, steps
            self.best_state = copy.deepcopy(
                {"actor": policy.actor.state_dict(), "critic": policy.critic.state_dict()})
        self.seconds += time.perf_counter() - tick
        return dict(zip(self.KEYS, score, strict=True))

    def finish(self, policy: Policy, timing: dict[str, float]
               ) -> tuple[int | None, tuple[float, float] | None]:
        """Load the best evaluation's weights into ``policy`` and move the evaluations'
        seconds from ``timing``'s update to its ``eval``. Returns the env steps the kept
        policy was evaluated at (None without ``keep_best``) and the handed-back
        policy's evaluation (the best, or the last)."""
        timing["update"] -= self.seconds
        timing["eval"] = self.seconds
        if self.best_state is None:
            return None, self.last
        policy.actor.load_state_dict(self.best_state["actor"])
        policy.critic.load_state_dict(self.best_state["critic"])
        return self.best_steps, self.best


class WeightAverage:
    """The actor's weights averaged over the updates from ``average_from`` of the budget
    on (``torch.optim.swa_utils.AveragedModel``: the uniform mean of the weights after
    each batch's update). The training acts with the current weights; the periodic
    evaluations from then on, and the policy handed back, use the averaged ones with the
    current observation statistics (buffers are not averaged)."""

    def __init__(self, policy: Policy, start: float) -> None:
        self.start = start
        self.model = AveragedModel(policy.actor, use_buffers=False)

    @classmethod
    def of(cls, policy: Policy, config: LearnerConfig, budget: int) -> WeightAverage | None:
        """The average ``config.average_from`` asks for over ``budget`` env steps; None
        without it, or for a learner that does not update."""
        if config.average_from is None or not config.update:
            return None
        return cls(policy, config.average_from * budget)

    @property
    def count(self) -> int:
        """Updates averaged so far."""
        return int(self.model.n_averaged)

    def update(self, policy: Policy, steps: int) -> None:
        """Fold the actor's weights after the update of the batch that ended at
        ``steps`` env steps into the average, from ``start`` env steps on."""
        if steps >= self.start:
            self.model.update_parameters(policy.actor)

    @staticmethod
    @torch.no_grad()
    def _copy(into: Iterator[torch.nn.Parameter], values: Iterable[torch.Tensor]) -> None:
        for mine, value in zip(into, values, strict=True):
            mine.copy_(value)

    @contextmanager
    def swapped(self, policy: Policy) -> Iterator[None]:
        """The averaged weights in the actor inside the block (once any are averaged),
        the current ones again after it."""
        if not self.count:
            yield
            return
        current = [p.detach().clone() for p in policy.actor.parameters()]
        self._copy(policy.actor.parameters(), self.model.module.parameters())
        try:
            yield
        finally:
            self._copy(policy.actor.parameters(), current)

    def hand_back(self, policy: Policy) -> None:
        """Leave the averaged weights in the actor (if any were averaged)."""
        if self.count:
            self._copy(policy.actor.parameters(), self.model.module.parameters())


def _train(
    robot: Robot,
    physics: PhysicsParams,
    env_config: EnvConfig,
    config: LearnerConfig,
    budget: int,
    seed: int,
    on_curve: CurveHook | None,
    on_episode: EpisodeHook | None,
    inheritance: Inheritance | None = None, scene: Scene | None = None,
) -> TrainResult:
    start = time.perf_counter()
    env, policy, periodic = _setup(robot, physics, env_config, config, seed, scene, on_episode,
                                   inheritance)
    loss, gae, optimizer = _objective(policy, config)
    frames = math.ceil(budget / config.frames_per_batch) * config.frames_per_batch
    _anneal(policy, config, 0, budget)
    average = WeightAverage.of(policy, config, budget)
    collector = Collector(env, policy.sampler(), frames_per_batch=config.frames_per_batch,
                          total_frames=frames, auto_register_policy_transforms=False,
                          track_traj_ids=False)
    scale = RewardScale(config.num_envs, config.gamma) if config.reward_scaling else None
    rows: list[dict[str, float]] = []
    returns_sum, returns_count, steps, stopped = 0.0, 0, 0, False
    timing = dict.fromkeys(("collect", "update"), 0.0)
    tick = time.perf_counter()
    try:
        for batch in collector:
            timing["collect"] += time.perf_counter() - tick
            tick = time.perf_counter()
            steps += batch.numel()
            episodes = _completed(batch)
            returns_sum += float(episodes["return"].sum())
            returns_count += int(episodes["return"].numel())
            row = _batch_row(batch, steps, episodes, env.core.task.reward_terms)
            with torch_threads(env_config.nthread):  # the physics threads are idle meanwhile
                row.update(_learn(batch, loss, gae, optimizer, policy, config, steps, budget,
                                  scale))
            row.update(_after_update(policy, config, steps, budget, steps >= frames, periodic,
                                     average))
            row["wall_seconds"] = time.perf_counter() - start
            rows.append(row)
            stop = on_curve is not None and bool(on_curve(row))
            timing["update"] += time.perf_counter() - tick
            tick = time.perf_counter()
            if stop and steps < frames:  # a stop asked at the last batch changes nothing
                stopped = True
                break
    finally:
        collector.shutdown()
    # When no episode ended within the budget, judge the running ones.
    fitness = returns_sum / returns_count if returns_count else float(np.mean(env.core.returns))
    timing.update(physics=env.core.physics_seconds, env=env.step_seconds)
    kept_at, evaluation = _hand_back(policy, periodic, average, timing)
    return TrainResult(fitness=fitness, curve=pd.DataFrame(rows), policy=policy,
                       env_steps=steps, episodes=returns_count,
                       wall_seconds=time.perf_counter() - start,
                       unstable=env.core.unstable_count, timing=timing, stopped_early=stopped,
                       kept_at=kept_at, evaluation=evaluation)


def _after_update(policy: Policy, config: LearnerConfig, steps: int, budget: int, last: bool,
                  periodic: PeriodicEvaluation | None, average: WeightAverage | None
                  ) -> dict[str, float]:
    """After the update of the batch that ended at ``steps`` (the ``last`` one): the
    spread's bound for the next batch, the weights folded into the average, and the
    periodic evaluation's row values (of the averaged actor, once there is one)."""
    _anneal(policy, config, steps, budget)
    if average is not None:
        average.update(policy, steps)
    with average.swapped(policy) if average is not None else nullcontext():
        return periodic(policy, steps, last=last) if periodic else {}


def _hand_back(policy: Policy, periodic: PeriodicEvaluation | None,
               average: WeightAverage | None, timing: dict[str, float]
               ) -> tuple[int | None, tuple[float, float] | None]:
    """Leave in ``policy`` the weights it hands back: the best periodic evaluation's
    with ``keep_best``, else the averaged ones with ``average_from``, else the last; with
    its own spread, unbounded. Returns what ``PeriodicEvaluation.finish`` does."""
    if average is not None:
        average.hand_back(policy)
    kept = periodic.finish(policy, timing) if periodic else (None, None)
    policy.head.log_std_cap = None  # the trained policy's own spread from here on
    return kept


def _setup(robot: Robot, physics: PhysicsParams, env_config: EnvConfig, config: LearnerConfig,
           seed: int, scene: Scene | None, on_episode: EpisodeHook | None,
           inheritance: Inheritance | None
           ) -> tuple[TaskEnv, Policy, PeriodicEvaluation | None]:
    """The training's arenas (watched by ``on_episode``), its fresh policy, sized by the
    env's specs (a parent's, slot-mapped, with ``inheritance``), and its periodic
    evaluations (``eval_interval``; the scene compiled once for both)."""
    periodic = None
    if config.eval_interval:
        if scene is None:
            scene = compile_scene(robot, physics, env_config.arena, env_config.task)
        periodic = PeriodicEvaluation(robot, physics, env_config, config, seed, scene)
    env = make_env(robot, physics, env_config, config.num_envs, seed, scene)
    if on_episode is not None:
        env.core.watch(on_episode)
    policy = make_policy(env.observation_spec["observation"].shape[-1],
                         env.action_spec.shape[-1], config)
    if inheritance is not None:
        inherit(policy, inheritance)
    return env, policy, periodic


def _anneal(policy: Policy, config: LearnerConfig, steps: int, budget: int) -> None:
    """With ``final_log_std``, bound the log std of the batches from ``steps`` on: from
    ``init_log_std`` until ``anneal_from`` of the budget, then linearly to
    ``final_log_std`` at the budget."""
    if config.final_log_std is None:
        return
    start = config.anneal_from * budget
    progress = min(1.0, max(0.0, steps - start) / (budget - start))
    cap = config.init_log_std + (config.final_log_std - config.init_log_std) * progress
    policy.head.log_std_cap = cap


@contextmanager
def torch_threads(n: int) -> Iterator[None]:
    """Let torch use ``n`` intra-op threads inside the block (as many as it had, at least)."""
    before = torch.get_num_threads()
    torch.set_num_threads(max(n, before))
    try:
        yield
    finally:
        torch.set_num_threads(before)


def _learn(
    batch: TensorDictBase,
    loss: ClipPPOLoss,
    gae: GAE,
    optimizer: torch.optim.Optimizer,
    policy: Policy,
    config: LearnerConfig,
    steps: int,
    budget: int,
    scale: RewardScale | None = None,
) -> dict[str, float]:
    """One PPO update on ``batch`` (its rewards scaled first by ``scale``, if given),
    then the observation statistics; NaN losses when the learner does not update."""
    if not config.update:
        return {**dict.fromkeys(_LOSS_KEYS, float("nan")), "train/lr": 0.0}
    lr = config.lr * (max(0.0, 1 - (steps - batch.numel()) / budget) if config.anneal_lr else 1)
    for group in optimizer.param_groups:
        group["lr"] = lr
    with torch.no_grad():
        if scale is not None:
            scale(batch)
        gae(batch)
    losses = _update(batch, loss, optimizer, config)
    # Statistics change only after the update, so the update's ratios start at 1.
    policy.norm.update(batch["observation"])
    return {**losses, "train/lr": lr}
