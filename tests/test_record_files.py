"""Recording files as outside tools see them: the ``rerun`` CLI's checks, the .rrd's
entities, crash safety of a killed writer, and the run-level files."""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import subprocess
import sys
import textwrap
from pathlib import Path
from typing import Any

import mujoco
import numpy as np
import pandas as pd
import pytest
from mcap.reader import make_reader
from test_record import curve_rows, robot_bodies, scene, simulate  # tests/ is on sys.path

from evo.record import (
    Birth,
    McapRecorder,
    RecordConfig,
    Recorders,
    RerunRecorder,
    RunRecorder,
    is_complete,
    open_recorder,
    read_births,
    read_curve,
    read_episodes,
    read_json_topic,
    read_metadata,
    write_replay_rrd,
)
from evo.robot import load_robot
from evo.robot.builder import build

ROOT = Path(__file__).resolve().parents[1]


def rerun_cli() -> str:
    """The ``rerun`` executable that ships with rerun-sdk."""
    local = Path(sys.executable).parent / "rerun"
    found = str(local) if local.exists() else shutil.which("rerun")
    assert found, "the rerun CLI (part of rerun-sdk) is not installed"
    return found


def cli(*args: str | Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [rerun_cli(), *map(str, args)], capture_output=True, text=True, timeout=120, check=False
    )


def entities(rrd: Path) -> set[str]:
    """Entity paths of the data (not blueprint) chunks, from ``rerun rrd print``."""
    out = cli("rrd", "print", rrd)
    assert out.returncode == 0, out.stderr
    return set(re.findall(r" - (/\S+) - data columns", out.stdout))


def record_evaluation(folder: Path, model: mujoco.MjModel) -> tuple[Path, Path]:
    """An evaluation's two files: 12 curve rows and two simulated episodes."""
    mcap, rrd = folder / "robot-1.mcap", folder / "robot-1.rrd"
    meta = {"robot": (ROOT / "robots/four_wheeler.json").read_text(), "seed": 5}
    with Recorders([McapRecorder(mcap, model, meta), RerunRecorder(rrd, model, meta)]) as rec:
        for i, row in enumerate(curve_rows(12)):
            rec.curve(row)
            if i in (3, 9):
                rec.episode(simulate(model, frames=60, index=i))
        rec.close({"fitness": 0.5})
    return mcap, rrd


def test_files_pass_the_rerun_checks(tmp_path: Path) -> None:
    mcap, rrd = record_evaluation(tmp_path, scene(n_rocks=3))
    check = cli("mcap", "check", mcap)
    assert check.returncode == 0, check.stdout + check.stderr
    for topic in ("/scene", "/tf", "/episode", "/episode/step", "/train/curve"):
        assert re.search(rf"ok\s+\d+\s+\d+\s+{re.escape(topic)}\s", check.stdout), topic
    verify = cli("rrd", "verify", rrd)
    assert verify.returncode == 0, verify.stdout + verify.stderr


def layout_paths(name: str) -> tuple[set[str], list[str]]:
    """The 3D topics and the plotted message paths of ``docs/foxglove/<name>.json``."""
    layout = json.loads((ROOT / "docs" / "foxglove" / f"{name}.json").read_text())
    topics: set[str] = set()
    paths: list[str] = []
    for panel, config in layout["configById"].items():
        if panel.startswith("3D!"):
            topics |= set(config["topics"])
        elif panel.startswith("Plot!"):
            paths += [p["value"] for p in config["paths"]]
            if "xAxisPath" in config:
                paths.append(config["xAxisPath"]["value"])
    return topics, paths


def has_number(message: Any, keys: list[str]) -> bool:
    """Whether ``message[k1][k2]...`` is a number."""
    for key in keys:
        if not isinstance(message, dict) or key not in message:
            return False
        message = message[key]
    return isinstance(message, int | float) and not isinstance(message, bool)


def check_layout(name: str, mcap: Path) -> None:
    """Every topic and message path the Foxglove layout shows is in the recording."""
    with mcap.open("rb") as stream:
        summary = make_reader(stream).get_summary()
    assert summary is not None
    channels = {c.topic for c in summary.channels.values()}
    topics, paths = layout_paths(name)
    assert topics <= channels, f"{name}: topics not recorded: {sorted(topics - channels)}"
    messages = {topic: read_json_topic(mcap, topic) for topic in {p.split(".")[0] for p in paths}}
    for path in paths:
        topic, _, fields = path.partition(".")
        assert messages[topic], f"{name}: nothing recorded on {topic}"
        assert any(has_number(m, fields.split(".")) for m in messages[topic]), f"{name}: no {path}"


def test_foxglove_layouts_show_what_is_recorded(tmp_path: Path) -> None:
    mcap, _ = record_evaluation(tmp_path, scene(n_rocks=1))
    check_layout("evaluation", mcap)
    with RunRecorder(tmp_path, {"seed": 0}) as run:
        run.birth(Birth(0, "robot-0", 0.5, True, 0.5, 0.5))
        run.robot("four_wheeler", build(load_robot(ROOT / "robots/four_wheeler.json")).compile(),
                  fitness=0.5)
        run.close({})
    check_layout("run", tmp_path / "run.mcap")


def test_rrd_holds_the_scene_curves_and_a_blueprint(tmp_path: Path) -> None:
    model = scene(n_rocks=2)
    _, rrd = record_evaluation(tmp_path, model)
    found = entities(rrd)
    expected = {
        "/scene/brain",
        "/scene/wheel3",
        "/scene/rock0",
        "/scene/rock1",
        "/scene/target",
        "/scene/brain/geometry/box",
        "/scene/wheel3/geometry/cylinder",
        "/scene/rock0/geometry/box",
        "/scene/world/geometry/box",
        "/episode/reward/time",
        "/episode/reward/approach",
        "/episode/return",
        "/episode/log",
        "/curve/train/mean_return",
        "/curve/train/success_rate",
        "/curve/train/loss/objective",
        "/curve/train/reward/approach",
        "/metadata/robot",
        "/metadata/seed",
        "/summary/fitness",
    }
    assert expected <= found, f"missing entities: {sorted(expected - found)}"
    printed = cli("rrd", "print", rrd).stdout
    assert "Blueprint" in printed and printed.count("/view/") >= 5, "no default blueprint"


def test_exception_inside_with_still_closes_the_rrd(tmp_path: Path) -> None:
    model = scene(n_rocks=0)
    mcap, rrd = tmp_path / "f.mcap", tmp_path / "f.rrd"
    recorders = Recorders([McapRecorder(mcap, model, {}), RerunRecorder(rrd, model, {})])
    with pytest.raises(ZeroDivisionError), recorders as rec:
        rec.curve({"env_steps": 64.0, "train/mean_return": 0.5})
        rec.episode(simulate(model, frames=20))
        _ = 1 / 0
    verify = cli("rrd", "verify", rrd)
    assert verify.returncode == 0, verify.stdout + verify.stderr
    assert is_complete(mcap) and read_metadata(mcap)["status"] == "failed"
    assert len(read_curve(mcap)) == 1 and len(read_episodes(mcap)) == 1


CHILD = textwrap.dedent(
    """
    import sys, time
    sys.path.insert(0, "tests")
    from evo.record import McapRecorder, Recorders, RerunRecorder
    from test_record import curve_rows, scene, simulate
    model = scene(n_rocks=2)
    out = sys.argv[1]
    rec = Recorders([
        McapRecorder(out + ".mcap", model, {"seed": 9}, flush_every=5),
        RerunRecorder(out + ".rrd", model, {"seed": 9}, flush_every=5),
    ])
    rec.episode(simulate(model, frames=40))
    for row in curve_rows(12):
        rec.curve(row)
    print("READY", flush=True)
    time.sleep(120)
    """
)


def test_killed_writer_leaves_everything_up_to_the_last_flush(tmp_path: Path) -> None:
    out = tmp_path / "killed"
    child = subprocess.Popen(
        [sys.executable, "-c", CHILD, str(out)], cwd=ROOT, stdout=subprocess.PIPE, text=True
    )
    try:
        assert child.stdout is not None
        assert child.stdout.readline().strip() == "READY"
        child.send_signal(signal.SIGKILL)
    finally:
        child.kill()
        child.wait(timeout=30)
    mcap = out.with_suffix(".mcap")
    assert not is_complete(mcap)
    pd.testing.assert_frame_equal(
        read_curve(mcap), pd.DataFrame(curve_rows(10)), check_exact=True
    )  # flushed at rows 5 and 10
    (episode,) = read_episodes(mcap)
    model = scene(n_rocks=2)
    want, robot = simulate(model, frames=40), robot_bodies(model)
    np.testing.assert_array_equal(episode.xpos[:, robot], want.xpos[:, robot])
    np.testing.assert_allclose(episode.xpos[:, 1:], want.xpos[:, 1:], rtol=0, atol=1e-6)
    assert read_metadata(mcap) == {"seed": 9}
    rrd = out.with_suffix(".rrd")
    assert cli("rrd", "verify", rrd).returncode != 0, "a killed writer leaves no footer"
    lenient = cli("rrd", "verify", "--check-footers", "false", rrd)
    assert lenient.returncode == 0, lenient.stdout + lenient.stderr


def test_run_files_hold_births_and_robots(tmp_path: Path) -> None:
    births = [
        Birth(
            i,
            f"robot-{i:08x}",
            fitness=0.1 * i - 0.2,
            accepted=i % 3 != 1,
            population_best=0.1 * i,
            population_mean=0.05 * i,
            extra={"generation": i // 2, "budget": 50_000 + 1000 * i},
        )
        for i in range(7)
    ]
    with RunRecorder(tmp_path, {"seed": 0, "method": "E+L"}) as run:
        for birth in births:
            run.birth(birth)
        for name in ("four_wheeler", "snake"):
            run.robot(name, build(load_robot(ROOT / f"robots/{name}.json")).compile(), fitness=0.4)
        run.close({"best_fitness": 0.4})
    table = read_births(tmp_path / "run.mcap")
    assert list(table["birth"]) == list(range(7))
    assert list(table["accepted"]) == [b.accepted for b in births]
    np.testing.assert_array_equal(table["fitness"], [b.fitness for b in births])
    assert list(table.columns[-2:]) == ["generation", "budget"]
    assert read_metadata(tmp_path / "run.mcap")["best_fitness"] == 0.4
    assert cli("mcap", "check", tmp_path / "run.mcap").returncode == 0
    assert cli("rrd", "verify", tmp_path / "run.rrd").returncode == 0
    found = entities(tmp_path / "run.rrd")
    expected = {
        "/ga/fitness/accepted",
        "/ga/fitness/rejected",
        "/ga/population/best",
        "/ga/population/mean",
        "/ga/log",
        "/robots/four_wheeler/box",
        "/robots/snake/cylinder",
        "/robots/snake/label",
    }
    assert expected <= found, f"missing entities: {sorted(expected - found)}"


def native_threads() -> int:
    return len(os.listdir("/proc/self/task"))


@pytest.mark.skipif(not Path("/proc/self/task").is_dir(), reason="counts threads through /proc")
def test_many_evaluations_leave_no_threads_behind(tmp_path: Path) -> None:
    model = build(load_robot(ROOT / "robots/snake.json")).compile()
    config = RecordConfig()

    def evaluate(i: int) -> None:
        with open_recorder(config, tmp_path, f"robot-{i}", model, {}) as rec:
            rec.curve({"env_steps": 1.0, "train/mean_return": 0.0})

    evaluate(0)  # rerun starts its shared runtime on first use
    before = native_threads()
    for i in range(1, 6):
        evaluate(i)
    assert native_threads() <= before, "recorders leak threads in a long-lived worker"
    assert cli("rrd", "verify", tmp_path / "robot-5.rrd").returncode == 0


def test_replays_become_rrd_files(tmp_path: Path) -> None:
    model = scene(n_rocks=1)
    robot = load_robot(ROOT / "robots/four_wheeler.json")
    played = [simulate(model, frames=30, seed=s) for s in (0, 1)]
    path = write_replay_rrd(model, robot, played, tmp_path / "replay.rrd")
    assert cli("rrd", "verify", path).returncode == 0
    found = entities(path)
    assert {"/scene/brain", "/episode/return", "/metadata/name", "/metadata/robot"} <= found
    assert robot.name in cli("rrd", "print", "-vvv", path).stdout
