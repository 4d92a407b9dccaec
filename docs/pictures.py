"""Make the README's pictures with the project's own code.

    MUJOCO_GL=egl python docs/pictures.py [--curve <train run>] [--run <evolution run>]
        [--designer <comparison folder> ...] [--recording <evals/name.mcap>]

Writes ``docs/robots.png`` (the example robots), ``docs/arena.png`` (the cluttered
arena with the four-wheeler), given a training run (``+exp=train``) ``docs/curve.png``,
and given an evolution run ``docs/evolution.png`` (every robot's fitness in birth order
with the population's best and mean), ``docs/best_curves.png`` (learning curves of the
best robots) and ``docs/best.png`` (the best robots), and given comparison folders of
``python -m analysis.designer`` ``docs/designer_<arena>.png`` (every robot's metrics,
evolved against hand-made) and ``docs/designer_robots_<arena>.png`` (the best of each),
and given an evaluation's recording (``evals/<name>.mcap``) ``docs/recording.png``: what
its Foxglove layout shows (the robot's path, the learning curve, the reward terms), read
back from the file by ``evo.record``.
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
from evo.record.readback import read_episodes
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
    parser.add_argument("--recording", type=Path, help="an evaluation's evals/<name>.mcap")
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
    if args.recording is not None:
        recording_picture(args.recording)


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


def recording_picture(path: Path) -> None:
    """``docs/recording.png``: an evaluation's recording read back as its Foxglove layout
    (``docs/foxglove/evaluation.json``) and the rerun viewer show it: the robot's path
    over the recorded episodes seen from above with each episode's target, the learning
    curve, and the reward terms of the last recorded episode (the deterministic one)."""
    episodes, curve = read_episodes(path), read_curve(path)
    fig, (top, learning, terms) = plt.subplots(1, 3, figsize=(12, 3.4))
    for episode in episodes:
        body = int(np.argmax(np.ptp(episode.xpos[:, :, :2], axis=0).sum(-1)))  # the robot's
        line, = top.plot(episode.xpos[:, body, 0], episode.xpos[:, body, 1], lw=1.2,
                         label=f"episode {episode.index} ({'reached' if episode.success else 'missed'})")
        top.scatter(*episode.target[:2], marker="x", color=line.get_color())
    top.set(xlabel="x (m)", ylabel="y (m)", title="/tf: the robot's path, x its target")
    top.legend(fontsize=7)
    learning.plot(curve["env_steps"], curve["train/mean_return"].interpolate(), color="tab:blue")
    learning.set(xlabel="env steps", ylabel="mean return", title="/train/curve")
    last = episodes[-1]
    for term, values in last.rewards.items():
        terms.plot(last.time, np.cumsum(values), label=term)
    terms.set(xlabel="simulated time (s)", ylabel="cumulative reward",
              title=f"/episode/step: episode {last.index}")
    terms.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(HERE / "recording.png", dpi=100)
    print(HERE / "recording.png")


if __name__ == "__main__":
    main()
