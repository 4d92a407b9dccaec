"""Command-line tool for robot files: ``python -m evo.robot VERB ...``.

Verbs and exit codes (scripts rely on them):

* ``validate FILE...``: 0 when every file is valid; 1 when any is invalid (every
  violation printed with its node path); 2 when any file cannot be read or parsed.
* ``random --count N --seed S --out DIR [--max-depth D]``: N distinct valid robots as
  JSON, identical for the same seed.
* ``crossover A.json B.json --seed S --out DIR``: the valid offspring of one crossover.
* ``mutate FILE --seed S --out DIR``: one mutated robot (mutation is an extension).
* ``info FILE``: module counts, m, n, the action size (one command per actuator), hash.
  A robot knows its motors and pivots, not the task it is trained for: the observation
  is the task's (``evo.envs.params.observation_size``).
* ``mjcf FILE``: MJCF on stdout (robot on a floor) that MuJoCo compiles.
* ``render FILE --out PNG``: an offscreen picture of the robot (needs OpenGL, e.g.
  ``MUJOCO_GL=egl``).

Any bad input ends with a message naming the file and exit code 2 (or 1 for an invalid
robot), never with a traceback.
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Callable, Sequence
from functools import partial
from pathlib import Path

import numpy as np

from evo.robot.io import RobotFileError, load_robot, save_robot
from evo.robot.operators import GeneratorParams, OperatorError, crossover, mutate, random_robot
from evo.robot.tree import ModuleType, Robot
from evo.robot.validate import InvalidRobotError

EXIT_OK, EXIT_INVALID, EXIT_UNREADABLE = 0, 1, 2

RobotDraw = Callable[[np.random.Generator, GeneratorParams], Robot]
"""How ``random`` draws one robot (:func:`evo.robot.operators.random_robot`)."""


def _validate(args: argparse.Namespace) -> int:
    worst = EXIT_OK
    for name in args.files:
        try:
            robot = load_robot(name)
        except RobotFileError as err:
            print(f"{err.source}: unreadable: {err.reason}", file=sys.stderr)
            worst = max(worst, EXIT_UNREADABLE)
        except InvalidRobotError as err:
            n = len(err.violations)
            print(f"{err.source}: invalid ({n} problem{'' if n == 1 else 's'})", file=sys.stderr)
            for v in err.violations:
                print(f"  {v}", file=sys.stderr)
            worst = max(worst, EXIT_INVALID)
        else:
            print(f"{name}: valid ({robot.name})")
    return worst


def _write(robots: Sequence[Robot], out: Path) -> None:
    for robot in robots:
        path = save_robot(robot, out / f"{robot.name}.json")
        print(path)


def _random(args: argparse.Namespace, draw: RobotDraw = random_robot) -> int:
    params = GeneratorParams(max_depth=args.max_depth, p_empty=args.p_empty)
    rng = np.random.default_rng(args.seed)
    # Files are named by hash, so a robot drawn twice would overwrite itself and leave
    # fewer than N files: draw until N distinct robots (bounded for tiny design spaces).
    robots: dict[str, Robot] = {}
    draws = 20 * args.count + 100
    for _ in range(draws):
        if len(robots) == args.count:
            break
        robot = draw(rng, params)
        robots.setdefault(robot.hash, robot)
    if len(robots) < args.count:
        raise OperatorError(
            f"only {len(robots)} distinct robots in {draws} draws; "
            "raise --max-depth or lower --p-empty"
        )
    _write(list(robots.values()), Path(args.out))
    return EXIT_OK


def _crossover(args: argparse.Namespace) -> int:
    a, b = load_robot(args.a), load_robot(args.b)
    result = crossover(a, b, np.random.default_rng(args.seed))
    _write(result.offspring, Path(args.out))
    return EXIT_OK


def _mutate(args: argparse.Namespace) -> int:
    robot = load_robot(args.file)
    _write([mutate(robot, np.random.default_rng(args.seed))], Path(args.out))
    return EXIT_OK


def _info(args: argparse.Namespace) -> int:
    robot = load_robot(args.file)
    counts = ", ".join(f"{t.value} {robot.count(t)}" for t in ModuleType)
    print(f"name:        {robot.name}")
    print(f"hash:        {robot.hash}")
    print(f"modules:     {len(robot)} ({counts})")
    print(f"depth:       {robot.depth}")
    print(f"motors m:    {robot.n_motors}")
    print(f"pivots n:    {robot.n_pivots}")
    print(f"action:      {robot.n_actuators}  (m + n: one command per actuator)")
    return EXIT_OK


def _mujoco_loads(verb: str) -> bool:
    """Import MuJoCo, or say why not and return False.

    MuJoCo sets up the OpenGL backend named by ``MUJOCO_GL`` when it is imported, and a
    backend that is unknown or not installed fails right there (in many ways). So only
    the verbs that need MuJoCo import it, and a failure is one line, not a traceback.
    """
    try:
        import mujoco  # noqa: F401
    except Exception as err:  # noqa: BLE001 - a broken GL backend fails in many ways
        backend = os.environ.get("MUJOCO_GL", "(unset)")
        print(
            f"{verb}: cannot load MuJoCo with MUJOCO_GL={backend}: {err}. "
            "Try MUJOCO_GL=egl, or unset it.",
            file=sys.stderr,
        )
        return False
    return True


def _mjcf(args: argparse.Namespace) -> int:
    robot = load_robot(args.file)
    if not _mujoco_loads("mjcf"):
        return EXIT_UNREADABLE
    from evo.robot.builder import build

    print(build(robot).xml)
    return EXIT_OK


def _render(args: argparse.Namespace) -> int:
    if not _mujoco_loads("render"):
        return EXIT_UNREADABLE
    from evo.robot.render import RenderError, render_png

    out = Path(args.out)
    if out.suffix.lower() != ".png":
        print(f"render: --out {out}: expected a .png file name", file=sys.stderr)
        return EXIT_UNREADABLE
    try:
        path = render_png(load_robot(args.file), out, width=args.width, height=args.height)
    except RenderError as err:
        print(f"render: {err}", file=sys.stderr)
        return EXIT_UNREADABLE
    except OSError as err:
        print(f"render: --out {out}: cannot write it ({err.strerror or err})", file=sys.stderr)
        return EXIT_UNREADABLE
    print(path)
    return EXIT_OK


_DEFAULTS = GeneratorParams()


def _parser(draw: RobotDraw = random_robot) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="python -m evo.robot",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    verbs = parser.add_subparsers(dest="verb", required=True)
    p = verbs.add_parser("validate", help="check robot files")
    p.add_argument("files", nargs="+")
    p.set_defaults(run=_validate)
    p = verbs.add_parser("random", help="write N random valid robots")
    p.add_argument("--count", type=int, required=True)
    p.add_argument("--seed", type=int, required=True)
    p.add_argument("--out", required=True)
    p.add_argument("--max-depth", type=int, default=_DEFAULTS.max_depth)
    p.add_argument("--p-empty", type=float, default=_DEFAULTS.p_empty)
    p.set_defaults(run=partial(_random, draw=draw))
    p = verbs.add_parser("crossover", help="write the valid offspring of two robots")
    p.add_argument("a")
    p.add_argument("b")
    p.add_argument("--seed", type=int, required=True)
    p.add_argument("--out", required=True)
    p.set_defaults(run=_crossover)
    p = verbs.add_parser("mutate", help="write one mutated robot")
    p.add_argument("file")
    p.add_argument("--seed", type=int, required=True)
    p.add_argument("--out", required=True)
    p.set_defaults(run=_mutate)
    p = verbs.add_parser("info", help="sizes, counts and hash of a robot")
    p.add_argument("file")
    p.set_defaults(run=_info)
    p = verbs.add_parser("mjcf", help="print the robot's MJCF")
    p.add_argument("file")
    p.set_defaults(run=_mjcf)
    p = verbs.add_parser("render", help="save an offscreen picture of the robot")
    p.add_argument("file")
    p.add_argument("--out", required=True)
    p.add_argument("--width", type=int, default=640)
    p.add_argument("--height", type=int, default=480)
    p.set_defaults(run=_render)
    return parser


def main(argv: Sequence[str] | None = None, draw: RobotDraw = random_robot) -> int:
    """Run one verb and return its exit code.

    Args:
        argv: The command line after ``python -m evo.robot``; None reads ``sys.argv``.
        draw: How ``random`` draws one robot.
    """
    args = _parser(draw).parse_args(argv)
    if getattr(args, "count", 1) < 0:
        print("random: --count must be >= 0", file=sys.stderr)
        return EXIT_UNREADABLE
    run: Callable[[argparse.Namespace], int] = args.run
    try:
        return run(args)
    except RobotFileError as err:
        print(f"{err.source}: unreadable: {err.reason}", file=sys.stderr)
        return EXIT_UNREADABLE
    except InvalidRobotError as err:
        print(str(err), file=sys.stderr)
        return EXIT_INVALID
    except (OperatorError, ValueError, OSError) as err:
        print(f"{args.verb}: {err}", file=sys.stderr)
        return EXIT_UNREADABLE


if __name__ == "__main__":
    sys.exit(main())
