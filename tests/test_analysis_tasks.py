"""The cross-task matrix (``python -m analysis.tasks``) on real retrainings: two bodies,
each trained from scratch under two seeds on two tasks, read back as a matrix of
evaluation returns with intervals, the verdict on each task's own evolved body, and a
heatmap."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

from analysis import tasks

REPO = Path(__file__).resolve().parents[1]
TINY = ["learner.total_steps=512", "learner.num_envs=4", "learner.rollout_steps=32",
        "learner.minibatch_size=64", "learner.epochs=1", "learner.eval_episodes=3",
        "env.task.t_max=40", "executor=serial"]  # in this process: no workers to start


@pytest.fixture(scope="module")
def trained(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The snake as locomotion's evolved body and the four-wheeler as reach's designed
    one, each retrained under 2 seeds on reach and on locomotion."""
    root = tmp_path_factory.mktemp("tasks")
    bodies = root / "bodies"
    bodies.mkdir()
    shutil.copy(REPO / "robots" / "snake.json", bodies / "locomotion_evolved.json")
    shutil.copy(REPO / "robots" / "four_wheeler.json", bodies / "reach_designed.json")
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    folders = {}
    for task in ("reach", "locomotion"):
        folders[task] = root / task
        done = subprocess.run(
            [sys.executable, str(REPO / "evo" / "main.py"), "+exp=designer",
             f"retrain.robots={bodies}", "retrain.seeds=2", "retrain.confirm=0",
             f"env/task={task}", *TINY, f"hydra.run.dir={folders[task]}"],
            cwd=REPO, env=env, capture_output=True, text=True, timeout=300)
        assert done.returncode == 0, done.stderr[-3000:]
    return folders


def test_every_body_on_every_task_with_intervals_and_the_diagonal(
        trained: dict[str, Path], tmp_path: Path) -> None:
    out = tmp_path / "matrix"
    argv = [f"{task}={folder}" for task, folder in trained.items()]
    assert tasks.main([*argv, "--out", str(out)]) == 0
    table = pd.read_csv(out / "matrix.csv")
    assert sorted(zip(table["body"], table["task"], strict=True)) == [
        ("locomotion_evolved", "locomotion"), ("locomotion_evolved", "reach"),
        ("reach_designed", "locomotion"), ("reach_designed", "reach")]
    assert (table["trainings"] == 2).all()
    assert ((table["low"] <= table["eval_return"]) & (table["eval_return"] <= table["high"])).all()
    raw = pd.concat([pd.read_csv(folder / "trainings.csv").assign(task=task)
                     for task, folder in trained.items()])
    means = raw.groupby(["robot", "task"])["eval_mean_return"].mean()
    for row in table.itertuples():
        assert row.eval_return == pytest.approx(means[(row.body, row.task)])
    verdicts = tasks.diagonal(table).set_index("task")["verdict"]
    assert verdicts["reach"] == "no body evolved for it"
    best = table[table["task"] == "locomotion"].set_index("body")["eval_return"]
    if best["locomotion_evolved"] >= best["reach_designed"]:
        assert verdicts["locomotion"] == "best"
    else:
        assert verdicts["locomotion"] in ("tied with the best", "beaten")
    text = (out / "matrix.md").read_text()
    assert "locomotion_evolved" in text and (out / "matrix.png").stat().st_size > 1000


def test_a_folder_without_trainings_is_refused(tmp_path: Path) -> None:
    with pytest.raises(SystemExit):
        tasks.main([f"push={tmp_path}", "--out", str(tmp_path / "out")])
