"""What a trained policy's deterministic robot does where its noisy one succeeds: the same
episodes (targets and rocks) run with the mean action and with the policy's noise, side
by side, and per mode the success, how far failed episodes end from the target, how
much of them the robot stands still (and of that, beside a rock), whether it ends them
stuck (standing still for their last 5 s), and how often its mean action lies outside
the action box [-1, 1].

    python docs/results/deployed/mechanism.py RETRAIN_DIR [TRAINING ...] \
        [--episodes 32] [--out docs/results/deployed/mechanism.csv]

RETRAIN_DIR is a ``+exp=designer`` folder; each TRAINING (default: every one) is a row
of its ``trainings.csv`` (``evals/<training>.pt``, ``robots/<robot>.json``), run in the
folder's arena (its ``config.yaml``) under the evaluation after training's seed (its
seed + 1). Prints one line per training and mode and writes them to ``--out``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pandas as pd
import torch
from omegaconf import OmegaConf

from evo.config import current, typed
from evo.envs.core import TaskCore
from evo.envs.params import GLOBAL_SLOTS, EnvConfig
from evo.learners.common import Policy, load_checkpoint
from evo.robot import load_robot
from evo.robot.builder import PhysicsParams
from evo.robot.tree import Robot
from evo.run.layout import RetrainLayout
from evo.run.records import read_trainings

STILL = 0.02
"""Brain speed over the ground (m/s) below which the robot counts as standing still."""

BESIDE = 0.12
"""A rock centre this close (m, horizontally) to a module centre: the robot is beside it."""

STUCK = 100
"""Control steps (5 s) standing still at the end of a failed episode: stuck for good."""

DISTANCE = GLOBAL_SLOTS - 1
"""The observation's slot of the reach task's distance d."""


def beside_rock(core: TaskCore) -> np.ndarray:
    """Whether each arena's robot has a rock within :data:`BESIDE` of a module."""
    if not core.arena.n_rocks:
        return np.zeros(core.num_envs, dtype=bool)
    rocks = core.qpos[:, core.rock_qpos[:, None] + np.arange(2)]  # (N, rocks, 2)
    modules = core.module_positions()[:, :, :2]  # (N, modules, 2)
    gaps = np.linalg.norm(modules[:, :, None] - rocks[:, None], axis=-1)
    return np.asarray((gaps < BESIDE).any(axis=(1, 2)))


def episodes(robot: Robot, policy: Policy, physics: PhysicsParams, env: EnvConfig,
             count: int, seed: int, noisy: bool) -> dict[str, float]:
    """``count`` episodes side by side, one per arena, with the mean action or the
    policy's noise (drawn from ``seed``); their summary."""
    core = TaskCore(robot, physics, env.arena, env.task, count, 1, seed)
    obs = core.reset()
    active = np.ones(count, dtype=bool)
    success = np.zeros(count, dtype=bool)
    still = np.zeros(count)
    still_beside = np.zeros(count)
    streak = np.zeros(count)
    steps = np.zeros(count)
    outside = np.zeros(count)
    travelled = np.zeros(count)
    start = obs[:, DISTANCE].astype(float)
    end = start.copy()  # d where each episode ended
    sampler = policy.sampler()
    generator = torch.random.fork_rng(devices=[])
    with generator, torch.no_grad():
        torch.manual_seed(seed)
        while active.any():
            observation = torch.from_numpy(obs)
            loc, _, draw, _ = sampler.sample(observation)
            action = draw if noisy else loc
            step = core.step(action.numpy())
            speed = np.linalg.norm(core.sensordata[:, core.i_linvel][:, :2], axis=1)
            steps += active
            resting = active & (speed < STILL)
            still += resting
            still_beside += resting & beside_rock(core)
            streak = np.where(active, np.where(resting, streak + 1, 0), streak)
            travelled += active * speed * core.control_step
            outside += active * (loc.abs() > 1).float().mean(-1).numpy()
            success |= active & step.success
            obs = step.observation
            end = np.where(active, obs[:, DISTANCE], end)
            active &= ~(step.success | step.truncated)
    failed = ~success
    return {
        "success": float(success.mean()),
        "still_share": float((still / steps).mean()),
        "mean_speed": float((travelled / (steps * core.control_step)).mean()),
        "progress_failed": float((start - end)[failed].mean())
        if failed.any() else np.nan,
        "travelled_failed": float(travelled[failed].mean()) if failed.any() else np.nan,
        "final_distance_failed": float(end[failed].mean()) if failed.any() else np.nan,
        "still_share_failed": float((still[failed] / steps[failed]).mean())
        if failed.any() else np.nan,
        "still_beside_rock_failed": float(still_beside[failed].sum() / max(1, still[failed].sum()))
        if failed.any() else np.nan,
        "stuck_failed": float((streak[failed] >= STUCK).mean()) if failed.any() else np.nan,
        "mean_outside": float((outside / steps).mean()),
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("folder", type=Path)
    parser.add_argument("trainings", nargs="*")
    parser.add_argument("--episodes", type=int, default=32)
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args(argv)
    layout = RetrainLayout(args.folder)
    config = current(OmegaConf.load(args.folder / "config.yaml"))
    physics = typed(PhysicsParams, config.morphology.physics, "morphology.physics")
    env = typed(EnvConfig, config.env, "env")
    rows = read_trainings(layout.trainings)
    if args.trainings:
        rows = rows[rows["name"].isin(args.trainings)]
    out = []
    for row in rows.itertuples():
        robot = load_robot(args.folder / "robots" / f"{row.robot}.json")
        policy = load_checkpoint(layout.policy(str(row.name)), robot=robot)
        for noisy in (False, True):
            summary = episodes(robot, policy, physics, env, args.episodes, int(row.seed) + 1,
                               noisy)
            line = {"training": row.name, "arena": row.arena,
                    "mode": "noisy" if noisy else "deterministic", **summary}
            print("  ".join(f"{k} {v:.3f}" if isinstance(v, float) else f"{k} {v}"
                            for k, v in line.items()), flush=True)
            out.append(line)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    pd.DataFrame(out).to_csv(args.out, index=False)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
