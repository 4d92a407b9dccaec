"""A user's mistake gets one clear line (exit 1 or 2) naming the file, key or value, never
a traceback: checkpoints, the robot and replay CLIs, the reports, the gymnasium env, and
runs whose files are half written or still being written."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import gymnasium as gym
import numpy as np
import pandas as pd
import pytest
import torch
from test_evolution import ENV, TINY, main_cmd

import evo.envs  # noqa: F401 - registers evo/Reach-v0
from analysis.ablation.report import main as report_main
from analysis.early_slope.report import main as early_slope_main
from analysis.load import load_runs
from evo.envs.params import observation_size
from evo.envs.tasks.reach import Reach
from evo.learners.common import load_checkpoint
from evo.replay import main as replay_main
from evo.robot import load_robot
from evo.robot.__main__ import main as robot_main
from evo.run.files import RunLock

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A finished tiny serial evolution (6 robots, policies, recordings)."""
    run_dir = tmp_path_factory.mktemp("user") / "run"
    done = subprocess.run(main_cmd(*TINY, "executor=serial", f"hydra.run.dir={run_dir}"),
                          cwd=run_dir.parent, env=ENV, capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]
    return run_dir


def two_robots(run_dir: Path) -> tuple[str, str]:
    """Two robots of the run with the same number of actuators."""
    history = pd.read_csv(run_dir / "history.csv")
    sizes = {n: load_robot(run_dir / "robots" / f"{n}.json").n_actuators
             for n in history["name"]}
    for a in sizes:
        for b in sizes:
            if a != b and sizes[a] == sizes[b]:
                return a, b
    raise AssertionError(f"no two robots with equal action sizes: {sizes}")


def truncated(path: Path, out: Path) -> Path:
    out.write_bytes(path.read_bytes()[:3000])
    return out


def one_line_error(stderr: str, *needles: str) -> None:
    lines = [line for line in stderr.strip().splitlines() if line.strip()]
    assert lines and "Traceback" not in stderr, stderr[-3000:]
    assert all(n in lines[-1] for n in needles), (needles, stderr[-2000:])


@pytest.mark.slow
def test_evaluate_names_a_checkpoint_that_does_not_fit(run_dir: Path, tmp_path: Path) -> None:
    a, b = two_robots(run_dir)
    robot, policy = run_dir / "robots" / f"{a}.json", run_dir / "evals" / f"{a}.pt"
    cases = [
        ([f"checkpoint={run_dir}"], [str(run_dir), "a folder, not a policy checkpoint"]),
        ([f"checkpoint={truncated(policy, tmp_path / 'cut.pt')}"],
         ["cut.pt", "not an evo policy checkpoint"]),
        ([f"checkpoint={policy}", "env.task.observe_up=true"],
         ["observes", "env.task.observe_up"]),
        ([f"checkpoint={run_dir / 'evals' / f'{b}.pt'}"], [f"trained on {b[:14]}", a]),
    ]
    procs = [subprocess.Popen(main_cmd("+exp=evaluate", f"robot={robot}", *args,
                                       f"hydra.run.dir={tmp_path / f'eval{i}'}"),
                              cwd=tmp_path, env=ENV, stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True)
             for i, (args, _) in enumerate(cases)]
    for (args, needles), proc in zip(cases, procs, strict=True):
        _, err = proc.communicate(timeout=180)
        assert proc.returncode == 2, (args, err[-2000:])
        one_line_error(err, "error: bad config: checkpoint:", *needles)
    # A checkpoint that fits runs: the README's +exp=evaluate command (tests/test_readme.py).


def test_a_checkpoint_stores_its_robot_and_sizes(run_dir: Path) -> None:
    name = pd.read_csv(run_dir / "history.csv")["name"].iloc[0]
    robot = load_robot(run_dir / "robots" / f"{name}.json")
    state = torch.load(run_dir / "evals" / f"{name}.pt", weights_only=True)
    assert state["robot"] == robot.hash
    obs_size = observation_size(robot, Reach())
    assert (state["obs_size"], state["action_size"]) == (obs_size, robot.n_actuators)
    load_checkpoint(run_dir / "evals" / f"{name}.pt", robot=robot, obs_size=obs_size)


def test_replay_names_a_bad_checkpoint_and_a_missing_robot_name(
    run_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    copy = tmp_path / "run"
    shutil.copytree(run_dir, copy)
    name = pd.read_csv(copy / "history.csv")["name"].iloc[0]
    truncated(run_dir / "evals" / f"{name}.pt", copy / "evals" / f"{name}.pt")
    assert replay_main([str(copy), name]) == 2
    one_line_error(capsys.readouterr().err, f"{name}.pt", "not an evo policy checkpoint")
    assert replay_main([str(copy)]) == 2
    one_line_error(capsys.readouterr().err, "name the robot", "its robots: robot-")


def test_render_names_an_output_that_is_no_png(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert robot_main(["render", str(REPO / "robots" / "four_wheeler.json"),
                       "--out", str(tmp_path / "x.txt")]) == 2
    one_line_error(capsys.readouterr().err, "x.txt", ".png")
    assert not (tmp_path / "x.txt").exists()


def test_reports_name_an_output_that_is_a_file_and_cuts_beyond_the_budget(
    run_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    afile = tmp_path / "afile"
    afile.write_text("keep")
    assert report_main([str(run_dir), "--out", str(afile)]) == 2
    one_line_error(capsys.readouterr().err, str(afile), "not a folder")
    assert early_slope_main([str(run_dir), "--out", str(tmp_path / "es"),
                             "--fractions", "0.5", "1.5"]) == 2
    one_line_error(capsys.readouterr().err, "--fractions", "1.5")
    with pytest.raises(SystemExit) as exited:
        report_main([str(run_dir), "--out", str(tmp_path / "r"), "--first", "0"])
    assert exited.value.code == 2
    assert "--first" in capsys.readouterr().err and not (tmp_path / "r").exists()
    assert afile.read_text() == "keep"


def test_a_half_written_or_running_run_is_not_called_complete(
    run_dir: Path, tmp_path: Path
) -> None:
    assert load_runs([run_dir]).runs["status"].tolist() == ["complete"]
    cut = tmp_path / "cut"
    shutil.copytree(run_dir, cut)
    text = (cut / "history.csv").read_text()
    (cut / "history.csv").write_text(text[: len(text) - 40])  # the last row cut mid-row
    runs = load_runs([cut])
    assert runs.runs["status"].tolist() == ["partial"]
    assert not runs.runs["complete"].any()
    assert len(runs.robots) == 5, "the broken row is left out, not counted as a failure"
    assert any("cut mid-row" in note for note in runs.notes)
    with RunLock(run_dir):  # a live process holds the run
        assert load_runs([run_dir]).runs["status"].tolist() == ["running"]


def test_the_gymnasium_env_refuses_a_wrong_action_and_steps_out_of_order() -> None:
    env = gym.make("evo/Reach-v0", robot="robots/four_wheeler.json",
                   task=Reach(t_max=3)).unwrapped
    with pytest.raises(gym.error.ResetNeeded, match="reset"):
        env.step(np.zeros(3, dtype=np.float32))
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"expected shape \(3,\).*got shape \(1,\)"):
        env.step(np.zeros(1))
    truncated_at = [env.step(np.zeros(3))[3] for _ in range(3)]
    assert truncated_at == [False, False, True]
    with pytest.raises(gym.error.ResetNeeded):
        env.step(np.zeros(3))
    env.reset(seed=1)
    env.step(np.zeros(3))  # a new episode steps again
