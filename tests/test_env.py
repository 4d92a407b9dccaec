"""The reach task, its batched TorchRL face and its gymnasium face."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import gymnasium as gym
import mujoco
import numpy as np
import pytest
import torch
from gymnasium.utils.env_checker import check_env
from torchrl.envs.utils import check_env_specs

import evo.envs
from evo.envs.arena import ArenaParams, obstacle_ranges
from evo.envs.core import TaskCore
from evo.envs.scene import Scene, compile_scene
from evo.envs.tasks.reach import Reach
from evo.envs.torchrl_env import TaskEnv
from evo.episode import Episode
from evo.record.config import EpisodeChoice
from evo.robot import Robot, load_robot
from evo.robot.builder import PhysicsParams

EXAMPLES = ["four_wheeler", "inchworm", "snake", "twisted_four_wheeler"]


def robot(name: str = "four_wheeler") -> Robot:
    return load_robot(f"robots/{name}.json")


def forward(core: TaskCore, sign: float = 1.0) -> np.ndarray:
    """All motors at ``sign``, pivots held straight."""
    action = np.zeros((core.num_envs, core.action_size))
    action[:, : len(core.built.motors)] = sign
    return action


@pytest.mark.parametrize("name", EXAMPLES)
def test_sizes_follow_the_robot(name: str) -> None:
    r = robot(name)
    core = TaskCore(r, num_envs=3, seed=0)
    m, n = r.n_motors, r.n_pivots
    assert core.reset().shape == (3, 9 + 2 * (m + n))
    assert core.action_size == m + n == core.model.nu
    up = TaskCore(r, task=Reach(observe_up=True), num_envs=2, seed=0)
    obs = up.reset()
    assert obs.shape == (2, 12 + 2 * (m + n))
    # At rest, upright: gravity points down the brain's -z.
    np.testing.assert_allclose(obs[:, -3:], [[0, 0, -1]] * 2, atol=1e-6)


def test_stall_value_grows_while_the_robot_stands_and_drops_when_it_moves() -> None:
    task = Reach(observe_stall=True, stall_radius=0.05, stall_seconds=1.0)
    core, plain = (TaskCore(robot(), task=t, num_envs=2, seed=0) for t in (task, Reach()))
    obs = core.reset()
    np.testing.assert_array_equal(obs[:, :-1], plain.reset())  # one value more, at the end
    assert (obs[:, -1] == 0).all()
    still = np.zeros((2, core.action_size))
    for k in range(1, 31):  # 1.5 s standing: 0.05 s a step over 1 s, capped at 1
        obs = core.step(still).observation
        np.testing.assert_allclose(obs[:, -1], min(k * 0.05, 1.0), atol=1e-6)
    seen = []
    for _ in range(40):  # driving: back to 0 each time the brain has moved 5 cm
        seen.append(core.step(forward(core)).observation[0, -1])
    assert seen[-1] < 0.25 and 0.0 in seen
    assert (np.diff(seen) < 0).any()  # it fell while driving (from 1 to 0)
    assert core.reset(np.array([False, True]))[1, -1] == 0  # a new episode starts at 0


def test_clock_follows_the_episode_time_and_restarts_with_it() -> None:
    task = Reach(observe_clock=True, clock_period=0.5)
    core, plain = (TaskCore(robot(), task=t, num_envs=2, seed=0) for t in (task, Reach()))
    obs = core.reset()
    np.testing.assert_array_equal(obs[:, :-2], plain.reset())  # two values more, at the end
    np.testing.assert_allclose(obs[:, -2:], [[0, 1]] * 2, atol=1e-6)
    still = np.zeros((2, core.action_size))
    for k in range(1, 13):  # 0.05 s a step: a quarter period every 2.5 steps
        obs = core.step(still).observation
        phase = 2 * math.pi * k * 0.05 / 0.5
        np.testing.assert_allclose(obs[:, -2:], [[math.sin(phase), math.cos(phase)]] * 2,
                                   atol=1e-5)
    # A new episode starts at 0; the arena that goes on keeps its time.
    again = core.reset(np.array([False, True]))
    np.testing.assert_allclose(again[1, -2:], [0, 1], atol=1e-6)
    np.testing.assert_array_equal(again[0], obs[0])


def test_stall_count_counts_each_long_stand_once_per_episode() -> None:
    task = Reach(observe_stall=True, observe_stall_count=True, stall_seconds=1.0)
    core = TaskCore(robot(), task=task, num_envs=1, seed=0)
    assert core.reset().shape[1] == TaskCore(robot(), num_envs=1).obs_size + 2
    still = np.zeros((1, core.action_size))
    counts = [core.step(still).observation[0, -1] for _ in range(30)]
    np.testing.assert_allclose(counts, [0.0] * 19 + [0.25] * 11)  # at 1 s still, once
    for _ in range(20):
        core.step(forward(core))
    for _ in range(20):
        obs = core.step(still).observation
    assert obs[0, -1] == pytest.approx(0.5)  # standing 1 s again: a second stall
    assert core.reset()[0, -1] == 0


def test_obstacle_ranges_see_the_nearest_rock_or_wall_in_each_sector() -> None:
    origin = np.array([[0.0, 0.0], [1.5, 0.0]])
    heading = np.array([0.0, math.pi / 2])  # the second looks along +y
    centres = np.array([[[0.5, 0.0], [0.3, 0.0], [-0.3, 1.0]],   # two ahead, one back left
                        [[1.5, 0.05], [9.0, 9.0], [9.0, 9.0]]])  # the second is inside one
    radii = np.array([0.1, 0.05, 0.1])
    got = obstacle_ranges(origin, heading, 4, centres, radii, half_side=2.0)
    # Sectors of 90 degrees: ahead, left, behind, right. Ahead the nearer rock; the walls
    # 2 m off straight out. The rock back left (bearing 107 degrees) lies in "left".
    np.testing.assert_allclose(got[0], [0.25, math.hypot(0.3, 1.0) - 0.1, 2.0, 2.0])
    np.testing.assert_allclose(got[1], [0.0, 0.0, 0.0, 0.0])
    walls = obstacle_ranges(origin[1:], heading[1:], 4, np.zeros((1, 0, 2)), radii[:0], 2.0)
    # Looking along +y from (1.5, 0), 0.5 m from the +x wall: right, it lies straight
    # out; ahead and behind, the sectors' edges meet it 45 degrees off; left, the +y
    # wall's nearest point in the sector is nearer than the -x wall 3.5 m off.
    edge = 1 / math.cos(math.pi / 4)
    np.testing.assert_allclose(walls[0], [0.5 * edge, 2.0 * edge, 0.5 * edge, 0.5])
    narrow = obstacle_ranges(origin[:1], heading[:1], 8, np.zeros((1, 0, 2)), radii[:0], 2.0)
    # A sector 45 degrees wide centred 45 degrees off a wall meets it at its edge, 22.5
    # degrees off the perpendicular.
    np.testing.assert_allclose(narrow[0, 1], 2.0 / math.cos(math.radians(22.5)))


def test_range_values_see_a_rock_set_ahead_of_the_brain_and_turn_with_it() -> None:
    task = Reach(observe_range=True, range_sectors=4, range_max=0.5)
    arena = ArenaParams(n_rocks=1, rock_types=(ArenaParams().rock_types[2],))  # a ball, 4 cm
    core = TaskCore(robot(), arena=arena, task=task, num_envs=1, seed=0)
    plain = TaskCore(robot(), arena=arena, num_envs=1, seed=0)
    np.testing.assert_array_equal(core.reset()[:, :-4], plain.reset())  # four values, last
    brain = core.sensordata[0, core.i_origin][:2]
    ahead = core.heading()[0]
    rock = core.joint_address("rock0")
    core.qpos[0, rock:rock + 2] = brain + 0.3 * ahead  # 0.3 m straight ahead
    obs = core.step(np.zeros((1, core.action_size))).observation
    np.testing.assert_allclose(obs[0, -4], (0.3 - 0.04) / 0.5, atol=0.02)
    assert (obs[0, -3:] == 1.0).all()  # the walls are 2 m off: beyond range_max
    core.qpos[0, rock:rock + 2] = brain + 0.2 * np.array([-ahead[1], ahead[0]])  # to its left
    obs = core.step(np.zeros((1, core.action_size))).observation
    np.testing.assert_allclose(obs[0, -3], (0.2 - 0.04) / 0.5, atol=0.02)
    assert obs[0, -4] == 1.0


def test_state_layout_is_time_qpos_qvel() -> None:
    core = TaskCore(robot(), arena=ArenaParams.cluttered(), num_envs=2, seed=1)
    core.reset()
    data = mujoco.MjData(core.model)
    mujoco.mj_setState(core.model, data, core.state[1], mujoco.mjtState.mjSTATE_INTEGRATION)
    np.testing.assert_array_equal(core.qpos[1], data.qpos)
    np.testing.assert_array_equal(core.qvel[1], data.qvel)


def test_observation_reports_direction_and_distance_to_target() -> None:
    core = TaskCore(robot(), num_envs=2, seed=0)
    core.reset()
    obs = core.set_target(0, [0.0, 1.0])  # to the robot's left (brain +y)
    obs = core.set_target(1, [1.0, 0.0])  # straight ahead
    np.testing.assert_allclose(obs[0, 6:8], [0, 1], atol=1e-3)
    np.testing.assert_allclose(obs[1, 6:8], [1, 0], atol=1e-3)
    modules = core.sensordata[1, core.i_modules].reshape(-1, 3)
    expected = np.hypot(1.0 - modules[:, 0], modules[:, 1]).min()
    assert obs[1, 8] == pytest.approx(expected, rel=1e-5)


def test_approach_reward_is_positive_when_closing_in_and_terms_sum_to_reward() -> None:
    core = TaskCore(robot(), num_envs=2, seed=0)
    core.reset()
    for arena in (0, 1):
        core.set_target(arena, [1.2, 0.0])
    action = np.concatenate([forward(core, 1.0)[:1], forward(core, -1.0)[:1]])
    approach = np.zeros(2)
    for _ in range(40):
        step = core.step(action)
        total = sum(step.terms[name] for name in Reach.reward_terms)
        np.testing.assert_allclose(step.reward, total)
        np.testing.assert_allclose(step.terms["time"], -1 / core.task.t_max)
        approach += step.terms["approach"]
    assert approach[0] > 0.01, f"driving at the target earned {approach[0]}"
    assert approach[1] < -0.01, f"driving away earned {approach[1]}"


def test_success_terminates_with_bonus() -> None:
    core = TaskCore(robot(), num_envs=1, seed=0)
    core.reset()
    core.set_target(0, [0.35, 0.0])
    steps = 0
    while steps < 200:
        step = core.step(forward(core))
        steps += 1
        if step.terminated[0]:
            break
    assert step.terminated[0] and step.success[0] and not step.truncated[0], "no success"
    assert step.terms["success"][0] == 1.0
    assert step.observation[0, 8] < core.task.success_radius
    assert step.episode_length[0] == steps


def test_truncation_at_t_max_and_episode_return() -> None:
    core = TaskCore(robot(), task=Reach(t_max=25), num_envs=3, seed=0)
    core.reset()
    rewards = []
    for _ in range(25):
        step = core.step(np.zeros((3, core.action_size)))
        rewards.append(step.reward)
        assert not step.terminated.any()
    assert step.truncated.all() and (step.episode_length == 25).all()
    np.testing.assert_allclose(step.episode_return, np.sum(rewards, axis=0))


def test_same_seed_same_trajectory_different_seed_different_target() -> None:
    def run(seed: int, nthread: int) -> tuple[np.ndarray, np.ndarray]:
        core = TaskCore(
            robot("inchworm"), arena=ArenaParams.cluttered(), num_envs=4, nthread=nthread,
            seed=seed,
        )
        core.reset()
        rng = np.random.default_rng(7)
        for _ in range(30):
            step = core.step(rng.uniform(-1, 1, (4, core.action_size)))
        return core.target.copy(), np.concatenate([step.observation, core.state], axis=1)

    target_a, final_a = run(3, 1)
    target_b, final_b = run(3, 2)
    target_c, _ = run(4, 1)
    np.testing.assert_array_equal(target_a, target_b)
    np.testing.assert_array_equal(final_a, final_b)  # threads do not change the physics
    assert not np.allclose(target_a, target_c)


def test_arenas_given_the_compiled_scene_run_as_arenas_that_compile_their_own() -> None:
    arena, task = ArenaParams.cluttered(), Reach()
    scene = compile_scene(robot("inchworm"), PhysicsParams(), arena, task)

    def run(given: Scene | None) -> np.ndarray:
        core = TaskCore(robot("inchworm"), arena=arena, num_envs=2, seed=5, scene=given)
        core.reset()
        rng = np.random.default_rng(7)
        for _ in range(20):
            step = core.step(rng.uniform(-1, 1, (2, core.action_size)))
        return np.concatenate([step.observation, core.state], axis=1)

    first, again = run(scene), run(scene)  # two users of one model, one after the other
    np.testing.assert_array_equal(first, run(None))
    np.testing.assert_array_equal(again, first)
    assert TaskCore(robot("inchworm"), arena=arena, scene=scene).model is scene.model
    with pytest.raises(ValueError, match="scene: compiled for another robot"):
        TaskCore(robot("snake"), arena=arena, scene=scene)


def test_targets_fill_the_annulus() -> None:
    core = TaskCore(robot(), num_envs=200, seed=0)
    core.reset()
    r = np.hypot(core.target[:, 0], core.target[:, 1])
    assert r.min() >= 0.5 and r.max() <= 1.5
    assert r.min() < 0.6 and r.max() > 1.4
    angles = np.arctan2(core.target[:, 1], core.target[:, 0])
    assert np.histogram(angles, bins=4, range=(-math.pi, math.pi))[0].min() > 25


def test_rocks_lie_around_the_target_clear_of_the_start_and_move_when_pushed() -> None:
    arena = ArenaParams.cluttered()
    core = TaskCore(robot(), arena=arena, num_envs=6, seed=2)
    core.reset()
    rock_xyz = core.qpos[:, core.rock_qpos[:, None] + np.arange(3)]  # (N, rocks, 3)
    to_target = np.linalg.norm(rock_xyz[..., :2] - core.target[:, None, :2], axis=2)
    assert to_target.max() <= arena.rock_spread + 1e-9
    assert to_target.min() >= arena.target_clearance
    assert np.linalg.norm(rock_xyz[..., :2], axis=2).min() >= arena.start_clearance
    assert len({tuple(np.round(t, 6)) for t in core.target}) == 6

    # Drive straight at a target beyond a rock field: rocks in the way get pushed.
    core.set_target(0, [1.0, 0.0])
    core.qpos[0, core.rock_qpos[0] + np.arange(3)] = [0.45, 0.0, arena.rocks[0].half_height]
    before = core.qpos[0, core.rock_qpos[0] + np.arange(2)].copy()
    for _ in range(60):
        core.step(forward(core))
    moved = np.linalg.norm(core.qpos[0, core.rock_qpos[0] + np.arange(2)] - before)
    assert moved > 0.02, f"the rock in the robot's path moved only {moved:.4f} m"


def test_injected_nan_ends_only_that_arena_flagged() -> None:
    env = TaskEnv(TaskCore(robot(), num_envs=4, seed=0))
    td = env.reset()
    env.core.qvel[2, 0] = np.nan
    td["action"] = torch.zeros(4, env.core.action_size)
    td = env.step(td)["next"]
    assert td["unstable"].squeeze(-1).tolist() == [False, False, True, False]
    assert td["truncated"].squeeze(-1).tolist() == [False, False, True, False]
    assert torch.isfinite(td["observation"]).all()
    assert env.core.unstable_count == 1
    td["_reset"] = td["done"].clone()
    td = env.reset(td)
    assert np.isfinite(env.core.state).all()
    assert env.core.steps.tolist() == [1, 1, 0, 1]


def test_a_thrown_robot_ends_unstable_and_earns_only_the_time_penalty() -> None:
    """A contact blow-up can stay finite and throw the robot: up past ``max_height`` or
    out over the walls, where the approach term would pay for the distance. Either ends
    that arena's episode as unstable; driving about never does."""
    core = TaskCore(robot(), num_envs=4, seed=0)
    core.reset()
    for _ in range(40):
        assert not core.step(forward(core)).unstable.any()
    brain = core.model.body("brain").jntadr[0]
    qpos, qvel = core.model.jnt_qposadr[brain], core.model.jnt_dofadr[brain]
    core.qvel[1, qvel + 2] = 40.0  # flung upwards: ~2 m within one control step
    core.qpos[2, qpos] = core.arena.side / 2 + 1.0  # out over the wall
    step = core.step(forward(core))
    assert step.unstable.tolist() == [False, True, True, False]
    assert step.truncated.tolist() == [False, True, True, False]
    assert step.terms["approach"][1:3].tolist() == [0.0, 0.0]
    assert np.allclose(step.reward[1:3], -1 / core.task.t_max)


def test_traced_episodes_are_numbered_and_a_blown_up_one_is_flagged_and_not_recorded(
    tmp_path: Path,
) -> None:
    """The tracer numbers arena 0's episodes and marks the one a NaN ended ``unstable``;
    the evaluation's sampler counts it but records only the stable ones."""
    from evo.evaluation import EpisodeSampler
    from evo.record import McapRecorder, RecordConfig, read_episodes

    core = TaskCore(robot(), task=Reach(t_max=6), num_envs=2, seed=0)
    seen: list[Episode] = []
    core.watch(seen.append)
    zero = np.zeros((2, core.action_size))
    core.reset()
    for _ in range(3):
        core.step(zero)
    core.qvel[0, 0] = np.nan
    assert core.step(zero).unstable.tolist() == [True, False]
    core.reset(np.array([True, False]))
    for _ in range(6):
        core.step(zero)
    assert [(e.index, e.unstable) for e in seen] == [(0, True), (1, False)]
    assert seen[0].frames == 5 and seen[1].frames == 7
    assert np.all(np.diff(seen[1].time) > 0) and seen[1].env_step == core.steps_taken
    everything = RecordConfig(episodes=EpisodeChoice(first=True, last=True, every=1))
    with McapRecorder(tmp_path / "e.mcap", core.model, {}) as recorder:
        sampler = EpisodeSampler(recorder, everything)
        for episode in seen:
            sampler(episode)
        sampler.finish()
    assert sampler.count == 2
    assert [e.index for e in read_episodes(tmp_path / "e.mcap")] == [1]


def test_partial_reset_touches_only_masked_arenas() -> None:
    env = TaskEnv(TaskCore(robot(), num_envs=3, seed=0))
    td = env.reset()
    td["action"] = torch.zeros(3, env.core.action_size)
    for _ in range(5):
        td = env.step(td)["next"]
        td["action"] = torch.zeros(3, env.core.action_size)
    targets, steps = env.core.target.copy(), env.core.steps.copy()
    td["_reset"] = torch.tensor([[False], [True], [False]])
    env.reset(td)
    assert (env.core.steps == [steps[0], 0, steps[2]]).all()
    np.testing.assert_array_equal(env.core.target[[0, 2]], targets[[0, 2]])
    assert not np.array_equal(env.core.target[1], targets[1])


@pytest.mark.parametrize("arena", ["clean", "cluttered"])
def test_torchrl_env_passes_check_env_specs(arena: str) -> None:
    env = TaskEnv(TaskCore(robot("snake"), arena=getattr(ArenaParams, arena)(), num_envs=5,
                               seed=0))
    check_env_specs(env, seed=0)
    rollout = env.rollout(12, break_when_any_done=False)
    assert rollout.batch_size == torch.Size([5, 12])
    terms = sum(rollout["next", "reward_terms", name] for name in Reach.reward_terms)
    torch.testing.assert_close(terms, rollout["next", "reward"])


def test_gymnasium_env_registered_and_passes_check_env() -> None:
    assert evo.envs.ENV_ID == "evo/Reach-v0"
    env = gym.make("evo/Reach-v0", robot="robots/four_wheeler.json", arena="cluttered")
    check_env(env.unwrapped, skip_render_check=True)
    obs, _ = env.reset(seed=5)
    assert obs.shape == (15,) and env.action_space.shape == (3,)
    obs2, _ = env.reset(seed=5)
    np.testing.assert_array_equal(obs, obs2)
    _, reward, terminated, truncated, info = env.step(env.action_space.sample())
    assert reward == pytest.approx(sum(info[f"reward/{t}"] for t in Reach.reward_terms))
    assert not (terminated or truncated)


def test_gymnasium_and_torchrl_faces_agree() -> None:
    env = gym.make("evo/Reach-v0", robot=robot("inchworm")).unwrapped
    batched = TaskEnv(TaskCore(robot("inchworm"), num_envs=1, seed=11))
    obs, _ = env.reset(seed=11)
    td = batched.reset()
    np.testing.assert_array_equal(obs, td["observation"][0].numpy())
    rng = np.random.default_rng(0)
    for _ in range(10):
        action = rng.uniform(-1, 1, env.action_space.shape).astype(np.float32)
        obs, reward, *_ = env.step(action)
        td["action"] = torch.from_numpy(action)[None]
        td = batched.step(td)["next"]
        np.testing.assert_array_equal(obs, td["observation"][0].numpy())
        assert reward == pytest.approx(float(td["reward"][0]), rel=1e-6)


def test_bad_arena_name_is_named() -> None:
    with pytest.raises(ValueError, match="arena must be one of"):
        gym.make("evo/Reach-v0", robot="robots/four_wheeler.json", arena="muddy")


def drive_through_rocks(sleep: bool, name: str = "four_wheeler", n: int = 16,
                        steps: int = 200) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A fixed action sequence (full speed, pivots swinging) into each arena's rock field,
    moved so that its target lies 1 m ahead. Returns the brain's path (steps, n, 2), the
    rocks' displacements at the end (n, rocks) and, per step, whether any rock has moved
    sideways by more than 10 µm yet (steps, n): the robot has touched one."""
    arena = dataclasses.replace(ArenaParams.cluttered(), sleep=sleep)
    core = TaskCore(robot(name), arena=arena, num_envs=n, seed=5)
    core.reset()
    xy = core.rock_qpos[:, None] + np.arange(2)
    core.qpos[:, xy] += (np.array([1.0, 0.0]) - core.target[:, :2])[:, None, :]
    start = core.qpos[:, xy].copy()
    m = len(core.built.motors)
    path, disturbed = [], []
    for t in range(steps):
        action = np.zeros((n, core.action_size))
        action[:, :m], action[:, m:] = 1.0, 0.5 * math.sin(t / 8.0)
        core.step(action)
        path.append(core.sensordata[:, core.i_origin][:, :2].copy())
        disturbed.append((np.linalg.norm(core.qpos[:, xy] - start, axis=-1) > 1e-5).any(axis=1))
    return np.array(path), np.linalg.norm(core.qpos[:, xy] - start, axis=-1), np.array(disturbed)


def test_sleeping_rocks_change_what_the_robot_meets_within_tolerance() -> None:
    """Sleep against the physics without it, for a robot ploughing through rock fields.

    Tolerance (stated): until the first rock moves, the robot's path is the same to a
    nanometre (sleeping rocks change nothing in free space but the solver's rounding);
    after it, contact dynamics are
    chaotic (a nanometre-per-second nudge of the robot alone already changes some paths
    by decimetres), so what must hold is the aggregate over 16 arenas: the robot's
    travel, the rocks moved by more than 1 cm and their total displacement, each
    within 15 % of the physics without sleep.
    """
    path_a, moved_a, disturbed_a = drive_through_rocks(sleep=False)
    path_b, moved_b, _ = drive_through_rocks(sleep=True)
    first = disturbed_a.argmax(axis=0)  # the step each arena's first rock moved
    assert disturbed_a.any(axis=0).all(), "every arena's robot reaches the rocks"
    for arena, t in enumerate(first):
        np.testing.assert_allclose(path_a[:t, arena], path_b[:t, arena], rtol=0, atol=1e-9)
    travel = [np.linalg.norm(p[-1] - p[0], axis=-1).sum() for p in (path_a, path_b)]
    assert travel[1] == pytest.approx(travel[0], rel=0.15), travel
    assert (moved_b > 0.01).sum() == pytest.approx((moved_a > 0.01).sum(), rel=0.15)
    assert moved_b.sum() == pytest.approx(moved_a.sum(), rel=0.15), (moved_a.sum(), moved_b.sum())
    assert (moved_a > 0.01).sum() >= 40, "the robots push plenty of rocks"


def test_settled_rocks_sleep_and_leave_only_the_robots_contacts() -> None:
    core = TaskCore(robot(), arena=ArenaParams.cluttered(), num_envs=8, seed=0)
    clean = TaskCore(robot(), num_envs=8, seed=0)
    core.reset()
    clean.reset()
    for _ in range(10):
        core.step(np.zeros((8, core.action_size)))
        clean.step(np.zeros((8, clean.action_size)))
    asleep = [np.asarray(core.batch.get_data(i).tree_asleep) >= 0 for i in range(8)]
    assert all(a.sum() == core.arena.n_rocks for a in asleep), "every rock asleep, robot awake"
    np.testing.assert_array_equal(core.batch.bind("ncon"), clean.batch.bind("ncon"))
