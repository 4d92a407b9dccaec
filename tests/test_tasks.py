"""The tasks beside reach, through the task seam (SPEC section 3b): each passes both
libraries' checkers, a robot that should succeed does and a still one does not, its
reward terms sum to the reward, the same seed gives the same episode; and a task
written outside evo (``docs/tasks.md``'s worked example) runs through ``+exp=train``
and a smoke evolution whose recordings read back with the task's terms and marker."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch
from gymnasium.utils.env_checker import check_env
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory
from torchrl.envs.utils import check_env_specs

import evo.envs
from evo.envs.arena import ArenaParams
from evo.envs.core import TaskCore
from evo.envs.tasks.base import Task
from evo.envs.tasks.locomotion import Locomotion
from evo.envs.tasks.push import Push
from evo.envs.tasks.rough import Rough
from evo.envs.torchrl_env import TaskEnv
from evo.episode import Episode
from evo.record import McapRecorder, Recorders, RerunRecorder
from evo.record.mcap_file import TOPIC_SCENE
from evo.record.readback import read_episodes
from evo.robot import load_robot

REPO = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl"), "COLUMNS": "120"}

TASKS: dict[str, tuple[Task, ArenaParams]] = {
    "locomotion": (Locomotion(t_max=60), ArenaParams.open()),
    "push": (Push(t_max=60), ArenaParams.cluttered()),
    "rough": (Rough(t_max=60), ArenaParams(wall_height=0.2)),
}
"""Each new task, short, in its arena."""


@pytest.mark.parametrize("name", sorted(TASKS))
def test_both_libraries_checkers_pass_and_the_terms_sum_to_the_reward(name: str) -> None:
    task, arena = TASKS[name]
    env = TaskEnv(TaskCore(load_robot("robots/snake.json"), arena=arena, task=task,
                           num_envs=4, seed=0))
    check_env_specs(env, seed=0)
    rollout = env.rollout(80, break_when_any_done=False)  # past t_max: episodes end
    terms = sum(rollout["next", "reward_terms", term] for term in task.reward_terms)
    torch.testing.assert_close(terms, rollout["next", "reward"])
    assert rollout["next", "truncated"].any()
    ids = [i for i, kwargs in evo.envs.TASK_IDS.items() if type(kwargs.get("task")) is type(task)]
    assert len(ids) == 1, ids
    gym_env = gym.make(ids[0], robot="robots/four_wheeler.json", task=task)
    check_env(gym_env.unwrapped, skip_render_check=True)
    gym_env.reset(seed=0)
    _, reward, _, _, info = gym_env.step(gym_env.action_space.sample())
    assert reward == pytest.approx(sum(info[f"reward/{t}"] for t in task.reward_terms))


def test_the_same_seed_gives_the_same_episode() -> None:
    for task, arena in TASKS.values():
        runs = []
        for _ in range(2):
            core = TaskCore(load_robot("robots/twisted_four_wheeler.json"), arena=arena,
                            task=task, num_envs=3, seed=7)
            actions = np.random.default_rng(1).uniform(-1, 1, (40, 3, core.action_size))
            first = core.reset()
            steps = [core.step(a) for a in actions]
            runs.append((first, np.stack([s.observation for s in steps]),
                         np.stack([s.reward for s in steps]), core.target.copy()))
        for a, b in zip(*runs, strict=True):
            np.testing.assert_array_equal(a, b)


def test_a_snake_that_crawls_along_the_heading_succeeds_and_a_still_one_does_not() -> None:
    """With the heading fixed along +x, the snake driven at full speed (it crawls along
    its brain's x axis) travels about 5 m in 20 s; standing still travels nothing. The
    return is the distance along the heading, and the observation says where it is."""
    snake = load_robot("robots/snake.json")
    task = Locomotion(heading_range=0.0)
    core = TaskCore(snake, arena=ArenaParams.open(), task=task, num_envs=2, seed=0)
    obs = core.reset()
    np.testing.assert_allclose(obs[:, 6:8], [[1, 0], [1, 0]], atol=1e-6)  # heading ahead
    np.testing.assert_allclose(core.target, [[1, 0, 0], [1, 0, 0]])
    act = np.zeros((2, core.action_size))
    act[0] = 1.0
    returns = np.zeros(2)
    for _ in range(task.t_max):
        step = core.step(act)
        returns += step.reward
        assert not step.terminated.any()
    assert step.truncated.all() and list(step.success) == [True, False]
    assert returns[0] > 3 * task.success_distance and abs(returns[1]) < 0.02
    assert step.observation[0, 8] == pytest.approx(returns[0], rel=1e-4)


STRAIGHT = (1.0, 1.0, 0.0)
"""The four-wheeler's action that drives it straight ahead (+x) at about 0.37 m/s."""


def drive(core: TaskCore, driven: int, steps: int) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Drive the first ``driven`` arenas' four-wheelers straight ahead and leave the rest
    still; whether each succeeded and each term's sum until then."""
    act = np.zeros((core.num_envs, core.action_size))
    act[:driven] = STRAIGHT
    done = np.zeros(core.num_envs, dtype=bool)
    sums = {term: np.zeros(core.num_envs) for term in core.task.reward_terms}
    for _ in range(steps):
        step = core.step(act)
        for term in sums:
            sums[term] += step.terms[term] * ~done
        done |= step.terminated | step.truncated
        if step.success.any():
            assert (step.terminated == step.success).all()
    return done & (sums.get("success", 0) > 0), sums


OBJECT = {"locomotion": None, "push": "box", "rough": "terrain"}
"""The body each task adds to the scene."""


@pytest.mark.parametrize("name", sorted(TASKS))
def test_recordings_read_back_with_the_tasks_terms_marker_and_objects(
        name: str, tmp_path: Path) -> None:
    from test_record_files import entities  # the rerun CLI's view of an .rrd

    task, arena = TASKS[name]
    core = TaskCore(load_robot("robots/four_wheeler.json"), arena=arena, task=task,
                    num_envs=2, seed=3)
    played: list[Episode] = []
    core.watch(played.append)
    core.reset()
    while not played:
        core.step(np.tile(STRAIGHT, (2, 1)))
    mcap, rrd = tmp_path / "e.mcap", tmp_path / "e.rrd"
    with Recorders([McapRecorder(mcap, core.model, {}), RerunRecorder(rrd, core.model, {})]) as rec:
        rec.episode(played[0])
    (back,) = read_episodes(mcap)
    assert list(back.rewards) == list(task.reward_terms)
    np.testing.assert_array_equal(back.target, played[0].target)
    for term in task.reward_terms:
        np.testing.assert_array_equal(back.rewards[term], played[0].rewards[term])
    with mcap.open("rb") as f:
        (message,) = [m for _, _, _, m in make_reader(f, decoder_factories=[DecoderFactory()])
                      .iter_decoded_messages(topics=[TOPIC_SCENE])]
    drawn = {e.id: len(e.cubes) + len(e.cylinders) + len(e.spheres) for e in message.entities}
    assert drawn.get("target", 0) >= 1  # the marker
    if OBJECT[name]:
        body = OBJECT[name]
        assert drawn.get(body, 0) >= (10 if body == "terrain" else 1), drawn
        assert any(path.endswith(f"/{body}") for path in entities(rrd)), entities(rrd)
        moved = back.xpos[:, core.model.body(body).id]
        if body == "terrain":  # laid where the episode's draw put it
            assert np.linalg.norm(moved[0, :2]) > 0


def test_a_car_driven_at_a_box_pushes_it_to_the_goal_and_a_still_one_does_not() -> None:
    task = Push()
    core = TaskCore(load_robot("robots/four_wheeler.json"), task=task, num_envs=2, seed=0)
    core.reset()
    box = core.joint_address("box")
    core.qpos[:, box:box + 7] = [0.3, 0.0, task.box_size, 1.0, 0.0, 0.0, 0.0]
    for arena in range(2):
        obs = core.set_target(arena, [0.8, 0.0])
    np.testing.assert_allclose(obs[:, 6:8], [[1, 0], [1, 0]], atol=1e-6)  # the box ahead
    np.testing.assert_allclose(obs[:, -3:], [[1, 0, 0.5], [1, 0, 0.5]], atol=1e-6)
    success, sums = drive(core, 1, 200)
    assert list(success) == [True, False]
    # the box went from 0.5 m to under goal_radius from the goal
    assert task.push_weight * (0.5 - task.goal_radius) <= sums["push"][0] <= task.push_weight * 0.5
    assert abs(sums["push"][1]) < 1e-6 and abs(sums["near"][1]) < 1e-6


def test_rough_ground_varies_between_episodes_starts_level_and_a_driven_car_gets_there() -> None:
    arena = ArenaParams(wall_height=0.2)
    four = load_robot("robots/four_wheeler.json")
    flat = TaskCore(four, num_envs=1, seed=0)
    flat.reset()
    core = TaskCore(four, arena=arena, task=Rough(), num_envs=16, seed=0)
    core.reset()
    placements = core.batch.bind("mocap_pos").reshape(16, -1, 3)[:, core.mocap_index("terrain"), :2]
    assert len({tuple(p.round(6)) for p in placements}) > 4  # other stretches of the map
    np.testing.assert_allclose(core.module_positions()[:, :, 2],  # level start: as on flat
                               np.repeat(flat.module_positions()[:, :, 2], 16, axis=0))
    for i in range(16):
        core.set_target(i, [0.8, 0.0])
    success, _ = drive(core, 8, 1000)
    assert 2 <= success[:8].sum() < 8 and not success[8:].any(), success  # bumps in the way
    assert core.unstable_count == 0


def worked_example(tmp_path: Path) -> Path:
    """Write ``docs/tasks.md``'s example task (its ``title=`` code blocks) under
    ``tmp_path``, as a user would."""
    page = (REPO / "docs" / "tasks.md").read_text()
    blocks = re.findall(r'```\w+ title="([^"]+)"\n(.*?)```', page, flags=re.S)
    assert {name for name, _ in blocks} == {"escape.py", "myconf/env/task/escape.yaml"}
    for name, text in blocks:
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text(text)
    return tmp_path


def test_a_task_written_outside_evo_trains_evolves_and_is_recorded(tmp_path: Path) -> None:
    """The worked example's module and YAML, chosen with ``env/task=escape``: ``+exp=train``
    logs its term and a smoke evolution records its episodes with the term and marker."""
    here = worked_example(tmp_path)
    env = {**ENV, "PYTHONPATH": os.pathsep.join([str(here), str(REPO)])}
    common = ["env/task=escape", f"hydra.searchpath=[file://{here / 'myconf'}]",
              "learner.num_envs=8", "learner.rollout_steps=32", "learner.minibatch_size=128",
              "learner.eval_episodes=2"]
    train = subprocess.run(
        [sys.executable, str(REPO / "evo" / "main.py"), "+exp=train", "robot=robots/snake.json",
         "learner.total_steps=1024", *common, f"hydra.run.dir={here / 'train'}"],
        cwd=REPO, env=env, capture_output=True, text=True, timeout=300)
    assert train.returncode == 0, train.stderr[-3000:]
    curve = (here / "train" / "curve.csv").read_text().splitlines()[0].split(",")
    assert "train/reward/away" in curve and "train/reward/approach" not in curve
    summary = json.loads((here / "train" / "summary.json").read_text())
    assert summary["robot"] and "success_rate" in json.dumps(summary)
    smoke = subprocess.run(
        [sys.executable, str(REPO / "evo" / "main.py"), "+exp=smoke", *common,
         "ga.population_size=2", "ga.robot_budget=3", f"hydra.run.dir={here / 'smoke'}"],
        cwd=REPO, env=env, capture_output=True, text=True, timeout=300)
    assert smoke.returncode == 0, smoke.stderr[-3000:]
    recordings = sorted((here / "smoke" / "evals").glob("*.mcap"))
    assert len(recordings) == 3
    episodes = read_episodes(recordings[0])
    assert episodes and all(set(e.rewards) == {"away"} for e in episodes)
    assert all(np.allclose(e.target, 0) for e in episodes)  # the marker stays at the start
