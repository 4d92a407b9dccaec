"""Make the README's pictures with the project's own code.

    MUJOCO_GL=egl python docs/pictures.py [--curve <train run>] [--run <evolution run>]
        [--designer <comparison folder> ...]

Writes ``docs/robots.png`` (the example robots), ``docs/arena.png`` (the cluttered
arena with the four-wheeler), given a training run (``+exp=train``) ``docs/curve.png``,
and given an evolution run ``docs/evolution.png`` (every robot's fitness in birth order
with the population's best and mean), ``docs/best_curves.png`` (learning curves of the
best robots) and ``docs/best.png`` (the best robots), and given comparison folders of
``python -m analysis.designer`` ``docs/designer_<arena>.png`` (every robot's metrics,
evolved against hand-made) and ``docs/designer_robots_<arena>.png`` (the best of each).
"""

from __future__ import annotations

import argparse
import glob
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

from analysis import designer, plots
from analysis.load import load_runs
from evo.envs.gym_env import TaskGymEnv
from evo.record import read_curve
from evo.robot import load_robot
from evo.robot.builder import PhysicsParams
from evo.robot.gallery import contact_sheet

HERE = Path(__file__).parent


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--curve", type=Path, help="run directory of python evo/main.py +exp=train")
    parser.add_argument("--run", type=Path, help="run directory of an evolution")
    parser.add_argument("--designer", type=Path, nargs="+", default=[],
                        help="output folders of python -m analysis.designer")
    args = parser.parse_args()
    robots = [load_robot(p) for p in sorted(glob.glob("robots/*.json"))]
    print(contact_sheet(robots, PhysicsParams(), HERE / "robots.png"))
    env = TaskGymEnv("robots/four_wheeler.json", arena="cluttered", render_mode="rgb_array")
    env.reset(seed=4)
    for _ in range(20):
        env.step(np.array([1.0, 1.0, 0.0]))
    plt.imsave(HERE / "arena.png", env.render())
    env.close()
    print(HERE / "arena.png")
    if args.curve is not None:
        curve = read_curve(args.curve / "curve.csv")
        fig, (left, right) = plt.subplots(1, 2, figsize=(9, 3.2))
        left.plot(curve["env_steps"], curve["train/mean_return"].interpolate(), color="tab:blue")
        left.set(xlabel="env steps", ylabel="mean return of finished episodes")
        right.plot(curve["env_steps"], curve["train/success_rate"].interpolate(), color="tab:green")
        right.set(xlabel="env steps", ylabel="success rate", ylim=(-0.02, 1.02))
        fig.suptitle("PPO on the four-wheeler, clean arena")
        fig.tight_layout()
        fig.savefig(HERE / "curve.png", dpi=110)
        print(HERE / "curve.png")
    if args.run is not None:
        evolution_pictures(args.run)
    for folder in args.designer:
        designer_pictures(folder)


def evolution_pictures(run_dir: Path, top: int = 4) -> None:
    """``docs/evolution.png``, ``docs/best_curves.png`` and ``docs/best.png`` of a run."""
    runs = load_runs(run_dir)
    size = int(runs.runs["population_size"].iloc[0])
    plots.plot_evolution(runs.robots, population_size=size, path=HERE / "evolution.png")
    best = runs.robots.dropna(subset=["fitness"]).nlargest(top, "fitness")
    plots.plot_learning_curves(runs.curves, list(best["name"]), window=3,
                               path=HERE / "best_curves.png")
    chosen = [load_robot(run_dir / "robots" / f"{name}.json") for name in best["name"]]
    print(contact_sheet(chosen, PhysicsParams(), HERE / "best.png"))
    print(HERE / "evolution.png", HERE / "best_curves.png")


def designer_pictures(folder: Path) -> None:
    """``docs/designer_<arena>.png`` and ``docs/designer_robots_<arena>.png``, drawn
    again from a comparison folder's tables and robots as its own figures are."""
    arena = designer.folder_arena(folder)
    comparison = pd.read_csv(folder / designer.COMPARISON, dtype={"robot": str})
    written, notes = designer.write_figures(
        folder, comparison, arena, figure=HERE / f"designer_{arena}.png",
        pictures=HERE / f"designer_robots_{arena}.png")
    print(*written, *notes, sep="\n")


if __name__ == "__main__":
    main()
