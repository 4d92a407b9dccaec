"""Replay saved robots: ``python -m evo.replay``.

* ``python -m evo.replay RUN_DIR ROBOT_NAME [--episodes K] [--seed S] [--video out.mp4]
  [--rrd out.rrd] [--size 640x480] [--fps 20] [--seconds S]``: reload the robot's trained
  policy, re-simulate K deterministic episodes and write a video (MuJoCo offscreen
  rendering, ``MUJOCO_GL=egl``; ``.mp4``, ``.webm`` or ``.gif``, of the first S simulated
  seconds at most) and/or a rerun recording. The same seed gives the same episodes as the
  recording made after training (its seed is in the evaluation's metadata). A short small
  clip for a web page: ``--video clip.webm --size 320x240 --fps 10 --seconds 10``.
* ``python -m evo.replay --gallery RUN_DIR [--top N] [--out robots.png]``: a picture of
  the run's best robots.

RUN_DIR is a run directory of ``task=evolve`` (robots/<name>.json, evals/<name>.pt) or
of ``task=train`` (robot.json, policy.pt; ROBOT_NAME may then be omitted).
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np
import numpy.typing as npt

from evo.checks import at_least, positive
from evo.config import ConfigError
from evo.edge import run_config
from evo.envs.params import EnvConfig, observation_size
from evo.episode import Episode
from evo.learners.common import load_checkpoint
from evo.learners.rollouts import play
from evo.robot.builder import PhysicsParams
from evo.robot.io import RobotFileError, load_robot
from evo.robot.render import RenderError, make_renderer
from evo.robot.tree import Robot
from evo.robot.validate import InvalidRobotError
from evo.run.layout import RunLayout, TrainLayout
from evo.run.records import read_history


def _run_config(run_dir: Path) -> tuple[PhysicsParams, EnvConfig]:
    config = run_config(run_dir)
    return config.physics, config.env


def _files(run_dir: Path, name: str | None) -> tuple[Robot, Path]:
    """The robot and its policy checkpoint, in either run-directory layout."""
    run, train = RunLayout(run_dir), TrainLayout(run_dir)
    if name is None:
        robot_path, policy_path = train.robot, train.policy
        if not robot_path.exists() and run.robots.is_dir():
            names = run.robot_names()
            shown = ", ".join(names[:5]) + (", ..." if len(names) > 5 else "")
            raise ValueError(f"{run_dir} is an evolution run: name the robot to replay "
                             f"(python -m evo.replay {run_dir} NAME); its robots: {shown}")
    else:
        robot_path, policy_path = run.robot(name), run.policy(name)
        if not robot_path.exists() and train.robot.exists():
            robot_path, policy_path = train.robot, train.policy
    if not robot_path.exists():
        raise ValueError(f"{robot_path} not found: no robot {name!r} in {run_dir}")
    return load_robot(robot_path), policy_path


@dataclass(frozen=True)
class Clip:
    """How a video is cut and encoded.

    Attributes:
        width: Frame width, pixels.
        height: Frame height, pixels.
        fps: Frames per second; the episodes' control steps are thinned to it (at most
            the control rate: every step is a frame).
        seconds: Simulated seconds shown at most, over all episodes (None: all of them).
    """

    width: int = 640
    height: int = 480
    fps: int = 20
    seconds: float | None = None

    def __post_init__(self) -> None:
        at_least(self, 16, "width", "height", note=" pixels")
        at_least(self, 1, "fps")
        if self.seconds is not None:
            positive(self, "seconds")

    def frames(self, time: npt.NDArray[np.float64], shown: float) -> list[int]:
        """The steps of an episode (its ``time``, s) to draw, ``shown`` seconds already
        drawn before it."""
        step = float(np.median(np.diff(time))) if len(time) > 1 else 1.0 / self.fps
        every = max(1, round(1.0 / (self.fps * step)))
        end = np.inf if self.seconds is None else self.seconds - shown
        return [t for t in range(0, len(time), every) if time[t] - time[0] <= end]


CODECS = {".webm": {"codec": "libvpx-vp9", "bitrate": "300k"}}
"""ffmpeg options per video suffix other than imageio's defaults."""


def write_video(
    model: mujoco.MjModel,
    episodes: Sequence[Episode],
    path: Path,
    clip: Clip = Clip(),
) -> Path:
    """Render the frames of ``episodes`` that ``clip`` keeps and encode them (mp4 or webm
    via ffmpeg, or gif).

    The camera follows the robot: every frame it looks at the point between the brain
    and the target and stands back just far enough to keep both in view (smoothed over
    about half a second), so the robot stays a good size however far it drives.
    """
    import imageio.v2 as imageio

    renderer = make_renderer(model, clip.width, clip.height)
    data = mujoco.MjData(model)
    mocap = [(int(model.body_mocapid[b]), b) for b in range(model.nbody)
             if model.body_mocapid[b] >= 0]  # the target, a task's moving map
    brain = model.body("brain").id
    camera = mujoco.MjvCamera()
    camera.azimuth, camera.elevation = 135.0, -35.0
    shown = 0.0
    try:
        with imageio.get_writer(path, fps=clip.fps, **CODECS.get(path.suffix, {})) as writer:
            for episode in episodes:
                if episode.qpos is None:
                    raise ValueError(f"{path}: episode {episode.index} has no joint positions "
                                     "to render (a played episode has them)")
                lookat, distance = tracking_shot(episode.xpos[:, brain], episode.target)
                frames = clip.frames(episode.time, shown)
                shown += float(episode.time[frames[-1]] - episode.time[0]) if frames else 0.0
                for t in frames:
                    data.qpos[:] = episode.qpos[t]
                    for index, body in mocap:  # where each stood in this frame
                        data.mocap_pos[index] = episode.xpos[t, body]
                        data.mocap_quat[index] = episode.xquat[t, body]
                    mujoco.mj_kinematics(model, data)
                    camera.lookat[:], camera.distance = lookat[t], distance[t]
                    renderer.update_scene(data, camera=camera)
                    writer.append_data(renderer.render())  # type: ignore[attr-defined]
    finally:
        renderer.close()
    return path


def tracking_shot(brain: npt.NDArray[np.float64], target: npt.NDArray[np.float64],
                  smoothing: float = 0.1) -> tuple[npt.NDArray[np.float64],
                                                    npt.NDArray[np.float64]]:
    """Per frame, where a following camera looks and how far back it stands.

    Args:
        brain: The brain's position in every frame, (T, 3).
        target: The target, (3,).
        smoothing: Weight of the new frame in the exponential smoothing (0.1 at 20 Hz:
            about half a second).

    Returns:
        Look-at points (T, 3) between the brain and the target, and distances (T,)
        that frame both with a margin (never nearer than 0.5 m).
    """
    lookat = np.empty_like(brain)
    distance = np.empty(len(brain))
    point = (brain[0] + target) / 2
    far = 0.5 + 1.6 * float(np.linalg.norm(brain[0, :2] - target[:2]))
    for t, position in enumerate(brain):
        point = (1 - smoothing) * point + smoothing * (position + target) / 2
        wanted = max(0.5, 0.35 + 1.6 * float(np.linalg.norm(position[:2] - target[:2])))
        far = (1 - smoothing) * far + smoothing * wanted
        lookat[t], distance[t] = point, far
    return lookat, distance


def recorded_seed(run_dir: Path, name: str | None) -> int:
    """The seed of the deterministic episode recorded after training (0 if unknown)."""
    if name is None or not RunLayout(run_dir).mcap(name).is_file():
        return 0
    from evo.record import read_metadata

    path = RunLayout(run_dir).mcap(name)
    seed = read_metadata(path).get("replay_seed", 0)
    if not isinstance(seed, int | float | str):
        raise ValueError(f"{path}: replay_seed {seed!r} is not a number")
    return int(seed)


def replay(
    run_dir: Path,
    name: str | None,
    episodes: int,
    seed: int | None,
    video: Path | None,
    rrd: Path | None,
    clip: Clip = Clip(),
) -> list[Episode]:
    """Re-simulate ``episodes`` deterministic episodes and write the requested files
    (the video cut and encoded as ``clip`` says).

    With ``seed=None`` the first episode is the one recorded after training.
    """
    physics, env = _run_config(run_dir)
    robot, policy_path = _files(run_dir, name)
    seed = recorded_seed(run_dir, name) if seed is None else seed
    policy = load_checkpoint(policy_path, robot=robot, obs_size=observation_size(robot, env.task))
    core, played = play(robot, policy, physics=physics, env=env, seed=seed, episodes=episodes)
    for i, episode in enumerate(played):
        print(
            f"episode {i}: {len(episode.time) - 1} steps, return {episode.total_return:+.4f}, "
            f"{'success' if episode.success else 'no success'}"
        )
    if video is not None:
        print(f"video: {write_video(core.model, played, video, clip)}")
    if rrd is not None:
        from evo.record.playback import write_replay_rrd

        print(f"rerun: {write_replay_rrd(core.model, robot, played, rrd)}")
    return played


def gallery(run_dir: Path, top: int, out: Path) -> Path:
    """A contact sheet of the ``top`` fittest robots of a run."""
    from evo.robot.gallery import contact_sheet

    layout = RunLayout(run_dir)
    if not layout.history.is_file():
        raise ValueError(f"{layout.history} not found; is {run_dir} an evolution run "
                         "directory?")
    rows = read_history(layout.history).dropna(subset=["fitness"]).nlargest(top, "fitness")
    robots = [load_robot(layout.robot(n)) for n in rows["name"]]
    physics, _ = _run_config(run_dir)
    return contact_sheet(robots, physics, out)


def _size(text: str) -> tuple[int, int]:
    """``WxH`` as (width, height)."""
    try:
        width, height = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"{text!r} is not WIDTHxHEIGHT (e.g. 320x240)") from None
    return width, height


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m evo.replay",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("run_dir", type=Path)
    parser.add_argument("name", nargs="?", help="robot name (omit for a task=train run)")
    parser.add_argument("--episodes", type=int, default=1)
    parser.add_argument(
        "--seed",
        type=int,
        default=None,
        help="episode seed (default: that of the recorded deterministic episode)",
    )
    parser.add_argument("--video", type=Path, help="video file: .mp4, .webm or .gif")
    parser.add_argument("--size", type=_size, default=(640, 480), metavar="WxH",
                        help="video frame size in pixels (default 640x480)")
    parser.add_argument("--fps", type=int, default=20, help="video frames per second")
    parser.add_argument("--seconds", type=float, default=None,
                        help="simulated seconds the video shows at most (default: all)")
    parser.add_argument("--rrd", type=Path)
    parser.add_argument("--gallery", action="store_true", help="picture the best robots")
    parser.add_argument("--top", type=int, default=8)
    parser.add_argument("--out", type=Path, help="gallery picture (default RUN_DIR/best.png)")
    args = parser.parse_args(argv)
    try:
        if args.gallery:
            print(gallery(args.run_dir, args.top, args.out or args.run_dir / "best.png"))
        else:
            (width, height), fps, seconds = args.size, args.fps, args.seconds
            clip = Clip(width=width, height=height, fps=fps, seconds=seconds)
            replay(args.run_dir, args.name, args.episodes, args.seed, args.video, args.rrd,
                   clip)
    except (ValueError, ConfigError, RobotFileError, InvalidRobotError, RenderError) as err:
        print(f"replay: {err}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
