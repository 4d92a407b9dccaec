"""Make the README's pictures with the project's own code.

    MUJOCO_GL=egl python docs/pictures.py [--curve <run dir of +exp=train>]

Writes ``docs/robots.png`` (the example robots), ``docs/arena.png`` (the cluttered
arena with the four-wheeler) and, given a training run, ``docs/curve.png``.
"""

from __future__ import annotations

import argparse
import glob
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

from evo.envs.gym_env import ReachGymEnv
from evo.robot import load_robot
from evo.robot.builder import PhysicsParams
from evo.robot.gallery import contact_sheet

HERE = Path(__file__).parent


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--curve", type=Path, help="run directory of python evo/main.py +exp=train")
    args = parser.parse_args()
    robots = [load_robot(p) for p in sorted(glob.glob("robots/*.json"))]
    print(contact_sheet(robots, PhysicsParams(), HERE / "robots.png"))
    env = ReachGymEnv("robots/four_wheeler.json", arena="cluttered", render_mode="rgb_array")
    env.reset(seed=4)
    for _ in range(20):
        env.step(np.array([1.0, 1.0, 0.0]))
    plt.imsave(HERE / "arena.png", env.render())
    env.close()
    print(HERE / "arena.png")
    if args.curve is not None:
        curve = pd.read_csv(args.curve / "curve.csv")
        fig, (left, right) = plt.subplots(1, 2, figsize=(9, 3.2))
        left.plot(curve["env_steps"], curve["mean_return"].interpolate(), color="tab:blue")
        left.set(xlabel="env steps", ylabel="mean return of finished episodes")
        right.plot(curve["env_steps"], curve["success_rate"].interpolate(), color="tab:green")
        right.set(xlabel="env steps", ylabel="success rate", ylim=(-0.02, 1.02))
        fig.suptitle("PPO on the four-wheeler, clean arena")
        fig.tight_layout()
        fig.savefig(HERE / "curve.png", dpi=110)
        print(HERE / "curve.png")


if __name__ == "__main__":
    main()
