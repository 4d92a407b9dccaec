"""Write the golden histories of ``tests/test_early_rejection.py``'s off-by-default test.

Each is a tiny serial run of a paper experiment; the test checks that the code of the
day gives the same history (early rejection off must change nothing). Regenerate them
only after a change meant to alter the numbers, and say why in the commit, or to record
them with another machine's arithmetic (``numerics.txt``, ``tests/numerics.py``):

    python tests/data/golden/make_golden.py
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
from pathlib import Path

import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
import numerics  # noqa: E402

HERE = Path(__file__).resolve().parent
REPO = HERE.parents[2]
POPULATION = 3
TINY = [f"ga.population_size={POPULATION}", "ga.robot_budget=6", "ga.schedule.initial=512",
        "ga.schedule.first=512", "ga.schedule.last=768", "learner.num_envs=4",
        "learner.rollout_steps=64", "learner.epochs=1", "learner.minibatch_size=128",
        "learner.hidden=[32,32]", "env.task.t_max=40", "executor=serial", "record=off"]
RUNS = {
    "paper_clean": ["+exp=paper_clean"],
    "paper_cluttered": ["+exp=paper_cluttered"],
    "ablation_paper_E+L": ["+exp=ablation_paper", "hydra.mode=RUN", "ga.structure=E",
                           "learner=ppo"],
    "ablation_paper_R+R": ["+exp=ablation_paper", "hydra.mode=RUN", "ga.structure=R",
                           "learner=random"],
}
COLUMNS = ["birth", "name", "method", "parents", "operator", "budget", "seed", "fitness",
           "accepted", "replaced", "env_steps", "episodes"]


def history(name: str, root: Path) -> pd.DataFrame:
    """The history of one tiny run of ``RUNS[name]``, the columns the test compares."""
    run_dir = root / name
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    done = subprocess.run([sys.executable, str(REPO / "evo" / "main.py"), *RUNS[name], *TINY,
                           f"hydra.run.dir={run_dir}"], cwd=root, env=env,
                          capture_output=True, text=True, timeout=600)
    if done.returncode != 0:
        raise RuntimeError(f"{name}: {done.stderr[-3000:]}")
    table = pd.read_csv(run_dir / "history.csv", dtype=str, keep_default_na=False)
    return table[COLUMNS]


if __name__ == "__main__":
    with tempfile.TemporaryDirectory() as tmp:
        for name in RUNS:
            history(name, Path(tmp)).to_csv(HERE / f"{name}.csv", index=False)
            print(HERE / f"{name}.csv")
    print(numerics.stamp(HERE))
