"""The evaluation pool that the evolution and the retraining share, and the ``retrain``
task of ``evo/main.py`` (the noise ceiling's trainings): end to end with its report
(``analysis.noise_ceiling``), resumed, stopped by a signal, and the same numbers and
files under the older one-shot command line."""

from __future__ import annotations

import json
import shutil
import signal
import subprocess
import time
from collections.abc import Callable, Sequence
from concurrent.futures import Future
from pathlib import Path
from typing import Any

import pandas as pd
import pytest
from test_evolution import ENV, main_cmd

from analysis import noise_ceiling as nc
from evo.evaluation import Job, Outcome
from evo.pool import EvaluationPool
from evo.run.records import TRAINING_COLUMNS, Candidate

REPO = Path(__file__).resolve().parents[1]
ROBOTS = ("four_wheeler", "snake", "twisted_four_wheeler")
TINY = ["noise_ceiling.budget=128", "learner.num_envs=2",
        "learner.rollout_steps=64", "learner.minibatch_size=64", "env.task.t_max=40",
        "record=off", "executor=serial"]
"""Three robots x (two seeds + the random learner) x 128 env steps: seconds."""
NUMBERS = ["name", "structure", "role", "learner", "replicate", "seed", "budget", "fitness",
           "fitness_late", "episodes", "env_steps"]
"""The columns of ``trainings.csv`` that the settings and seeds decide."""


# ---------------------------------------------------------------- the pool


def fake_evaluate(candidate: Candidate, job: Job) -> Outcome:
    """An evaluation without training: fitness is the birth; birth 2 fails."""
    if candidate.birth == 2:
        raise RuntimeError("no luck")
    return Outcome(candidate.birth, candidate.name, fitness=float(candidate.birth))


class Deferred:
    """An executor of ``workers`` whose futures finish only when :meth:`finish` runs
    them, last submitted first: the pool must wait for whichever ends. A submission that
    fills the last free worker finishes the newest at once, as the pool is about to wait."""

    def __init__(self, workers: int) -> None:
        self.workers = workers
        self.queue: list[tuple[Future[Any], Callable[..., Any], tuple[Any, ...]]] = []
        self.calls: list[str] = []

    def submit(self, fn: Callable[..., Any], /, *args: Any) -> Future[Any]:
        future: Future[Any] = Future()
        self.queue.append((future, fn, args))
        if len(self.queue) == self.workers:
            self.finish()
        return future

    def finish(self) -> None:
        future, fn, args = self.queue.pop()
        try:
            future.set_result(fn(*args))
        except Exception as err:  # noqa: BLE001 - handed over through the future
            future.set_exception(err)

    def restart(self) -> None:
        self.calls.append("restart")

    def shutdown(self) -> None:
        self.calls.append("shutdown")

    def terminate(self) -> None:
        self.calls.append("terminate")


def candidates(n: int) -> list[Candidate]:
    return [Candidate(b, f"robot-{b}", "{}", 64, b) for b in range(n)]


def test_the_pool_keeps_the_workers_busy_and_hands_back_outcomes_as_they_finish() -> None:
    executor = Deferred(workers=2)
    job = Job.__new__(Job)  # never looked at by fake_evaluate
    todo = candidates(5)
    seen_running: list[list[str]] = []
    outcomes: list[Outcome] = []

    def next_candidate(running: Sequence[Candidate]) -> tuple[Candidate, Job] | None:
        seen_running.append([c.name for c in running])
        if todo:
            return todo.pop(0), job
        if executor.queue:  # none to add: the pool waits for those in flight
            executor.finish()
        return None

    def on_outcome(candidate: Candidate, outcome: Outcome) -> None:
        assert candidate.name == outcome.name
        outcomes.append(outcome)

    resumed = Candidate(9, "resumed", "{}", 64, 9)
    EvaluationPool(executor, fake_evaluate).run(next_candidate, on_outcome,
                                                resumed=[(resumed, job)])
    # The resumed candidate went first and finishes last: outcomes come as they end.
    assert [o.birth for o in outcomes] == [0, 1, 2, 3, 4, 9]
    assert seen_running[0] == ["resumed"] and seen_running[-1] == [], seen_running
    assert all(len(r) < executor.workers for r in seen_running), "asked only with a free worker"
    failed = next(o for o in outcomes if o.birth == 2)
    assert failed.error == "RuntimeError: no luck", "a failure is an outcome"
    assert executor.calls == ["shutdown"]


def test_the_pool_stops_its_workers_when_interrupted() -> None:
    executor = Deferred(workers=2)
    todo = candidates(3)

    def on_outcome(candidate: Candidate, outcome: Outcome) -> None:
        raise KeyboardInterrupt  # a signal while the result is recorded

    with pytest.raises(KeyboardInterrupt):
        EvaluationPool(executor, fake_evaluate).run(
            lambda running: (todo.pop(0), Job.__new__(Job)) if todo else None, on_outcome)
    assert executor.calls == ["terminate"], "stopped, not waited for"
    assert len(executor.queue) == 1, "the other evaluation was in flight"


# ---------------------------------------------------------------- the retrain task


def robots_folder(folder: Path) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    for stem in ROBOTS:
        shutil.copy(REPO / "robots" / f"{stem}.json", folder / f"{stem}.json")
    return folder


def retrain_cmd(out: Path, robots: Path, *extra: str) -> list[str]:
    """The retrain task, its keys in their older spelling (``noise_ceiling.<key>``)."""
    return main_cmd("+exp=retrain", f"noise_ceiling.robots={robots}", *TINY,
                    f"hydra.run.dir={out}", *extra)


def report(out: Path) -> None:
    """``python -m analysis.noise_ceiling OUT``: the report of a retraining's folder."""
    assert nc.main([str(out), "--resamples", "20"]) == 0


def run(cmd: list[str], cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(cmd, cwd=cwd, env=ENV, capture_output=True, text=True, timeout=300)


@pytest.fixture(scope="module")
def retrained(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A finished ``+exp=retrain`` of three robots."""
    root = tmp_path_factory.mktemp("retrain")
    out = root / "ceiling"
    done = run(retrain_cmd(out, robots_folder(root / "robots")), root)
    assert done.returncode == 0, done.stderr[-3000:]
    assert f"report: python -m analysis.noise_ceiling {out}" in done.stdout, done.stdout
    assert not (out / "summary.json").exists(), "evo trains; the report is analysis's"
    report(out)
    return out


def test_the_retrain_task_writes_the_noise_ceiling(retrained: Path) -> None:
    trainings = pd.read_csv(retrained / nc.TRAININGS)
    assert list(trainings.columns) == list(TRAINING_COLUMNS)
    assert len(trainings) == 3 * 2 + 3, "two seeds and one baseline per structure"
    assert sorted(trainings["role"].unique()) == ["baseline", "seed"]
    assert (trainings["env_steps"] >= 128).all() and (trainings["cpu_seconds"] > 0).all()
    summary = json.loads((retrained / "summary.json").read_text())
    assert set(summary["metrics"]) == set(nc.ESTIMATORS) and summary["trainings"] == 9
    assert summary["command"].startswith("python evo/main.py +exp=retrain")
    settings = json.loads((retrained / nc.SETTINGS).read_text())
    assert settings["budget"] == 128 and settings["seeds"] == 2 and settings["baseline"]
    for name in ("noise_ceiling.md", "noise_ceiling.csv", "noise_ceiling.png",
                 "progress.json", "config.yaml", "lock.json"):
        assert (retrained / name).is_file(), name
    assert json.loads((retrained / "lock.json").read_text())["pid"] > 0


def test_a_resumed_retrain_reuses_the_finished_trainings(retrained: Path,
                                                         tmp_path: Path) -> None:
    """Stopped with three trainings done (the others in flight or not started):
    ``resume=DIR`` keeps those three and trains the rest with their own seeds."""
    first = pd.read_csv(retrained / nc.TRAININGS)
    stopped = tmp_path / "stopped"
    shutil.copytree(retrained, stopped)
    first.head(3).to_csv(stopped / nc.TRAININGS, index=False)
    for name in ("summary.json", "noise_ceiling.md", "noise_ceiling.csv"):
        (stopped / name).unlink()
    done = run(main_cmd(f"resume={stopped}"), tmp_path)
    assert done.returncode == 0, done.stderr[-3000:]
    assert "3 of 9 trainings already done; 6 to run" in done.stdout, done.stdout[-2000:]
    report(stopped)
    again = pd.read_csv(stopped / nc.TRAININGS)
    pd.testing.assert_frame_equal(again.head(3), first.head(3), obj="reused, not retrained")
    by_name = again.set_index("name").sort_index()[NUMBERS[1:]]
    pd.testing.assert_frame_equal(by_name, first.set_index("name").sort_index()[NUMBERS[1:]])
    summary = json.loads((stopped / "summary.json").read_text())
    assert summary["metrics"] == json.loads((retrained / "summary.json").read_text())["metrics"]
    assert json.loads((stopped / nc.SETTINGS).read_text())["overrides"] == json.loads(
        (retrained / nc.SETTINGS).read_text())["overrides"], "the settings it was started with"


def test_other_settings_in_a_retrain_folder_are_refused_and_change_nothing(
    retrained: Path, tmp_path: Path,
) -> None:
    folder = tmp_path / "ceiling"
    shutil.copytree(retrained, folder)
    before = {p.name: p.read_bytes() for p in folder.iterdir() if p.is_file()}
    done = run(retrain_cmd(folder, retrained.parent / "robots", "noise_ceiling.budget=256"),
               tmp_path)
    assert done.returncode == 2, done.stderr[-3000:]
    assert "holds a noise ceiling with other settings (budget differ" in done.stderr, done.stderr
    after = {p.name: p.read_bytes() for p in folder.iterdir() if p.is_file()}
    assert after == before, "config.yaml and the rest as they were"


def test_the_older_command_line_gives_the_same_files(retrained: Path, tmp_path: Path) -> None:
    out = tmp_path / "alias"
    overrides = [o for o in TINY if not o.startswith("noise_ceiling.")]
    argv = ["--robots", str(retrained.parent / "robots"), "--budget", "128",
            "--resamples", "20", "--out", str(out), *overrides]
    assert nc.main(argv) == 0
    assert {p.name for p in out.iterdir()} == {p.name for p in retrained.iterdir()}
    numbers = [pd.read_csv(d / nc.TRAININGS).set_index("name").sort_index()[NUMBERS[1:]]
               for d in (retrained, out)]
    pd.testing.assert_frame_equal(*numbers)
    summaries = [json.loads((d / "summary.json").read_text()) for d in (retrained, out)]
    assert summaries[0]["metrics"] == summaries[1]["metrics"]
    assert summaries[1]["command"].startswith("python -m analysis.noise_ceiling --robots")
    assert summaries[1]["settings"]["overrides"][-len(overrides):] == overrides
    pd.testing.assert_frame_equal(*[pd.read_csv(d / "noise_ceiling.csv")
                                    for d in (retrained, out)])


def test_a_bad_retrain_setting_names_its_key(tmp_path: Path) -> None:
    """Checked before anything is written (``main`` turns the error into one line, exit 2;
    the robots' checks are the alias's, ``test_noise_ceiling``)."""
    from evo.config import ConfigError
    from evo.edge import compose_config, typed_config
    from evo.main import Run, run_retrain
    from evo.run.files import RunLock

    (tmp_path / "empty").mkdir()
    for overrides, message in [
        (["retrain.random=3", "retrain.seeds=1"], "retrain.seeds: expected at least 2, got 1"),
        ([], "retrain.robots: give the structures to train"),
        (["retrain.random=3", "retrain.confirm=1"], "retrain.confirm: expected 0 or at least 2"),
        (["retrain.random=3", "retrain.first_seed=-1"], "retrain.first_seed: expected a non"),
        (["retrain.runs=[nowhere]"], "retrain.runs nowhere: not a GA run directory"),
        (["retrain.random=2"], "retrain.random: expected at least 3 robots, got 2"),
        ([f"retrain.robots={tmp_path / 'empty'}"], "no robot files"),
        ([f"retrain.robots={tmp_path / 'missing'}"], "no such folder"),
        (["retrain.random=3", "learner.gamma=2"], "learner: gamma must be in"),
    ]:
        cfg = compose_config(["+exp=retrain", *overrides])
        with pytest.raises(ConfigError, match=message):
            run_retrain(Run(typed_config(cfg), tmp_path / "out", RunLock(tmp_path)))
    assert not (tmp_path / "out").exists()


def test_resume_continues_the_task_a_directory_was_started_with(tmp_path: Path) -> None:
    from evo.config import ConfigError
    from evo.edge import compose_config
    from evo.main import _resumable_task

    cfg = compose_config([f"resume={tmp_path}"])
    (tmp_path / "config.yaml").write_text("task: retrain\n")
    assert _resumable_task(cfg) == "retrain"
    (tmp_path / "config.yaml").write_text("task: noise_sweep\n")
    with pytest.raises(ConfigError, match="task=noise_sweep run, which does not resume"):
        _resumable_task(cfg)


@pytest.mark.long  # a signal mid-task; the resume test above covers what it continues
def test_a_signal_stops_the_retrain_task_and_resume_continues_it(tmp_path: Path) -> None:
    out = tmp_path / "ceiling"
    command = retrain_cmd(out, robots_folder(tmp_path / "robots"), "noise_ceiling.budget=4096")
    with (tmp_path / "log").open("w") as log:
        proc = subprocess.Popen(command, cwd=tmp_path, env=ENV, stdout=log, stderr=log)
        trainings = out / nc.TRAININGS
        while proc.poll() is None and not (
                trainings.is_file() and len(trainings.read_text().splitlines()) > 2):
            time.sleep(0.2)
        proc.send_signal(signal.SIGINT)
        proc.wait(timeout=120)
    err = (tmp_path / "log").read_text()
    assert proc.returncode == 130, err[-2000:]
    assert f"continue with: python evo/main.py resume={out}" in err
    kept = pd.read_csv(out / nc.TRAININGS)
    assert 2 <= len(kept) < 9
    done = run(main_cmd(f"resume={out}"), tmp_path)
    assert done.returncode == 0, done.stderr[-3000:]
    again = pd.read_csv(out / nc.TRAININGS)
    assert len(again) == 9
    pd.testing.assert_frame_equal(again.head(len(kept)), kept, obj="reused, not retrained")
