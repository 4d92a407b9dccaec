"""The physics step: raw rate and fidelity of other timestep × substep pairs against
today's 0.005 s × 10 (one control step of 0.05 s either way).

For each hand-made robot and each pair (``morphology.physics.timestep``,
``env.task.frame_skip``), in the clean arena:

* ``raw``: env steps per CPU-second of the env's ``mujoco.batch.Batch`` of N arenas on
  one thread, random controls, no Python in between: what a training's physics can
  reach on one core. CPU time, not wall time, so that other work on a shared machine
  does not move the figure;
* ``path``: a fixed action sequence (each arena's actions drawn once, held for 5
  control steps, the same for every pair) run for ``--seconds`` of simulated time from
  the same start; the RMS, over arenas, control steps and modules, of the distance
  between each module's position under the pair and under today's, m. ``ref`` is the
  same against the finest pair listed (0.0025 s × 20 by default): today's own
  discretisation error sets the scale;
* ``unstable``: episodes the task flags unstable (MuJoCo reset, non-finite state,
  robot thrown) and MuJoCo warnings during that run.

Contact-rich motion is chaotic: even a finer step moves the modules' paths away from
today's within seconds. So a deviation is judged against today's own discretisation
error, ``ref`` of today's row (today's against the finest pair, same robot and
actions): a pair keeps today's behaviour (``ok``) when its ``path`` deviation is at most
:data:`TOLERANCE` times that, and it is no less stable.

Usage: ``python bench/physics_step.py [--robots robots/*.json] [--seconds 10]
[--pairs 0.005x10 0.01x5 ...]``. The integrator stays MuJoCo's ``implicitfast``
(``evo.robot.builder``).
"""

from __future__ import annotations

import argparse
import dataclasses
import glob
import time

import numpy as np
from numpy.typing import NDArray

from evo.envs.arena import ArenaParams
from evo.envs.core import TaskCore
from evo.envs.tasks.reach import Reach
from evo.robot import load_robot
from evo.robot.builder import PhysicsParams
from evo.robot.tree import Robot

TODAY = (0.005, 10)
"""The paper configs' physics: 0.005 s steps, 10 per control step (20 Hz)."""
PAIRS = ("0.0025x20", "0.005x10", "0.00625x8", "0.01x5", "0.0125x4", "0.025x2")
TOLERANCE = 1.5
"""Largest RMS module-path deviation from today's physics, as a multiple of today's own
deviation from the finest pair."""
HOLD = 5
"""Control steps each drawn action is held for (a smooth, repeatable sequence)."""


def parse_pair(text: str) -> tuple[float, int]:
    """``"0.01x5"`` -> (0.01, 5)."""
    timestep, _, substeps = text.partition("x")
    return float(timestep), int(substeps)


def core_of(robot: Robot, pair: tuple[float, int], num_envs: int, t_max: int) -> TaskCore:
    """The clean arena with ``pair``'s physics, one thread, seed 0."""
    physics = dataclasses.replace(PhysicsParams(), timestep=pair[0])
    task = dataclasses.replace(Reach(), frame_skip=pair[1], t_max=t_max)
    return TaskCore(robot, physics, ArenaParams(), task, num_envs, 1, seed=0)


def cpu_rate(core: TaskCore, steps: int, rng: np.random.Generator) -> float:
    """Env steps per CPU-second of ``core``'s batch stepping ``frame_skip`` physics steps
    per control step under random controls."""
    controls = rng.uniform(-1, 1, (steps, core.num_envs, core.model.nu)) * core.ctrl_scale
    core.reset()
    core.batch.step(nstep=10 * core.task.frame_skip)  # settle
    start = time.process_time()
    for t in range(steps):
        core.ctrl[:] = controls[t]
        core.batch.step(nstep=core.task.frame_skip)
    return core.num_envs * steps / (time.process_time() - start)


def actions(core: TaskCore, steps: int, seed: int = 0) -> NDArray[np.float64]:
    """A fixed action sequence, (steps, arenas, actuators): uniform in [-1, 1], each draw
    held for :data:`HOLD` control steps."""
    rng = np.random.default_rng(seed)
    draws = rng.uniform(-1, 1, (steps // HOLD + 1, core.num_envs, core.action_size))
    return np.repeat(draws, HOLD, axis=0)[:steps]


def module_paths(core: TaskCore, sequence: NDArray[np.float64]
                 ) -> tuple[NDArray[np.float64], int, int]:
    """Module positions after every control step (steps, arenas, modules, 3), and the
    unstable episodes and MuJoCo warnings of the run."""
    core.reset()
    paths, unstable = [], 0
    for act in sequence:
        step = core.step(act)
        unstable += int(step.unstable.sum())
        if step.unstable.any():
            core.reset(step.unstable)
        paths.append(core.sensordata[:, core.i_modules].reshape(core.num_envs, -1, 3).copy())
    return np.stack(paths), unstable, core.warning_count


def rms(a: NDArray[np.float64], b: NDArray[np.float64]) -> float:
    """RMS over everything of the distance between matching points of two paths, m."""
    return float(np.sqrt(np.mean(np.sum((a - b) ** 2, axis=-1))))


def main() -> None:
    cli = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    cli.add_argument("--robots", nargs="+", default=sorted(glob.glob("robots/*.json")),
                     help="robot files (default: robots/*.json)")
    cli.add_argument("--pairs", nargs="+", default=list(PAIRS),
                     help="timestep x substeps, e.g. 0.01x5")
    cli.add_argument("--seconds", type=float, default=10.0, help="simulated time of a path")
    cli.add_argument("--arenas", type=int, default=8, help="arenas (action sequences) per path")
    cli.add_argument("--num-envs", type=int, default=32, help="arenas of the raw-rate batch")
    cli.add_argument("--rate-steps", type=int, default=100, help="control steps per rate")
    args = cli.parse_args()
    pairs = [parse_pair(p) for p in args.pairs]
    finest = min(pairs, key=lambda p: p[0])
    steps = round(args.seconds / (TODAY[0] * TODAY[1]))
    print(f"paths of {args.seconds:g} s ({steps} control steps) "
          f"in {args.arenas} arenas; ok: path <= {TOLERANCE:g} x today's ref; "
          f"ref = {finest[0]:g} s x {finest[1]}")
    print(f"{'robot':>22} {'pair':>10} {'raw':>8} {'x today':>8} {'path':>7} {'ref':>7} "
          f"{'unstable':>8} {'warnings':>8}  verdict")
    rng = np.random.default_rng(0)
    for path in args.robots:
        robot = load_robot(path)
        name = path.split("/")[-1].removesuffix(".json")
        runs, rates = {}, {}
        for pair in pairs:
            control = pair[0] * pair[1]
            if abs(control - TODAY[0] * TODAY[1]) > 1e-9:
                raise SystemExit(f"--pairs: {pair[0]:g} x {pair[1]} is a {control:g} s control "
                                 f"step; keep {TODAY[0] * TODAY[1]:g} s")
            core = core_of(robot, pair, args.arenas, t_max=10 * steps)
            runs[pair] = module_paths(core, actions(core, steps))
            batch = core_of(robot, pair, args.num_envs, 1000)
            rates[pair] = max(cpu_rate(batch, args.rate_steps, rng) for _ in range(2))
        today = runs.get(TODAY, runs[pairs[0]])
        for pair in pairs:
            paths, unstable, warnings = runs[pair]
            dev, ref = rms(paths, today[0]), rms(paths, runs[finest][0])
            ok = dev <= TOLERANCE * rms(today[0], runs[finest][0]) and unstable <= today[1]
            print(f"{name:>22} {pair[0]:>6g}x{pair[1]:<3d} {rates[pair]:>8,.0f} "
                  f"{rates[pair] / rates.get(TODAY, rates[pairs[0]]):>8.2f} {dev:>7.3f} "
                  f"{ref:>7.3f} {unstable:>8d} {warnings:>8d}  {'ok' if ok else 'differs'}",
                  flush=True)


if __name__ == "__main__":
    main()
