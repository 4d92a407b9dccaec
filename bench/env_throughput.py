"""Environment throughput against the raw physics rate of the same model.

For each example robot, arena, batch size N and thread count, this measures in one run:

* ``raw``: a persistent ``mujoco.batch.Batch`` stepping the same compiled model (the
  env's options, sleeping rocks included) for N arenas on the same number of threads
  with the same frame skip, random controls, no Python in between: the limit any
  environment on this model can reach;
* ``env``: ``TaskEnv`` (TorchRL, random actions, automatic partial resets through
  ``step_and_maybe_reset`` exactly as a collector drives it).

Both are env steps per second (one env step = one control step of one arena). The ratio
``env / raw`` is what the environment's Python, numpy and TensorDict work costs; at the
end, each setting's raw physics against the clean arena's for each robot, N and thread
count (goal: >= 0.5, SPEC sections 3b and 9). A setting is an arena of the reach task
(``clean``, ``cluttered``) or another task in its own arena (``locomotion``, ``push``,
``rough``: ``conf/env/task/``, as ``env/task=<name>`` composes it).

Usage: ``python bench/env_throughput.py [--steps 200] [--robots robots/*.json]
[--arenas clean cluttered locomotion push rough]``
"""

from __future__ import annotations

import argparse
import glob
import time

import mujoco
import mujoco.batch
import numpy as np
import torch
from rich.console import Console
from rich.table import Table

from evo.edge import compose_config, typed_config
from evo.envs.core import TaskCore
from evo.envs.params import EnvConfig
from evo.envs.torchrl_env import TaskEnv
from evo.robot import load_robot


def raw_rate(env: TaskEnv, steps: int, rng: np.random.Generator) -> float:
    """Env steps/s of a bare ``mujoco.batch.Batch`` on the env's model, arenas, threads
    and current states (one ``step`` call of ``frame_skip`` physics steps per control
    step, as the env makes)."""
    core = env.core
    n, k = core.num_envs, core.task.frame_skip
    batch = mujoco.batch.Batch(core.model, nsim=n, nthread=core.nthread, persistent=True)
    batch.state[:] = core.state
    ctrl = batch.bind("ctrl")
    controls = rng.uniform(-1, 1, (steps, n, core.model.nu)) * core.ctrl_scale
    batch.step(nstep=10 * k)  # a new batch starts awake: let settled rocks fall asleep
    start = time.perf_counter()
    for t in range(steps):
        ctrl[:] = controls[t]
        batch.step(nstep=k)
    return n * steps / (time.perf_counter() - start)


def env_rate(env: TaskEnv, steps: int) -> float:
    """Env steps/s of ``TaskEnv`` driven like a collector, with random actions."""
    td = env.reset()
    start = time.perf_counter()
    for _ in range(steps):
        td["action"] = torch.rand(env.action_spec.shape) * 2 - 1
        _, td = env.step_and_maybe_reset(td)
    elapsed = time.perf_counter() - start
    return env.num_envs * steps / elapsed


def setting_override(name: str) -> str:
    """The override that chooses a setting: ``env=<arena>`` for reach's arenas (clean,
    cluttered), ``env/task=<task>`` for another task in its own arena."""
    return f"env={name}" if name in ("clean", "cluttered") else f"env/task={name}"


def setting(name: str) -> EnvConfig:
    """The env of a setting, composed as ``evo/main.py`` would."""
    return typed_config(compose_config([setting_override(name)])).env


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=200, help="control steps per measurement")
    parser.add_argument("--robots", nargs="+", default=sorted(glob.glob("robots/*.json")))
    parser.add_argument("--num-envs", type=int, nargs="+", default=[12, 64, 256])
    parser.add_argument("--nthread", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--arenas", nargs="+", default=["clean", "cluttered"],
                        help="reach's arenas and other tasks: clean cluttered locomotion push "
                             "rough")
    parser.add_argument("--repeats", type=int, default=3, help="interleaved repeats, best kept")
    args = parser.parse_args()
    torch.set_num_threads(1)
    table = Table(title="TaskEnv throughput (env steps/s) vs raw MuJoCo batch, same run")
    for column in ("robot", "arena", "N", "threads", "raw", "env", "env/raw"):
        table.add_column(column, justify="right")
    rng = np.random.default_rng(0)
    raws: dict[tuple[str, str, int, int], float] = {}
    for path in args.robots:
        robot = load_robot(path)
        for arena_name in args.arenas:
            config = setting(arena_name)
            for n in args.num_envs:
                for nthread in args.nthread:
                    env = TaskEnv(TaskCore(robot, arena=config.arena, task=config.task,
                                           num_envs=n, nthread=nthread, seed=0))
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
                    raws[(row[0], arena_name, n, nthread)] = raw
                    env.close()
    Console(width=200).print(table)
    for (name, arena_name, n, nthread), raw in raws.items():
        clean = raws.get((name, "clean", n, nthread))
        if arena_name != "clean" and clean:
            print(f"{name} N={n} threads={nthread}: raw {arena_name} / clean = "
                  f"{raw / clean:.2f} ({raw:,.0f} / {clean:,.0f} env steps/s)")


if __name__ == "__main__":
    main()
