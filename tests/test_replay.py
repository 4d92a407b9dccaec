"""Replay re-simulates the deterministic episode recorded after training, exactly."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from evo.record import read_episodes, read_metadata
from evo.replay import replay


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("replay") / "run"
    subprocess.run(
        [
            sys.executable,
            "evo/main.py",
            "+exp=smoke",
            "executor=serial",
            "ga.population_size=2",
            "ga.robot_budget=2",
            f"hydra.run.dir={out}",
        ],
        check=True,
        capture_output=True,
        text=True,
        timeout=300,
    )
    return out


def test_replay_reproduces_the_recorded_deterministic_episode(
    run_dir: Path, tmp_path: Path
) -> None:
    history = pd.read_csv(run_dir / "history.csv")
    name = str(history["name"].iloc[0])
    mcap = run_dir / "evals" / f"{name}.mcap"
    recorded = read_episodes(mcap)[-1]  # the deterministic episode comes last
    assert read_metadata(mcap)["replay_seed"] == int(history["seed"].iloc[0])
    (played,) = replay(run_dir, name, episodes=1, seed=None, video=None, rrd=tmp_path / "r.rrd")
    assert len(played.time) == recorded.frames
    np.testing.assert_array_equal(played.time, recorded.time)
    np.testing.assert_allclose(played.xpos[:, 1:], recorded.xpos[:, 1:], rtol=0, atol=1e-6)
    np.testing.assert_allclose(played.xquat[:, 1:], recorded.xquat[:, 1:], rtol=0, atol=1e-6)
    for term, values in recorded.rewards.items():
        np.testing.assert_array_equal(played.rewards[term], values)
    assert played.success == recorded.success
    assert (tmp_path / "r.rrd").stat().st_size > 0


def test_replay_cli_names_a_missing_robot(run_dir: Path) -> None:
    """(The CLI writing a video and a recording runs as the README shows it, in
    tests/test_readme.py.)"""
    missing = subprocess.run(
        [sys.executable, "-m", "evo.replay", str(run_dir), "robot-00000000"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert missing.returncode == 2
    assert "robot-00000000" in missing.stderr and "Traceback" not in missing.stderr


def test_a_clip_keeps_the_frames_asked_for(run_dir: Path, tmp_path: Path) -> None:
    """``--size``, ``--fps`` and ``--seconds`` cut a short small webm: read back, it has
    the size asked for and one frame per 1/fps of the first seconds."""
    import imageio.v3 as iio

    from evo.replay import Clip

    name = pd.read_csv(run_dir / "history.csv")["name"].iloc[0]
    clip = tmp_path / "clip.webm"
    done = subprocess.run(
        [sys.executable, "-m", "evo.replay", str(run_dir), name, "--video", str(clip),
         "--size", "160x128", "--fps", "5", "--seconds", "2"],
        capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    frames = iio.imread(clip, index=None)
    assert frames.shape[1:3] == (128, 160)
    assert 9 <= len(frames) <= 11  # 2 s at 5 fps, from a 20 Hz episode: steps 0, 4, ... 40
    step = np.arange(0.0, 10.0, 0.05)
    assert Clip(fps=5, seconds=2).frames(step, 0.0) == list(range(0, 41, 4))
    assert Clip(fps=5, seconds=2).frames(step, 1.0) == list(range(0, 21, 4))
    assert Clip(fps=40).frames(step, 0.0) == list(range(200)), "at most every step"
    bad = subprocess.run(
        [sys.executable, "-m", "evo.replay", str(run_dir), name, "--video", str(clip),
         "--size", "160by128"], capture_output=True, text=True, timeout=120)
    assert bad.returncode == 2 and "WIDTHxHEIGHT" in bad.stderr
    with pytest.raises(ValueError, match="seconds"):
        Clip(seconds=0)
