"""``python -m evo.robot``, run as a user runs it: in a subprocess, checking exit codes,
output and files. No bad input may end in a traceback."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from functools import cache
from pathlib import Path

import mujoco
import numpy as np
import pytest

import evo.robot.__main__ as robot_cli
from evo.robot import FORMAT, Robot, load_robot, save_robot
from evo.robot.operators import crossover_sites, replace_at, subtree_at

REPO = Path(__file__).resolve().parents[1]
FOUR_WHEELER = REPO / "robots" / "four_wheeler.json"
SNAKE = REPO / "robots" / "snake.json"


def cli(*args: str | Path, gl: str = "egl") -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "MUJOCO_GL": gl}
    done = subprocess.run(
        [sys.executable, "-m", "evo.robot", *map(str, args)],
        capture_output=True,
        text=True,
        cwd=REPO,
        env=env,
        timeout=120,
    )
    assert "Traceback" not in done.stderr, done.stderr
    return done


def write(path: Path, doc: object) -> Path:
    path.write_text(json.dumps(doc), encoding="utf-8")
    return path


def three_problems(tmp_path: Path) -> Path:
    wheel = {"type": "wheel"}
    motor = {
        "type": "motor",
        "children": [{"face": 2, "module": wheel}, {"face": 3, "module": wheel}],
    }
    root = {
        "type": "brain",
        "children": [
            {"face": 4, "module": motor},
            {"face": 0, "module": {"type": "main", "children": [{"face": 2, "module": wheel}]}},
            {
                "face": 1,
                "module": {"type": "pivot", "children": [{"face": 2, "module": {"type": "main"}}]},
            },
        ],
    }
    return write(tmp_path / "three.json", {"format": FORMAT, "root": root})


# --- validate -----------------------------------------------------------------------------


def test_validate_valid_files() -> None:
    files = sorted((REPO / "robots").glob("*.json"))
    done = cli("validate", *files)
    assert done.returncode == 0, done.stderr
    for path in files:
        assert f"{path}: valid ({load_robot(path).name})" in done.stdout


def test_validate_invalid_file_prints_every_violation(tmp_path: Path) -> None:
    path = three_problems(tmp_path)
    done = cli("validate", path)
    assert done.returncode == 1
    assert f"{path}: invalid (3 problems)" in done.stderr
    for line in (
        "root: child on the brain's button face 4 (+z)",
        "root/0:main: single wheel on face 2; wheels come in pairs",
        "root/1:pivot: pivot child off face 0",
    ):
        assert line in done.stderr, done.stderr


@pytest.mark.parametrize(
    ("content", "reason"),
    [
        (None, "cannot read file"),
        ("{not json", "not valid JSON"),
        ("[]", "expected a JSON object at the top, got list"),
        ('{"root": {}}', "missing 'format' key"),
        ('{"format": "evo.robot/0", "root": {}}', "unknown format 'evo.robot/0'"),
    ],
)
def test_validate_unreadable_file(tmp_path: Path, content: str | None, reason: str) -> None:
    path = tmp_path / "bad.json"
    if content is not None:
        path.write_text(content, encoding="utf-8")
    done = cli("validate", path)
    assert done.returncode == 2
    assert f"{path}: unreadable: {reason}" in done.stderr, done.stderr


def test_validate_reports_the_worst_of_several_files(tmp_path: Path) -> None:
    invalid, missing = three_problems(tmp_path), tmp_path / "missing.json"
    done = cli("validate", FOUR_WHEELER, invalid, missing)
    assert done.returncode == 2
    assert "valid" in done.stdout and "invalid (3 problems)" in done.stderr
    assert f"{missing}: unreadable" in done.stderr
    assert cli("validate", FOUR_WHEELER, invalid).returncode == 1


# --- random, crossover, mutate ------------------------------------------------------------


def robot_files(out: Path) -> dict[str, str]:
    return {p.name: p.read_text(encoding="utf-8") for p in sorted(out.glob("*.json"))}


def test_random_writes_n_valid_files_the_same_for_the_same_seed(tmp_path: Path) -> None:
    # 30 robots at a high p_empty draw some structure twice; still 30 distinct files.
    args = ("random", "--count", "30", "--p-empty", "0.8")
    first = cli(*args, "--seed", "4", "--out", tmp_path / "a")
    again = cli(*args, "--seed", "4", "--out", tmp_path / "b")
    other = cli(*args, "--seed", "5", "--out", tmp_path / "c")
    assert first.returncode == again.returncode == other.returncode == 0, first.stderr
    a, b = robot_files(tmp_path / "a"), robot_files(tmp_path / "b")
    assert len(a) == 30, sorted(a)
    assert a == b, "the same seed gave different robots"
    assert robot_files(tmp_path / "c") != a
    for name, text in a.items():
        robot = load_robot(tmp_path / "a" / name)
        assert name == f"{robot.name}.json"
        assert text == robot.to_json() + "\n", "not the canonical form"
    assert sorted(first.stdout.split()) == sorted(str(tmp_path / "a" / n) for n in a)


def test_random_honours_max_depth(tmp_path: Path) -> None:
    done = cli("random", "--count", "20", "--seed", "1", "--max-depth", "1", "--out", tmp_path)
    assert done.returncode == 0, done.stderr
    assert all(load_robot(p).depth == 1 for p in tmp_path.glob("*.json"))


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (("--count", "-1"), "--count must be >= 0"),
        (("--count", "2", "--p-empty", "1.5"), "p_empty must be a probability"),
        (("--count", "2", "--max-depth", "0"), "max_depth must be >= 1"),
    ],
)
def test_random_rejects_bad_arguments(tmp_path: Path, args: tuple[str, ...], message: str) -> None:
    done = cli("random", *args, "--seed", "0", "--out", tmp_path)
    assert done.returncode == 2
    assert message in done.stderr, done.stderr
    assert not list(tmp_path.glob("*.json"))


def test_random_gives_up_when_the_design_space_is_too_small(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    only_one = load_robot(FOUR_WHEELER)
    code = robot_cli.main(["random", "--count", "3", "--seed", "0", "--out", str(tmp_path)],
                          draw=lambda rng, params: only_one)
    assert code == 2
    assert "random: only 1 distinct robots in 160 draws" in capsys.readouterr().err
    assert not list(tmp_path.glob("*.json"))


def test_crossover_writes_valid_offspring_of_the_parents(tmp_path: Path) -> None:
    a, b = load_robot(FOUR_WHEELER), load_robot(SNAKE)
    done = cli("crossover", FOUR_WHEELER, SNAKE, "--seed", "3", "--out", tmp_path / "x")
    assert done.returncode == 0, done.stderr
    children = [load_robot(p) for p in sorted((tmp_path / "x").glob("*.json"))]
    assert 1 <= len(children) <= 2
    swaps = set()
    for p1, p2 in crossover_sites(a, b):
        swaps.add(Robot(replace_at(a.root, p1, subtree_at(b.root, p2))))
        swaps.add(Robot(replace_at(b.root, p2, subtree_at(a.root, p1))))
    for child in children:
        assert child in swaps, "offspring is not a subtree swap of the parents"
    cli("crossover", FOUR_WHEELER, SNAKE, "--seed", "3", "--out", tmp_path / "y")
    assert robot_files(tmp_path / "x") == robot_files(tmp_path / "y")


def test_crossover_of_an_invalid_parent_fails_cleanly(tmp_path: Path) -> None:
    done = cli(
        "crossover", FOUR_WHEELER, three_problems(tmp_path), "--seed", "0", "--out", tmp_path
    )
    assert done.returncode == 1
    assert "three.json is not a valid robot (3 problems)" in done.stderr
    done = cli("crossover", FOUR_WHEELER, tmp_path / "gone.json", "--seed", "0", "--out", tmp_path)
    assert done.returncode == 2 and "gone.json: unreadable: cannot read file" in done.stderr


def test_mutate_writes_one_valid_changed_robot(tmp_path: Path) -> None:
    done = cli("mutate", FOUR_WHEELER, "--seed", "0", "--out", tmp_path)
    assert done.returncode == 0, done.stderr
    (path,) = tmp_path.glob("*.json")
    assert load_robot(path) != load_robot(FOUR_WHEELER)


# --- info, mjcf, render -------------------------------------------------------------------


def info_fields(text: str) -> dict[str, str]:
    fields = {}
    for line in text.splitlines():
        key, _, value = line.partition(":")
        fields[key.strip()] = value.strip()
    return fields


@pytest.mark.parametrize("path", sorted((REPO / "robots").glob("*.json")), ids=lambda p: p.stem)
def test_info_prints_sizes_and_hash(path: Path) -> None:
    robot = load_robot(path)
    done = cli("info", path)
    assert done.returncode == 0, done.stderr
    fields = info_fields(done.stdout)
    m, n = robot.n_motors, robot.n_pivots
    assert fields["motors m"] == str(m)
    assert fields["pivots n"] == str(n)
    assert fields["action"].split()[0] == str(m + n)
    assert "observation" not in fields  # the task's, not the robot's
    assert fields["hash"] == robot.hash and re.fullmatch(r"[0-9a-f]{64}", robot.hash)
    assert fields["name"] == f"robot-{robot.hash[:8]}"
    assert fields["modules"].startswith(f"{len(robot)} (")


def test_info_of_the_four_wheeler() -> None:
    fields = info_fields(cli("info", FOUR_WHEELER).stdout)
    assert (fields["motors m"], fields["pivots n"]) == ("2", "1")
    assert fields["action"].startswith("3")


def test_info_on_bad_files(tmp_path: Path) -> None:
    done = cli("info", three_problems(tmp_path))
    assert done.returncode == 1 and "root/1:pivot: pivot child off face 0" in done.stderr
    done = cli("info", tmp_path / "nothing.json")
    assert done.returncode == 2 and "nothing.json: unreadable" in done.stderr


def test_mjcf_output_compiles(tmp_path: Path) -> None:
    robot = load_robot(FOUR_WHEELER)
    done = cli("mjcf", FOUR_WHEELER)
    assert done.returncode == 0, done.stderr
    model = mujoco.MjModel.from_xml_string(done.stdout)
    assert model.nu == robot.n_actuators
    assert model.body("brain").id > 0 and model.geom("floor").id >= 0
    data = mujoco.MjData(model)
    mujoco.mj_step(model, data, 20)
    assert np.all(np.isfinite(data.qpos))
    # A hand-edited twisted robot exports as well.
    twisted = save_robot(
        load_robot(REPO / "robots" / "twisted_four_wheeler.json"), tmp_path / "t.json"
    )
    assert mujoco.MjModel.from_xml_string(cli("mjcf", twisted).stdout).nu == 3


@cache
def gl_backend() -> tuple[str | None, str]:
    """The first OpenGL backend that can make an offscreen context, and why the others failed."""
    probe = "import mujoco; c = mujoco.GLContext(8, 8); c.make_current(); c.free()"
    reasons = []
    for backend in ("egl", "osmesa", "glfw"):
        done = subprocess.run(
            [sys.executable, "-c", probe],
            capture_output=True,
            text=True,
            env={**os.environ, "MUJOCO_GL": backend},
            timeout=60,
        )
        if done.returncode == 0:
            return backend, ""
        last = done.stderr.strip().splitlines()[-1:] or ["no message"]
        reasons.append(f"{backend}: {last[0]}")
    return None, "; ".join(reasons)


def test_render_writes_a_png(tmp_path: Path) -> None:
    backend, why = gl_backend()
    if backend is None:
        pytest.skip(f"no OpenGL backend can render offscreen here ({why})")
    out = tmp_path / "pics" / "four.png"
    done = cli(
        "render", FOUR_WHEELER, "--out", out, "--width", "320", "--height", "240", gl=backend
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == str(out)
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    import matplotlib.image

    image = matplotlib.image.imread(out)
    assert image.shape[:2] == (240, 320)
    # Not a blank frame: the robot's dark wheels and coloured modules stand out of the floor.
    rgb = image[..., :3]
    assert rgb.std() > 0.05
    assert (rgb.max(axis=2) < 0.2).sum() > 200, "no dark wheel pixels"


@pytest.mark.parametrize("backend", ["bogus", "osmesa"])
def test_a_broken_opengl_backend_fails_cleanly(tmp_path: Path, backend: str) -> None:
    if backend == gl_backend()[0]:
        pytest.skip(f"{backend} works here")
    done = cli("render", FOUR_WHEELER, "--out", tmp_path / "x.png", gl=backend)
    assert done.returncode == 2
    # MuJoCo fails at import or when making the context; either way one line says so.
    assert done.stderr.startswith("render: ") and done.stderr.count("\n") == 1, done.stderr
    assert f"MUJOCO_GL={backend}" in done.stderr
    assert not (tmp_path / "x.png").exists()
    # Verbs that need no MuJoCo do not care about the backend.
    assert cli("validate", FOUR_WHEELER, gl=backend).returncode == 0
    assert cli("info", FOUR_WHEELER, gl=backend).returncode == 0
