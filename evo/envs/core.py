"""The batched core every task runs on: a batch of arenas of one robot, in numpy.

``TaskCore`` holds ``N`` arenas of the same robot that advance together: one call of a
persistent ``mujoco.batch.Batch`` (one ``MjData`` per arena, kept between calls) steps
every arena ``frame_skip`` physics steps in C on ``nthread`` threads, then the task's
rules (``evo.envs.tasks``) compute observations, rewards, success and termination for
all arenas at once with numpy. The TorchRL ``TaskEnv`` and the gymnasium
``TaskGymEnv`` are thin faces over it. Every control step starts the constraint solver
cold (zero warm start), as a stateless rollout from the saved physics state would; the
arenas' data persist so that resting rocks can sleep (``ArenaParams.sleep``). The
observation's layout and sizes are ``evo.envs.params``, the scene's MJCF
``evo.envs.scene``.

Observation (``9 + 2(m + n)`` values, then the task's ``extra_slots``, then ``+3`` with
``observe_up``, ``+1`` with ``observe_stall``, ``+1`` with ``observe_stall_count``,
``+range_sectors`` with ``observe_range`` and ``+2`` with ``observe_clock``), in this order:

======================  ====  =========================================================
brain linear velocity    3    m/s, in the brain frame
brain angular velocity   3    rad/s, in the brain frame
the task's values        3    reach: direction to the target (2), distance to it (1)
per motor                2    wheel speed / motor_max_speed, last command (both in [-1, 1])
per pivot                2    hinge angle / pivot_range, last command (both in [-1, 1])
the task's extra values  k    ``Task.extra_slots`` (none for reach)
gravity (observe_up)     3    unit vector of gravity in the brain frame
stall (observe_stall)    1    time since the brain last moved ``stall_radius``, over
                              ``stall_seconds``, capped at 1 (0 after a reset)
stall count              1    times this episode it stood still for ``stall_seconds``,
(observe_stall_count)         over 4, capped at 1
obstacle ranges          K    per sector around the brain (K = ``range_sectors``,
(observe_range)               counter-clockwise from the heading), the distance to the
                              nearest rock or wall in it, over ``range_max``, capped at 1
clock (observe_clock)    2    sine and cosine of 2 pi t / ``clock_period``, t the
                              episode's simulated time, s (0 after a reset)
======================  ====  =========================================================

Motors come first, then pivots, each in depth-first tree order (``BuiltRobot.actuators``,
``Robot.actuator_paths``); ``evo.envs.params`` names the layout's parts (``GLOBAL_SLOTS``,
``ACTUATOR_SLOTS``, ``UP_SLOTS``) and maps it between two bodies (``observation_origins``).

The reward of a step is the sum of the task's named terms (``Task.reward_terms``). An
episode ends when the task terminates it or is truncated after ``t_max`` control steps.
A numerical blow-up (non-finite state, MuJoCo resetting the arena after a bad
acceleration, which shows as time jumping back, or the robot thrown: a module above
``task.max_height`` or beyond the walls) ends only that arena's episode: it is
truncated, flagged ``unstable``, its observation is held at the last good one and its
step earns no task term but those the task pays regardless (reach's time penalty).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass

import mujoco
import mujoco.batch
import numpy as np
import numpy.typing as npt

from evo.envs.arena import ArenaParams, obstacle_ranges, scatter_rocks
from evo.envs.params import observation_size
from evo.envs.scene import Scene, compile_scene
from evo.envs.tasks.base import Task
from evo.envs.tasks.reach import Reach
from evo.episode import Episode
from evo.robot.builder import PhysicsParams
from evo.robot.tree import Robot

F64 = npt.NDArray[np.float64]
Bools = npt.NDArray[np.bool_]
@dataclass(frozen=True, slots=True)
class Step:
    """What one control step returns for every arena (arrays over arenas)."""

    observation: npt.NDArray[np.float32]
    reward: F64
    terms: dict[str, F64]
    terminated: Bools
    truncated: Bools
    success: Bools
    unstable: Bools
    episode_return: F64
    episode_length: npt.NDArray[np.int64]


class _Tracer:
    """Frames of the watched arena's running episode; ``count`` episodes ended so far."""

    def __init__(self, core: TaskCore, callback: Callable[[Episode], None]) -> None:
        self.core, self.callback = core, callback
        self.frames: list[tuple[float, F64, F64, F64, dict[str, float]]] = []
        self.count = 0

    def frame(self, terms: dict[str, float]) -> None:
        xpos, xquat = self.core.poses(0)
        self.frames.append((float(self.core.time[0]), xpos, xquat, self.core.qpos[0].copy(),
                            terms))

    def finish(self, success: bool, unstable: bool) -> None:
        if not self.frames:
            return
        time, xpos, xquat, qpos, terms = zip(*self.frames, strict=True)
        self.frames = []
        index, self.count = self.count, self.count + 1
        self.callback(
            Episode(
                index=index,
                env_step=int(self.core.steps_taken),
                time=np.array(time),
                xpos=np.stack(xpos),
                xquat=np.stack(xquat),
                target=self.core.target[0].copy(),
                rewards={k: np.array([t[k] for t in terms]) for k in self.core.task.reward_terms},
                success=success,
                qpos=np.stack(qpos),
                unstable=unstable,
            )
        )


class TaskCore:
    """``num_envs`` arenas of one robot, stepped together under one task.

    Args:
        robot: The robot structure.
        physics: Module constants.
        arena: The arena (clean or cluttered).
        task: The task (reach when None).
        num_envs: Number of arenas N.
        nthread: Threads MuJoCo's rollout uses for the N arenas.
        seed: Seed of the arenas' random episodes (the task's draws and the rocks).
        scene: The scene of ``robot`` under these settings, compiled by the caller (an
            evaluation compiles it once for all its users); compiled here when None.
    """

    def __init__(
        self,
        robot: Robot,
        physics: PhysicsParams | None = None,
        arena: ArenaParams | None = None,
        task: Task | None = None,
        num_envs: int = 1,
        nthread: int = 1,
        seed: int | None = None,
        scene: Scene | None = None,
    ) -> None:
        if num_envs < 1 or nthread < 1:
            raise ValueError(f"num_envs and nthread must be >= 1, got {num_envs}, {nthread}")
        self.robot = robot
        self.physics = physics or PhysicsParams()
        self.arena = arena or ArenaParams()
        self.task: Task = task or Reach()
        if scene is None:
            scene = compile_scene(robot, self.physics, self.arena, self.task)
        elif not scene.of(robot, self.physics, self.arena, self.task):
            raise ValueError("scene: compiled for another robot or other settings")
        self.built, self.model = scene.built, scene.model
        self.num_envs, self.nthread = num_envs, nthread
        self.rng = np.random.default_rng(seed)
        self._index_model()
        self._allocate()
        self.rules = self.task.rules(self)
        self.unstable_count = 0
        self.warning_count = 0
        self.physics_seconds = 0.0
        self.steps_taken = 0  # env steps over all arenas since construction
        self._tracer: _Tracer | None = None

    # ---- set-up -------------------------------------------------------------------------
    def _index_model(self) -> None:
        m, built = self.model, self.built

        def sensor(name: str) -> npt.NDArray[np.intp]:
            s = m.sensor(name)
            return np.arange(s.adr[0], s.adr[0] + s.dim[0])

        self.i_linvel, self.i_angvel = sensor("brain_linvel"), sensor("brain_angvel")
        self.i_origin = sensor("brain_origin")
        self.i_xaxis, self.i_zaxis = sensor("brain_xaxis"), sensor("brain_zaxis")
        self.i_modules = np.concatenate([sensor(f"{b}_pos") for b in built.bodies])
        self.i_speed = np.array([sensor(f"{a}_speed")[0] for a in built.motors], dtype=np.intp)
        self.i_angle = np.array([sensor(f"{a}_angle")[0] for a in built.pivots], dtype=np.intp)
        self.n_modules = len(built.bodies)
        self.pivot_limit = math.radians(self.physics.pivot_range)
        self.ctrl_scale = np.array(
            [self.physics.motor_max_speed] * len(built.motors)
            + [self.pivot_limit] * len(built.pivots)
        )
        self.rock_qpos = np.array(
            [m.jnt_qposadr[m.joint(f"rock{i}").id] for i in range(self.arena.n_rocks)],
            dtype=np.intp,
        )
        self.target_mocap = self.mocap_index("target")
        self.rock_radii = np.array([rock.radius for rock in self.arena.rocks])

    def _allocate(self) -> None:
        n, m = self.num_envs, self.model
        self.scratch = mujoco.MjData(m)
        self.batch = mujoco.batch.Batch(m, nsim=n, nthread=self.nthread, persistent=True)
        b = self.batch
        # Live views of the arenas' state (writes take effect at the next step) ...
        self.time, self.qpos, self.qvel = b.bind("time"), b.bind("qpos"), b.bind("qvel")
        self.ctrl, self._warmstart = b.bind("ctrl"), b.bind("qacc_warmstart")
        self._loaded = {f: b.bind(f) for f in ("act", "mocap_pos", "mocap_quat")}
        # ... and outputs refreshed by every step (sensors of the state before the last
        # physics step, as mj_step leaves them).
        self._sensor_out = b.bind("sensordata")
        self.warnings_seen = 0
        self._diverged_seen = np.zeros(n, dtype=np.int64)  # per arena, see _diverged()
        self.sensordata = np.zeros((n, m.nsensordata))
        self.target = np.zeros((n, 3))
        self.action = np.zeros((n, m.nu))
        self.steps = np.zeros(n, dtype=np.int64)
        self.still = np.zeros(n, dtype=np.int64)  # control steps since the brain last moved
        self.still_from = np.zeros((n, 2))  # where it was then (x, y)
        self.stalls = np.zeros(n, dtype=np.int64)  # times this episode still that long
        self.returns = np.zeros(n)
        self.observation = np.zeros((n, self.obs_size), dtype=np.float32)

    # ---- sizes ---------------------------------------------------------------------------
    @property
    def control_step(self) -> float:
        """Seconds of simulated time per control step: the physics timestep times
        ``task.frame_skip`` (0.005 s x 10 = 0.05 s by default)."""
        return float(self.model.opt.timestep * self.task.frame_skip)

    @property
    def _stall_steps(self) -> int:
        """Control steps of standing still that make a stall (``task.stall_seconds``)."""
        return max(1, math.ceil(self.task.stall_seconds / self.control_step - 1e-9))

    @property
    def obs_size(self) -> int:
        """Length of one observation."""
        return observation_size(self.robot, self.task)

    @property
    def action_size(self) -> int:
        """Length of one action, m + n."""
        return int(self.model.nu)

    @property
    def state(self) -> F64:
        """Every arena's integration state, (N, nstate): time, qpos, qvel, ... as
        ``mjSTATE_INTEGRATION`` lays them out (``qpos``, ``qvel``, ``time`` are views)."""
        state: F64 = self.batch.state
        return state

    def watch(self, callback: Callable[[Episode], None] | None) -> None:
        """Trace every episode of arena 0 from its next reset; ``callback`` receives each
        one when it ends, numbered from 0 (None stops tracing). Costs one forward
        kinematics per step."""
        self._tracer = None if callback is None else _Tracer(self, callback)

    def seed(self, seed: int | None) -> None:
        """Re-seed the random targets and rocks."""
        self.rng = np.random.default_rng(seed)

    # ---- episodes ------------------------------------------------------------------------
    def reset(self, mask: Bools | None = None) -> npt.NDArray[np.float32]:
        """Start new episodes in the arenas where ``mask`` is true (all when None).

        Returns:
            The observation of every arena (new episodes and running ones).
        """
        chosen = np.arange(self.num_envs) if mask is None else np.flatnonzero(mask)
        m, d = self.model, self.scratch
        if len(chosen):  # a fresh MjData for each: awake, no history
            self.batch.reset(chosen, stage=mujoco.mjtStage.mjSTAGE_NONE)
        for i in chosen:
            mujoco.mj_resetData(m, d)
            target = self.rules.draw(int(i), self.rng, d)
            if self.arena.n_rocks:
                pos, quat = scatter_rocks(self.arena, target, self.rng)
                d.qpos[self.rock_qpos[:, None] + np.arange(3)] = pos
                d.qpos[self.rock_qpos[:, None] + np.arange(3, 7)] = quat
            d.mocap_pos[self.target_mocap] = target
            mujoco.mj_forward(m, d)
            self.time[i], self.qpos[i], self.qvel[i] = d.time, d.qpos, d.qvel
            for field, view in self._loaded.items():
                view[i] = getattr(d, field).reshape(view[i].shape)
            self.sensordata[i] = d.sensordata
            self.target[i] = target
        self.action[chosen] = 0.0
        self.steps[chosen] = 0
        self.still[chosen] = 0
        self.stalls[chosen] = 0
        self.still_from[chosen] = self.sensordata[chosen][:, self.i_origin][:, :2]
        self.returns[chosen] = 0.0
        self.rules.start(chosen)
        self.observation[chosen] = self._observe()[chosen]
        if self._tracer is not None and (mask is None or mask[0]):
            self._tracer.frames = []
            self._tracer.frame(dict.fromkeys(self.task.reward_terms, 0.0))
        return self.observation.copy()

    def set_target(self, arena: int, position: npt.ArrayLike) -> npt.NDArray[np.float32]:
        """Move ``arena``'s marker (reach's target; x, y in m) for the rest of its
        episode (rocks stay); the task measures that arena's progress afresh from here.

        Returns:
            The observation of every arena.
        """
        self.target[arena, :2] = np.asarray(position, dtype=np.float64)[:2]
        self.rules.start(np.array([arena], dtype=np.intp))
        self.observation[arena] = self._observe()[arena]
        return self.observation.copy()

    def step(self, action: npt.ArrayLike) -> Step:
        """Advance every arena one control step with ``action`` of shape (N, m + n).

        Raises:
            ValueError: When ``action`` does not hold N × (m + n) values.
        """
        act = np.asarray(action, dtype=np.float64)
        if act.size != self.num_envs * self.action_size:
            raise ValueError(f"action: expected {self.num_envs} x {self.action_size} values "
                             f"(arenas x actuators), got shape {act.shape}")
        act = np.clip(act.reshape(self.num_envs, self.action_size), -1, 1)
        unstable = self._simulate(act)
        self.action[:] = act
        if self.task.observe_stall or self.task.observe_stall_count:
            self._track_stall()
        observation = self._observe()
        stable = ~unstable
        self.observation[stable] = observation[stable]
        terms, success, terminated = self.rules.step(stable, self.steps + 1 >= self.task.t_max)
        first, *rest = self.task.reward_terms
        reward = np.array(terms[first], dtype=np.float64)
        for name in rest:  # summed in the task's order
            reward = reward + terms[name]
        self.steps += 1
        self.steps_taken += self.num_envs
        self.returns += reward
        self.unstable_count += int(unstable.sum())
        truncated = unstable | (self.steps >= self.task.t_max)
        if self._tracer is not None and self._tracer.frames:
            self._tracer.frame({name: float(terms[name][0]) for name in self.task.reward_terms})
            if terminated[0] or truncated[0]:
                self._tracer.finish(bool(success[0]), bool(unstable[0]))
        return Step(
            observation=self.observation.copy(),
            reward=reward,
            terms=terms,
            terminated=terminated,
            truncated=truncated,
            success=success,
            unstable=unstable,
            episode_return=self.returns.copy(),
            episode_length=self.steps.copy(),
        )

    # ---- internals -----------------------------------------------------------------------
    def _simulate(self, act: npt.NDArray[np.float64]) -> Bools:
        """Apply ``act`` and run ``frame_skip`` physics steps in every arena; returns
        which arenas went unstable (MuJoCo gave up, non-finite state, a lost step or a
        divergence warning)."""
        self.ctrl[:] = act * self.ctrl_scale
        self._warmstart[:] = 0.0  # a cold solver start, as from a saved state
        before = self.time.copy()
        failed = np.zeros(self.num_envs, dtype=bool)
        tick = time.perf_counter()
        try:
            self.batch.step(nstep=self.task.frame_skip)
        except mujoco.batch.SimulationError as err:  # MuJoCo gave up on those arenas
            failed[np.asarray(err.ids, dtype=np.intp)] = True
        self.physics_seconds += time.perf_counter() - tick
        self._count_warnings()
        dt = self.control_step
        self.sensordata[:] = self._sensor_out
        unstable: Bools = failed | ~np.isfinite(self.qpos).all(axis=1) | ~np.isfinite(
            self.qvel).all(axis=1) | ~np.isfinite(self.sensordata).all(axis=1)
        unstable |= np.abs(self.time - before - dt) > 0.5 * self.model.opt.timestep
        unstable |= self._diverged() | self._thrown()
        return unstable

    def _thrown(self) -> Bools:
        """Arenas whose robot the physics threw: a module centre above
        ``task.max_height`` or beyond the walls' centre lines. Driving does not get
        there (the walls stand twice a module's height); a contact blow-up that stays
        finite does, and outside the arena the approach term would pay for the distance."""
        modules = self.module_positions()
        outside = (np.abs(modules[:, :, :2]) > self.arena.side / 2).any(axis=(1, 2))
        high = (modules[:, :, 2] > self.task.max_height).any(axis=1)
        return np.asarray(outside | high, dtype=np.bool_)

    def mocap_index(self, name: str) -> int:
        """The index of mocap body ``name`` in ``MjData.mocap_pos``."""
        return int(self.model.body_mocapid[self.model.body(name).id])

    def joint_address(self, name: str) -> int:
        """Where joint ``name``'s values start in a ``qpos`` row."""
        return int(self.model.jnt_qposadr[self.model.joint(name).id])

    def module_positions(self) -> F64:
        """World position of every module in every arena, (N, modules, 3), from the
        current sensors."""
        modules: F64 = self.sensordata[:, self.i_modules].reshape(
            self.num_envs, self.n_modules, 3)
        return modules

    def _diverged(self) -> Bools:
        """Arenas whose state MuJoCo found bad (NaN, Inf or huge qpos, qvel or qacc) and
        reset during the last step: it carries on from the reset state, which only its
        warning counters tell."""
        bad = [mujoco.mjtWarning.mjWARN_BADQPOS, mujoco.mjtWarning.mjWARN_BADQVEL,
               mujoco.mjtWarning.mjWARN_BADQACC]
        counts = self.batch.warning[:, [int(w) for w in bad], 1].sum(axis=1)
        diverged: Bools = counts > self._diverged_seen
        self._diverged_seen = counts.astype(np.int64)
        return diverged

    def _count_warnings(self) -> None:
        """Tally MuJoCo warnings raised in any arena since the last step."""
        seen = int(self.batch.warning[..., 1].sum())
        self.warning_count += max(0, seen - self.warnings_seen)
        self.warnings_seen = seen

    def in_brain_frame(self, vectors: F64) -> F64:
        """Horizontal world vectors (N, 2) of every arena in its brain's horizontal frame
        (x = the brain's heading, y = its left)."""
        heading = self.heading()
        return np.stack(
            [
                (heading * vectors).sum(axis=1),
                heading[:, 0] * vectors[:, 1] - heading[:, 1] * vectors[:, 0],
            ],
            axis=1,
        )

    def heading(self) -> F64:
        """Every arena's brain heading, its x axis on the floor, as a unit vector (N, 2)
        (the world's x when the brain points straight up or down)."""
        heading = self.sensordata[:, self.i_xaxis][:, :2]
        norm = np.linalg.norm(heading, axis=1, keepdims=True)
        unit: F64 = np.where(norm > 1e-6, heading / np.maximum(norm, 1e-12), [1.0, 0.0])
        return unit

    def obstacle_ranges(self) -> F64:
        """For each arena, how far the nearest rock or wall is in each of
        ``task.range_sectors`` equal sectors around the brain (counter-clockwise from
        its heading), (N, K) m."""
        h = self.heading()
        rocks = self.qpos[:, self.rock_qpos[:, None] + np.arange(2)]  # (N, R, 2)
        return obstacle_ranges(self.sensordata[:, self.i_origin][:, :2],
                               np.arctan2(h[:, 1], h[:, 0]), self.task.range_sectors, rocks,
                               self.rock_radii, self.arena.side / 2)

    def direction_to(self, points: F64) -> F64:
        """The unit direction from every arena's brain to its point of ``points`` (N, 2+),
        in the brain's horizontal frame."""
        towards = points[:, :2] - self.sensordata[:, self.i_origin][:, :2]
        towards /= np.maximum(np.linalg.norm(towards, axis=1, keepdims=True), 1e-9)
        return self.in_brain_frame(towards)

    def _track_stall(self) -> None:
        """Count the control steps since each brain last moved ``task.stall_radius``
        (horizontally) from where it was then, and the times this episode that count
        reached ``task.stall_seconds``."""
        here = self.sensordata[:, self.i_origin][:, :2]
        moved = np.linalg.norm(here - self.still_from, axis=1) > self.task.stall_radius
        self.still_from[moved] = here[moved]
        self.still = np.where(moved, 0, self.still + 1)
        self.stalls += self.still == self._stall_steps

    def _observe(self) -> npt.NDArray[np.float32]:
        """The observation of every arena from the current sensors (and the task's
        measures, which its rules keep)."""
        s, n = self.sensordata, self.num_envs
        task_values, extra = self.rules.observe()
        n_motors = len(self.i_speed)
        motors = np.stack(
            [s[:, self.i_speed] / self.physics.motor_max_speed, self.action[:, :n_motors]], axis=2
        ).reshape(n, -1)
        pivots = np.stack(
            [s[:, self.i_angle] / self.pivot_limit, self.action[:, n_motors:]], axis=2
        ).reshape(n, -1)
        parts = [s[:, self.i_linvel], s[:, self.i_angvel], task_values, motors, pivots, extra]
        if self.task.observe_up:
            x, z = s[:, self.i_xaxis], s[:, self.i_zaxis]
            y = np.cross(z, x)
            parts.append(-np.stack([x[:, 2], y[:, 2], z[:, 2]], axis=1))
        if self.task.observe_stall:
            seconds = self.still * self.control_step / self.task.stall_seconds
            parts.append(np.minimum(seconds, 1.0)[:, None])
        if self.task.observe_stall_count:
            parts.append(np.minimum(self.stalls / 4, 1.0)[:, None])
        if self.task.observe_range:
            parts.append(np.minimum(self.obstacle_ranges() / self.task.range_max, 1.0))
        if self.task.observe_clock:
            phase = 2 * np.pi * self.time / self.task.clock_period
            parts.append(np.stack([np.sin(phase), np.cos(phase)], axis=1))
        return np.concatenate(parts, axis=1).astype(np.float32)

    def poses(self, arena: int) -> tuple[F64, F64]:
        """World positions (nbody, 3) and quaternions (nbody, 4; w, x, y, z) of every body
        in ``arena``'s current state, target marker included (for recording and replay)."""
        m, d = self.model, self.scratch
        d.qpos[:] = self.qpos[arena]
        d.mocap_pos[:] = self._loaded["mocap_pos"][arena].reshape(d.mocap_pos.shape)
        d.mocap_quat[:] = self._loaded["mocap_quat"][arena].reshape(d.mocap_quat.shape)
        d.mocap_pos[self.target_mocap] = self.target[arena]
        mujoco.mj_kinematics(m, d)
        return d.xpos.copy(), d.xquat.copy()
