"""The noise sweep: the new learner and physics options keep the seed's curve, the sweep
runs real trials through Hydra's Optuna sweeper, continues after a stop, and refuses bad
settings with one line."""

from __future__ import annotations

import dataclasses
import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest
import torch
from tensordict import TensorDict

from analysis.noise_sweep import trials_table
from evo.edge import CONF_DIR, compose_config
from evo.envs.params import EnvConfig
from evo.envs.tasks.reach import Reach
from evo.learners.common import LearnerConfig, make_policy
from evo.learners.ppo import RewardScale
from evo.learners.ppo import train as train_ppo
from evo.robot import load_robot
from evo.robot.builder import PhysicsParams
from evo.sweep import SweepError, check_params

REPO = Path(__file__).resolve().parents[1]

@pytest.fixture()
def sweeper() -> None:
    """The sweep extra (``pip install -e '.[sweep]'``; ``make test`` installs it)."""
    pytest.importorskip("hydra_plugins.hydra_optuna_sweeper", reason="the sweep extra")

# ---------------------------------------------------------------- the new options


def test_new_options_keep_the_seeds_curve_and_change_it() -> None:
    robot = load_robot(REPO / "robots" / "four_wheeler.json")
    env = EnvConfig(task=Reach(t_max=40, frame_skip=5))
    physics = PhysicsParams(timestep=0.01)
    on = LearnerConfig(num_envs=4, rollout_steps=32, minibatch_size=64, hidden=(16, 16),
                       policy_out_gain=0.0, reward_scaling=True)
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        runs = [train_ppo(robot, physics=physics, env=env, config=config, budget=256, seed=3)
                .curve.drop(columns="wall_seconds")
                for config in (on, on, dataclasses.replace(on, reward_scaling=False))]
    finally:
        torch.set_num_threads(threads)
    pd.testing.assert_frame_equal(runs[0], runs[1])
    assert not runs[0].equals(runs[2]), "reward scaling changes the updates"
    policy = make_policy(10, 2, on)
    assert torch.count_nonzero(policy.head.mlp[-1].weight) == 0, "a last layer of zeros"


def test_reward_scale_divides_by_the_running_std_of_the_discounted_return() -> None:
    reward = torch.tensor([[1.0, 1.0, 1.0], [2.0, 0.0, 2.0]]).unsqueeze(-1)
    done = torch.tensor([[False, True, False], [False, False, False]]).unsqueeze(-1)
    batch = TensorDict({"next": {"reward": reward.clone(), "done": done}}, batch_size=[2, 3])
    RewardScale(num_envs=2, gamma=0.5)(batch)
    # Discounted returns: arena 0: 1, 1.5, then a new episode: 1; arena 1: 2, 1, 2.5.
    returns = torch.tensor([1.0, 1.5, 1.0, 2.0, 1.0, 2.5], dtype=torch.float64)
    std = torch.sqrt(returns.var(unbiased=False) + 1e-8).float()
    torch.testing.assert_close(batch["next", "reward"], reward / std)


# ---------------------------------------------------------------- the sweep, for real

TINY = ["hydra.sweeper.n_trials=2", "noise_sweep.robots=3", "noise_sweep.budget=128",
        "noise_sweep.resamples=20", "learner.num_envs=2", "learner.rollout_steps=64",
        "env.task.t_max=40", "executor=serial",
        # the shipped space's minibatches (256-2048) exceed this batch of 2 x 64
        "learner.minibatch_size=choice(64,128)"]
"""Two trials of 3 robots x 2 seeds x 128 env steps, over the shipped search space."""


def sweep_command(sweep_dir: Path, *extra: str) -> list[str]:
    return [sys.executable, str(REPO / "evo" / "main.py"), "+exp=noise_sweep", *TINY,
            f"hydra.sweep.dir={sweep_dir}", *extra]


def environment() -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": str(REPO), "MUJOCO_GL": "egl"}


def finished_trials(sweep_dir: Path) -> list[Path]:
    return sorted(sweep_dir.glob("trials/*/trial.json"))


@pytest.mark.long  # a trial through the sweeper: the signal test below
def test_the_sweep_runs_trials_and_a_rerun_continues_the_study(
    sweeper: None, tmp_path: Path,
) -> None:
    sweep_dir = tmp_path / "sweep"
    command = sweep_command(sweep_dir)
    # Stop the sweep (SIGINT, as Ctrl-C) once its first trial is done.
    with (tmp_path / "first.log").open("w") as log:
        first = subprocess.Popen(command, cwd=REPO, env=environment(), stdout=log, stderr=log)
        while not finished_trials(sweep_dir) and first.poll() is None:
            time.sleep(0.2)
        first.send_signal(signal.SIGINT)
        first.wait(timeout=120)
    err = (tmp_path / "first.log").read_text()
    assert first.returncode != 0 or len(finished_trials(sweep_dir)) == 2, err[-2000:]
    trial = finished_trials(sweep_dir)[0]
    kept = pd.read_csv(trial.parent / "trainings.csv")
    # The same command again: it continues the stored study up to its 2 trials.
    again = subprocess.run(command, cwd=REPO, env=environment(), capture_output=True, text=True,
                           timeout=300)
    assert again.returncode == 0, again.stderr[-3000:]
    # 1 of 2, or 0 of 2 when the signal came between the trial's files and the study's
    # record of it: that trial is then asked again and reuses its trainings (below).
    assert re.search(r"noise sweep: [01] of 2 trials complete", again.stderr), again.stderr
    table = trials_table(sweep_dir)
    assert (table["state"] == "COMPLETE").sum() == 2, table
    assert len(finished_trials(sweep_dir)) >= 2
    pd.testing.assert_frame_equal(pd.read_csv(trial.parent / "trainings.csv").head(len(kept)),
                                  kept, obj="the first trial's trainings, reused")
    result = json.loads(trial.read_text())
    assert len(kept) == 6 and result["core_seconds_per_robot"] > 0
    row = table[table["folder"] == trial.parent.name].iloc[0]
    assert row["spearman"] == pytest.approx(result["spearman"], nan_ok=True)
    assert {"learner.gamma", "learner.epochs", "physics_step"} <= set(table.columns)


@pytest.mark.slow
def test_a_signal_stops_a_trial_whose_trainings_run_in_workers(
    sweeper: None, tmp_path: Path,
) -> None:
    """SIGTERM while a long training runs in the local pool: the sweep ends (it stops its
    workers) instead of waiting hours for the training to finish."""
    sweep_dir = tmp_path / "sweep"
    command = sweep_command(sweep_dir, "hydra.sweeper.n_trials=1",
                            "noise_sweep.budget=10000000", "executor=local",
                            "executor.workers=1", "record=default")
    with (tmp_path / "log").open("w") as log:
        proc = subprocess.Popen(command, cwd=REPO, env=environment(), stdout=log, stderr=log)
        try:
            # The worker is training once its recording of the training is open.
            deadline = time.monotonic() + 120
            while not list(sweep_dir.glob("trials/*/evals/*.mcap")) and proc.poll() is None:
                assert time.monotonic() < deadline, (tmp_path / "log").read_text()[-2000:]
                time.sleep(0.2)
            proc.send_signal(signal.SIGTERM)
            proc.wait(timeout=120)  # the 10M-step training takes hours: stopped, not awaited
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
    err = (tmp_path / "log").read_text()
    assert proc.returncode == 143 and "Traceback" not in err, err[-2000:]
    assert not list(sweep_dir.glob("trials/*/trainings.csv")), "no training ran to its end"


# ---------------------------------------------------------------- bad settings


def test_a_bad_sweep_stops_at_once_with_one_line(sweeper: None, tmp_path: Path) -> None:
    """From the command line (one process start; every other case is checked below by
    the same function, in this process)."""
    sweep_dir, message = tmp_path / "sweep", "learner.teleport: unknown parameter"
    done = subprocess.run(sweep_command(sweep_dir, "learner.teleport=choice(1,2)"), cwd=REPO,
                          env=environment(), capture_output=True, text=True, timeout=300)
    assert done.returncode == 2, done.stderr[-2000:]
    lines = [line for line in done.stderr.splitlines() if "error" in line.lower()]
    assert len(lines) == 1 and message in lines[0] and "Traceback" not in done.stderr, lines
    assert not sweep_dir.exists(), "nothing was started"


@pytest.mark.parametrize(("params", "message"), [
    ({"learner.epochs": "range(9, 2)"}, "learner.epochs: range(9, 2) is empty"),
    ({"learner.gamma": "interval(0.9, 0.9)"}, "learner.gamma: interval(0.9, 0.9) is empty"),
    ({"learner.teleport": "choice(1, 2)"}, "learner.teleport: unknown parameter"),
    ({"physics_step": "choice(dt5ms_x10, dt1ms_x50)"}, "no option dt1ms_x50"),
    ({"physics_step": "choice(1, 2)"}, "no option 1, 2"),  # options parsed as numbers
    ({"+learner.teleport": "choice(1, 2)"}, "+learner.teleport: unknown parameter"),
    ({"learner.epochs": "choice()"}, "learner.epochs"),
])
def test_each_bad_parameter_is_named(sweeper: None, params: dict[str, str],
                                     message: str) -> None:
    from hydra import compose, initialize_config_dir

    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        config = compose("config", overrides=["+exp=noise_sweep"], return_hydra_config=True)
    check_params(dict(config.hydra.sweeper.params), config, CONF_DIR)  # the shipped space
    with pytest.raises(SweepError, match="hydra.sweeper.params") as caught:
        check_params(params, config, CONF_DIR)
    assert message in str(caught.value)
    assert compose_config(["+exp=noise_sweep"]).task == "noise_sweep"
