"""The ceiling of PPO's end-to-end rate against raw physics: what PPO's own arithmetic
costs per collector batch, measured beside the physics it must wait for.

For one robot and the learner of ``+exp=paper_clean`` (the paper's 12 arenas x 128 steps,
4 epochs of minibatch 512; Hydra overrides change it), this collects one real batch
with the TorchRL collector and then times, in the same run:

* **physics**: the raw rate of the same compiled model, arenas, threads and frame skip
  (``bench/env_throughput.py``'s ``raw_rate``), as seconds per batch;
* **policy floor**: the actor's forward pass and sampling on each control step's
  observations, through ``GaussianSampler.sample`` (plain torch: no TensorDict, no
  collector);
* **update floor**: the epochs of minibatch steps in plain torch (the clipped objective,
  value loss, entropy bonus, backward pass, gradient clip, Adam step) on the same
  networks and sizes;
* **TorchRL's GAE**, and GAE with the ``ClipPPOLoss`` loop of ``evo.learners.ppo``, on the
  same batch (TorchRL's GAE is vectorised over time and is its own floor).

The ceiling is physics / (physics + policy floor + GAE + update floor): the rate
against raw physics that PPO could reach even if the environment, the collector and the
loss cost nothing beyond their arithmetic, on the same cores, one after the other.

Usage: ``python bench/ppo_floor.py [--robot robots/four_wheeler.json] [--repeats 5]
[learner.num_envs=32 learner.rollout_steps=64 ...]``
"""

from __future__ import annotations

import argparse
import copy
import dataclasses
import math
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import torch
from env_throughput import raw_rate  # bench/ is on sys.path when this script runs
from rich.console import Console
from rich.table import Table
from tensordict import TensorDictBase
from torchrl.collectors import Collector

from evo.edge import compose_config, typed_config
from evo.envs.torchrl_env import make_env
from evo.learners.common import (
    GaussianHead,
    GaussianSampler,
    LearnerConfig,
    ValueHead,
    make_policy,
)
from evo.learners.ppo import _objective, _update, torch_threads
from evo.robot import load_robot


def best_of(repeats: int, run: Callable[[], object]) -> float:
    """The fastest of ``repeats`` timed calls of ``run``, seconds."""
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        run()
        times.append(time.perf_counter() - start)
    return min(times)


def plain_policy(sampler: GaussianSampler, observations: torch.Tensor) -> None:
    """Every control step's actor forward pass and Gaussian sample, on tensors."""
    with torch.no_grad():
        for obs in observations:
            sampler.sample(obs)


def plain_update(head: GaussianHead, value: ValueHead, batch: TensorDictBase,
                 config: LearnerConfig) -> None:
    """``config.epochs`` passes of minibatch PPO steps in plain torch."""
    params = [*head.parameters(), *value.parameters()]
    optimizer = torch.optim.Adam(params, lr=config.lr)
    flat = batch.reshape(-1)
    obs, action = flat["observation"], flat["action"]
    old_log_prob = flat["action_log_prob"]
    advantage = torch.randn(flat.numel())
    target = torch.randn(flat.numel())
    eps, half_log_2pi = config.clip_epsilon, 0.5 * math.log(2 * math.pi)
    for _ in range(config.epochs):
        for index in torch.split(torch.randperm(flat.numel()), config.minibatch_size):
            loc, scale = head(obs[index])
            log_scale = scale.log()
            log_prob = (-0.5 * ((action[index] - loc) / scale) ** 2 - log_scale
                        - half_log_2pi).sum(-1)
            ratio = (log_prob - old_log_prob[index]).exp()
            a = advantage[index]
            a = (a - a.mean()) / (a.std() + 1e-8)
            objective = -torch.min(ratio * a, ratio.clamp(1 - eps, 1 + eps) * a).mean()
            entropy = (0.5 + half_log_2pi + log_scale).sum(-1).mean()
            critic = ((value(obs[index]).squeeze(-1) - target[index]) ** 2).mean()
            total = objective + config.critic_coeff * critic - config.entropy_coeff * entropy
            optimizer.zero_grad()
            total.backward()
            torch.nn.utils.clip_grad_norm_(params, config.max_grad_norm)
            optimizer.step()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robot", default="robots/four_wheeler.json")
    parser.add_argument("--arena", default="clean")
    parser.add_argument("--nthread", type=int, default=2, help="physics threads")
    parser.add_argument("--repeats", type=int, default=5, help="timed repeats (best kept)")
    parser.add_argument("overrides", nargs="*", help="Hydra overrides, e.g. learner.num_envs=32")
    args = parser.parse_args()
    torch.set_num_threads(1)
    torch.manual_seed(0)
    parts = typed_config(compose_config(
        ["+exp=paper_clean", f"env={args.arena}", *args.overrides])).training
    config, physics = parts.learner, parts.physics
    env_config = dataclasses.replace(parts.env, nthread=args.nthread)
    robot = load_robot(args.robot)
    env = make_env(robot, physics, env_config, config.num_envs, 0)
    policy = make_policy(env.observation_spec["observation"].shape[-1],
                         env.action_spec.shape[-1], config)
    collector = Collector(env, policy.sampler(), frames_per_batch=config.frames_per_batch,
                          total_frames=config.frames_per_batch,
                          auto_register_policy_transforms=False, track_traj_ids=False)
    batch = next(iter(collector))
    collector.shutdown()
    policy.norm.update(batch["observation"])  # normalise as after a first batch
    loss, gae, optimizer = _objective(policy, config)

    probe = make_env(robot, physics, env_config, config.num_envs, 0)
    probe.reset()
    frames = config.frames_per_batch
    physics_s = frames / raw_rate(probe, 4 * config.rollout_steps, np.random.default_rng(0))
    head, value = copy.deepcopy(policy.head), copy.deepcopy(policy.critic.module)
    sampler = GaussianSampler(head)
    by_step = batch["observation"].transpose(0, 1)  # control step, arena, observation
    with torch_threads(args.nthread):  # as the learner runs GAE and the update
        measured = {
            "policy floor": best_of(args.repeats, lambda: plain_policy(sampler, by_step)),
            "update floor": best_of(args.repeats, lambda: plain_update(
                head, value, batch, config)),
            "TorchRL GAE": best_of(args.repeats, lambda: gae(batch.clone())),
            "TorchRL GAE + update": best_of(args.repeats, lambda: _update(
                gae(batch.clone()), loss, optimizer, config)),
        }
    floor = measured["policy floor"] + measured["TorchRL GAE"] + measured["update floor"]
    table = Table(title=f"{Path(args.robot).stem}, {args.arena}: one batch of {frames:,} env steps "
                  f"({config.num_envs} arenas x {config.rollout_steps}), {config.epochs} "
                  f"epochs of minibatch {config.minibatch_size}, {args.nthread} threads")
    for column in ("part", "ms per batch", "against physics"):
        table.add_column(column, justify="left" if column == "part" else "right")
    for name, seconds in {"physics (raw)": physics_s, **measured}.items():
        table.add_row(name, f"{seconds * 1e3:.1f}", f"{seconds / physics_s:.2f}")
    Console(width=160).print(table)
    print(f"ceiling of end-to-end / raw physics: {physics_s / (physics_s + floor):.2f} "
          f"(physics {physics_s * 1e3:.1f} ms + PPO arithmetic {floor * 1e3:.1f} ms per batch)")
    torchrl = measured["policy floor"] + measured["TorchRL GAE + update"]
    print(f"with TorchRL's GAE and update in place of their floors: "
          f"{physics_s / (physics_s + torchrl):.2f}")


if __name__ == "__main__":
    main()
