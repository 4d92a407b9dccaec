"""Evaluate the policies of ``+exp=designer`` folders again, on more episodes: each
training's handed-back policy (``evals/<training>.pt``) with its mean action and with its
noise, on ``--episodes`` fresh episodes of its arena (seed + ``--offset``: neither the
evaluation after training's seed + 1 nor the periodic one's seed + 2).

    python docs/results/deployed/reevaluate.py LEVER=RETRAIN_DIR ... --episodes 100 \
        --out docs/results/deployed/reevaluated.csv

Twenty episodes put a success rate near 0.85 within about 0.08 (one standard error);
the gap between the mean action and the noisy policy, measured on the same few
episodes, is that noisy too. Writes one row per training (the deterministic and the
noisy success and mean return on the new episodes, beside the evaluation after
training's success, ``first_``) as each one is done, then, per lever, arena and robot,
the mean over seeds, the worst seed and the gap (beside it, the same ``.md``, and on
the screen). An earlier ``--out`` file keeps its rows for the trainings not given again.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Iterator
from pathlib import Path

import pandas as pd

from analysis.markdown import markdown_table
from evo.edge import run_config
from evo.envs.params import observation_size
from evo.learners.common import load_checkpoint
from evo.learners.rollouts import evaluate_policy
from evo.robot import load_robot
from evo.run.layout import RetrainLayout
from evo.run.records import read_trainings

KEY = ["lever", "arena", "robot", "seed"]


def reevaluate(lever: str, folder: Path, *, episodes: int, offset: int,
               robots: list[str] | None = None, seeds: list[int] | None = None
               ) -> Iterator[dict[str, object]]:
    """One row per finished training of ``folder`` (of ``robots`` and ``seeds``, when
    given): its policy on ``episodes`` new episodes, deterministically and with its
    noise."""
    layout = RetrainLayout(folder)
    config = run_config(folder)
    for row in read_trainings(layout.trainings).itertuples():
        if (robots and row.robot not in robots) or (seeds and row.seed not in seeds):
            continue
        robot = load_robot(layout.robot(str(row.robot)), config.limits)
        policy = load_checkpoint(layout.policy(str(row.name)), robot=robot,
                                 obs_size=observation_size(robot, config.env.task))
        det, noisy = (evaluate_policy(robot, policy, physics=config.physics, env=config.env,
                                      episodes=episodes, seed=int(row.seed) + offset,
                                      stochastic=stochastic)
                      for stochastic in (False, True))
        print(f"{lever} {row.arena} {row.name}: success {det.success_rate:.2f} "
              f"(noisy {noisy.success_rate:.2f}) over {episodes} episodes", flush=True)
        yield {"lever": lever, "arena": row.arena, "robot": row.robot, "seed": row.seed,
               "episodes": episodes, "success": det.success_rate,
               "noisy_success": noisy.success_rate, "eval_return": det.mean_return,
               "noisy_return": noisy.mean_return, "first_success": row.success_rate,
               "first_noisy_success": row.stochastic_success_rate}


def write(out: Path, earlier: pd.DataFrame | None, rows: list[dict[str, object]]
          ) -> pd.DataFrame:
    """Write ``out``: ``rows``, and the rows of ``earlier`` (the file as it was before
    this call of the script) of the trainings ``rows`` does not give, sorted."""
    table = new = pd.DataFrame(rows)
    if earlier is not None:
        kept = earlier.merge(new[KEY], on=KEY, how="left", indicator=True)
        table = pd.concat([earlier[(kept["_merge"] == "left_only").to_numpy()], new],
                          ignore_index=True)
    table = table.sort_values(KEY, ignore_index=True)
    table.to_csv(out, index=False)
    return table


def cells(table: pd.DataFrame) -> pd.DataFrame:
    """Per lever, arena and robot: mean and worst seed of the new evaluation, the gap
    (noisy minus deterministic, as ``table.py``'s) and the same of the evaluation after training
    (``first_``: ``trainings.csv``'s, on ``learner.eval_episodes`` episodes, seed + 1)."""
    grouped = table.groupby(["lever", "arena", "robot"], sort=True)
    out = grouped.agg(seeds=("seed", "size"), episodes=("episodes", "first"),
                      success=("success", "mean"), worst=("success", "min"),
                      noisy_success=("noisy_success", "mean"),
                      first_success=("first_success", "mean"),
                      first_noisy_success=("first_noisy_success", "mean")).reset_index()
    out["gap"] = out["noisy_success"] - out["success"]
    out["first_gap"] = out["first_noisy_success"] - out["first_success"]
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("folders", nargs="+", metavar="LEVER=RETRAIN_DIR")
    parser.add_argument("--episodes", type=int, default=100)
    parser.add_argument("--offset", type=int, default=3,
                        help="the episodes' seed: the training's seed + this")
    parser.add_argument("--robots", nargs="+", metavar="ROBOT",
                        help="only these robots' trainings (trainings.csv's robot column)")
    parser.add_argument("--seeds", nargs="+", type=int, metavar="SEED",
                        help="only the trainings of these seeds")
    parser.add_argument("--out", type=Path, required=True, help="the CSV to write")
    args = parser.parse_args(argv)
    if args.episodes < 1:
        parser.error(f"--episodes: expected a positive count, got {args.episodes}")
    given = []
    for item in args.folders:
        lever, sep, folder = item.partition("=")
        if not sep or not lever or not (Path(folder) / "trainings.csv").is_file():
            parser.error(f"{item}: expected LEVER=RETRAIN_DIR, a folder with trainings.csv")
        given.append((lever, Path(folder)))
    earlier = pd.read_csv(args.out) if args.out.is_file() else None
    args.out.parent.mkdir(parents=True, exist_ok=True)
    rows: list[dict[str, object]] = []
    for lever, folder in given:
        for row in reevaluate(lever, folder, episodes=args.episodes, offset=args.offset,
                              robots=args.robots, seeds=args.seeds):
            rows.append(row)
            table = write(args.out, earlier, rows)  # after each one: an interruption keeps them
    if not rows:
        parser.error("no training to evaluate: check --robots and --seeds against "
                     "trainings.csv")
    summary = markdown_table(cells(table))
    args.out.with_suffix(".md").write_text(summary + "\n")
    print(summary)
    return 0


if __name__ == "__main__":
    sys.exit(main())
