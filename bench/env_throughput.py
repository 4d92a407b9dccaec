"""Environment throughput against the raw physics rate of the same model.

For each example robot, arena, batch size N and thread count, this measures in one run:

* ``raw``: ``mujoco.rollout`` stepping the same compiled model for N arenas on the same
  number of threads with the same frame skip, random controls, no Python in between:
  the limit any environment on this model can reach;
* ``env``: ``ReachEnv`` (TorchRL, random actions, automatic partial resets through
  ``step_and_maybe_reset`` exactly as a collector drives it).

Both are env steps per second (one env step = one control step of one arena). The ratio
``env / raw`` is what the environment's Python, numpy and TensorDict work costs.

Usage: ``python bench/env_throughput.py [--steps 200] [--robots robots/*.json]``
"""

from __future__ import annotations

import argparse
import glob
import time

import mujoco
import numpy as np
import torch
from rich.console import Console
from rich.table import Table

from evo.envs.arena import ArenaParams
from evo.envs.reach import ReachEnv
from evo.robot import load_robot


def raw_rate(env: ReachEnv, steps: int, rng: np.random.Generator) -> float:
    """Env steps/s of bare ``mujoco.rollout`` on the env's model, arenas and threads."""
    core = env.core
    n, k, nu = core.num_envs, core.task.frame_skip, core.model.nu
    state = core.state.copy()
    controls = rng.uniform(-1, 1, (steps, n, 1, nu)) * core.ctrl_scale
    ctrl = np.zeros((n, k, nu))
    out_state = np.zeros((n, k, core.nstate))
    out_sensors = np.zeros((n, k, core.model.nsensordata))
    warm = np.zeros((n, core.model.nv))
    rollout = mujoco.rollout.Rollout(nthread=core.nthread)
    datas = [mujoco.MjData(core.model) for _ in range(core.nthread)]
    start = time.perf_counter()
    for t in range(steps):
        ctrl[:] = controls[t]
        rollout.rollout(
            core.models,
            datas,
            state,
            ctrl,
            nstep=k,
            initial_warmstart=warm,
            state=out_state,
            sensordata=out_sensors,
            skip_checks=True,
        )
        state[:] = out_state[:, -1]
    elapsed = time.perf_counter() - start
    rollout.close()
    return n * steps / elapsed


def env_rate(env: ReachEnv, steps: int) -> float:
    """Env steps/s of ``ReachEnv`` driven like a collector, with random actions."""
    td = env.reset()
    start = time.perf_counter()
    for _ in range(steps):
        td["action"] = torch.rand(env.action_spec.shape) * 2 - 1
        _, td = env.step_and_maybe_reset(td)
    elapsed = time.perf_counter() - start
    return env.num_envs * steps / elapsed


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=200, help="control steps per measurement")
    parser.add_argument("--robots", nargs="+", default=sorted(glob.glob("robots/*.json")))
    parser.add_argument("--num-envs", type=int, nargs="+", default=[12, 64, 256])
    parser.add_argument("--nthread", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--arenas", nargs="+", default=["clean", "cluttered"])
    parser.add_argument("--repeats", type=int, default=3, help="interleaved repeats, best kept")
    args = parser.parse_args()
    torch.set_num_threads(1)
    table = Table(title="ReachEnv throughput (env steps/s) vs raw MuJoCo rollout, same run")
    for column in ("robot", "arena", "N", "threads", "raw", "env", "env/raw"):
        table.add_column(column, justify="right")
    rng = np.random.default_rng(0)
    for path in args.robots:
        robot = load_robot(path)
        for arena_name in args.arenas:
            arena = getattr(ArenaParams, arena_name)()
            for n in args.num_envs:
                for nthread in args.nthread:
                    env = ReachEnv(robot, arena=arena, num_envs=n, nthread=nthread, seed=0)
                    steps = max(20, args.steps * 12 // n)
                    env_rate(env, steps // 4)  # warm up
                    # Interleaved repeats, best of each: the machine is shared and noisy.
                    raw = fast = 0.0
                    for _ in range(args.repeats):
                        raw = max(raw, raw_rate(env, steps, rng))
                        fast = max(fast, env_rate(env, steps))
                    row = (path.split("/")[-1].removesuffix(".json"), arena_name, str(n),
                           str(nthread), f"{raw:,.0f}", f"{fast:,.0f}", f"{fast / raw:.2f}")
                    table.add_row(*row)
                    print(*row, flush=True)  # progress; the table comes at the end
                    env.close()
    Console(width=200).print(table)


if __name__ == "__main__":
    main()
