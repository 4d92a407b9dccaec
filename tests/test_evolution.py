"""The evolution loop (``evo/evolution.py``) and ``python evo/main.py`` runs of it.

Two tiers:

* in-process runs with a fast stand-in for the evaluation (a seeded function of the
  robot, no physics), so the loop's rules, its failure handling and its resume after a
  crash at every point can be checked exhaustively;
* end-to-end runs of ``python evo/main.py`` in a subprocess with real training: runs
  killed with SIGKILL at several points and resumed with ``python evo/main.py
  resume=<run dir>`` (the smoke experiment runs as the README shows it, in
  tests/test_readme.py).
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import json
import math
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest

from evo.components.executors import SerialExecutor
from evo.components.ga import (
    BudgetSchedule,
    Evolve,
    GAConfig,
    Offspring,
    RandomStructures,
    ReplaceWorst,
    Roulette,
)
from evo.envs.params import EnvConfig
from evo.evaluation import Job, Outcome, evaluate
from evo.evolution import Evolution, evaluation_seed
from evo.learners.ppo import PPO
from evo.robot import OperatorError, load_robot
from evo.robot.builder import PhysicsParams
from evo.run.records import Candidate, HistoryRow
from evo.run.store import RunStore

REPO = Path(__file__).resolve().parents[1]
SCHEDULE = BudgetSchedule(initial=100, first=200, last=1000)


# ---- a fast stand-in for the evaluation ---------------------------------------------------


def fake_evaluate(candidate: Candidate, job: Job) -> Outcome:
    """A fitness in [-1, 1] that depends only on the robot and the evaluation's seed."""
    digest = hashlib.sha256(f"{candidate.robot}/{candidate.seed}".encode()).digest()
    fitness = int.from_bytes(digest[:4], "little") / 2**32 * 2 - 1
    return Outcome(
        candidate.birth,
        candidate.name,
        fitness=fitness,
        env_steps=candidate.budget,
        episodes=3,
        wall_seconds=0.001,
    )


class Crash(BaseException):
    """Stands for the process dying: nothing catches it."""


def make_evolution(
    run_dir: Path,
    *,
    structure: str = "E",
    population: int = 4,
    budget: int = 14,
    seed: int = 3,
    executor: Any = None,
    on_result: Callable[[HistoryRow], None] | None = None,
    evaluate: Callable[[Candidate, Job], Outcome] = fake_evaluate,
    store: RunStore | None = None,
) -> Evolution:
    ga = GAConfig(population, budget, selection=Roulette(), replacement=ReplaceWorst(),
                  schedule=SCHEDULE)
    return Evolution(
        store or RunStore(run_dir),
        ga=ga,
        strategy=Evolve(ga) if structure == "E" else RandomStructures(),
        job=Job(PhysicsParams(), EnvConfig(), PPO(), str(run_dir), f"{structure}+L"),
        executor=executor or SerialExecutor(),
        seed=seed,
        on_result=on_result,
        evaluate=evaluate,
    )


def read_history(run_dir: Path) -> pd.DataFrame:
    """history.csv with empty text cells as "" (and a failed robot's fitness as NaN)."""
    text = {column: str for column in ("parents", "replaced", "error")}
    history = pd.read_csv(run_dir / "history.csv", dtype=text, keep_default_na=False)
    for column in ("fitness", "threshold"):
        history[column] = pd.to_numeric(history[column], errors="coerce")
    return history


def comparable(history: pd.DataFrame) -> pd.DataFrame:
    """The history without wall times, in birth order."""
    return history.drop(columns=["wall_seconds"]).sort_values("birth").reset_index(drop=True)


def check_steady_state(run_dir: Path, population_size: int, robot_budget: int, seed: int) -> None:
    """Replay history.csv by the paper's rules; every recorded decision must match."""
    history = read_history(run_dir)
    assert sorted(history["birth"]) == list(range(robot_budget)), "births lost or repeated"
    assert history["name"].is_unique
    robots = {p.stem for p in (run_dir / "robots").glob("*.json")}
    assert robots == set(history["name"]), "robot files and history rows differ"
    population: dict[str, float] = {}
    for row in history.itertuples():
        assert row.seed == evaluation_seed(seed, row.birth)
        assert row.budget == SCHEDULE.budget(row.birth, population_size, robot_budget)
        ok = not row.error and math.isfinite(row.fitness)
        if isinstance(row.parents, str) and row.parents:
            for parent in row.parents.split(";"):
                assert parent in population, f"{row.name}: parent {parent} not in population"
        if len(population) < population_size and not row.parents:
            assert math.isnan(row.threshold), f"{row.name}: an initial robot beats nothing"
            assert row.accepted == ok and not row.replaced
            if ok:
                population[row.name] = row.fitness
        else:
            worst = min(population, key=lambda n: population[n])
            assert row.threshold == population[worst], f"{row.name}: bred against the minimum"
            accepted = ok and row.fitness > population[worst]
            assert row.accepted == accepted, f"{row.name}: accepted should be {accepted}"
            if accepted:
                assert row.replaced == worst
                del population[worst]
                population[row.name] = row.fitness
            else:
                assert not row.replaced
        if population:
            assert row.population_best == pytest.approx(max(population.values()))
            assert row.population_mean == pytest.approx(np.mean(list(population.values())))
        assert len(population) <= population_size
    assert len(population) == population_size
    saved = json.loads((run_dir / "population.json").read_text())["population"]
    assert {m["name"]: m["fitness"] for m in saved} == pytest.approx(population)
    summary = json.loads((run_dir / "summary.json").read_text())
    done = history[history["error"] == ""]
    assert summary["complete"] and summary["robots_evaluated"] == robot_budget
    assert summary["best_fitness"] == pytest.approx(done["fitness"].max())


# ---- the loop's rules ----------------------------------------------------------------------


def test_evolution_follows_the_steady_state_rules(tmp_path: Path) -> None:
    summary = make_evolution(tmp_path, population=5, budget=40).run()
    check_steady_state(tmp_path, 5, 40, seed=3)
    history = read_history(tmp_path)
    offspring = history[history["birth"] >= 5]
    assert (offspring["operator"] == "crossover").all()
    assert offspring["parents"].str.count(";").eq(1).all(), "two parents per offspring"
    assert 0 < offspring["accepted"].sum() < len(offspring), "replacement is a real choice"
    assert summary.accept_rate == pytest.approx(offspring["accepted"].mean())


def test_random_structure_strategy_has_no_parents(tmp_path: Path) -> None:
    make_evolution(tmp_path, structure="R", population=4, budget=20).run()
    check_steady_state(tmp_path, 4, 20, seed=3)
    history = read_history(tmp_path)
    assert (history["parents"] == "").all() and (history["operator"] == "random").all()
    assert (history["method"] == "R+L").all()


class NoCrossover:
    """A structure strategy ``E`` whose breeding always fails."""

    code = "E"

    def initial(self, rng: np.random.Generator) -> Offspring:
        return RandomStructures().initial(rng)

    def breed(self, population: Any, rng: np.random.Generator) -> Offspring:
        raise OperatorError("no crossover site")


def test_failed_breeding_falls_back_to_a_random_robot(tmp_path: Path) -> None:
    run = make_evolution(tmp_path, population=3, budget=8)
    run.strategy = NoCrossover()
    assert run.run().complete
    check_steady_state(tmp_path, 3, 8, seed=3)
    history = read_history(tmp_path)
    assert (history["operator"][3:] == "random-fallback").all()
    assert (history["parents"] == "").all()


def test_the_same_seed_gives_the_same_run(tmp_path: Path) -> None:
    make_evolution(tmp_path / "a", seed=8).run()
    make_evolution(tmp_path / "b", seed=8).run()
    make_evolution(tmp_path / "c", seed=9).run()
    a, b, c = (comparable(read_history(tmp_path / x)) for x in "abc")
    pd.testing.assert_frame_equal(a, b)
    assert list(a["name"]) != list(c["name"])


def test_a_robot_that_finished_no_episode_is_not_silently_named_best(tmp_path: Path) -> None:
    def unfinished_when_fit(candidate: Candidate, job: Job) -> Outcome:
        outcome = fake_evaluate(candidate, job)  # fitness above 0: no episode ended
        return dataclasses.replace(outcome, episodes=0 if outcome.fitness > 0 else 3)

    summary = make_evolution(tmp_path / "some", evaluate=unfinished_when_fit).run()
    history = read_history(tmp_path / "some")
    finished = history[history["episodes"] > 0]
    assert (history["episodes"] == 0).any() and len(finished)
    assert summary.best_fitness == finished["fitness"].max() and not summary.best_note
    summary = make_evolution(tmp_path / "none", evaluate=lambda candidate, job: dataclasses.replace(
        fake_evaluate(candidate, job), episodes=0)).run()
    assert summary.best_robot and "no robot finished an episode" in summary.best_note


def test_a_failing_evaluation_is_recorded_and_the_run_goes_on(tmp_path: Path) -> None:
    def flaky(candidate: Candidate, job: Job) -> Outcome:
        if candidate.birth in (1, 6):
            raise RuntimeError(f"simulated crash of {candidate.name}")
        return fake_evaluate(candidate, job)

    summary = make_evolution(tmp_path, population=4, budget=12, evaluate=flaky).run()
    history = read_history(tmp_path).set_index("birth")
    for birth in (1, 6):
        row = history.loc[birth]
        assert "simulated crash" in row["error"], row["error"]
        assert math.isnan(row["fitness"]) and not row["accepted"]
    assert summary.failed == 2 and summary.complete
    # The failed initial robot left a gap that the next random robot filled.
    assert history.loc[4, "operator"] == "random" and history.loc[4, "accepted"]
    check_steady_state(tmp_path, 4, 12, seed=3)


def broken_learner(*args: Any, **kwargs: Any) -> Any:
    raise FloatingPointError("policy diverged\nin batch 3")


def test_an_error_inside_training_is_one_line_and_its_traceback_a_file(tmp_path: Path) -> None:
    summary = make_evolution(tmp_path, population=2, budget=3,
                             evaluate=functools.partial(evaluate, learner=broken_learner)).run()
    history = read_history(tmp_path)
    assert len(history) == 3 and history["fitness"].isna().all()
    assert summary.failed == 3 and summary.best_robot is None and summary.complete
    assert len((tmp_path / "history.csv").read_text().splitlines()) == 1 + 3, "one line a row"
    for name, error in zip(history["name"], history["error"], strict=True):
        log = f"evals/{name}.log"
        assert error == f"FloatingPointError: policy diverged (traceback in {log})", error
        traceback = (tmp_path / log).read_text()
        assert traceback.startswith("Traceback (most recent call last):"), traceback
        assert "in broken_learner" in traceback
        assert traceback.rstrip().endswith("FloatingPointError: policy diverged\nin batch 3")


# A worker that dies: tests/test_lost_work.py.


# ---- resume after a crash at any point -----------------------------------------------------


def crash_on_call(k: int, fn: Callable[..., Any], after: bool = False) -> Callable[..., Any]:
    """``fn`` that crashes on its k-th call (before it runs, or after with ``after``)."""
    calls = 0

    def wrapper(*args: Any, **kwargs: Any) -> Any:
        nonlocal calls
        calls += 1
        if calls == k and not after:
            raise Crash(f"crash before call {k} of {fn.__name__}")
        result = fn(*args, **kwargs)
        if calls == k:
            raise Crash(f"crash after call {k} of {fn.__name__}")
        return result

    return wrapper


class RobotFileCrash(RunStore):
    """A store that crashes right after writing its k-th robot file."""

    def __init__(self, root: Path, k: int) -> None:
        super().__init__(root)
        self.k, self.calls = k, 0

    def save_robot(self, name: str, robot: Any) -> Path:
        path = super().save_robot(name, robot)
        self.calls += 1
        if self.calls == self.k:
            raise Crash(f"crash after robot file {self.k}")
        return path


class StateWriteCrash(RunStore):
    """A store that crashes on its k-th state.json: right after writing it, or with
    ``torn`` halfway through, leaving half of it in its temporary file."""

    def __init__(self, root: Path, k: int, torn: bool = False) -> None:
        super().__init__(root)
        self.k, self.torn, self.calls = k, torn, 0

    def write_state(self, data: dict[str, Any]) -> Path:
        self.calls += 1
        if self.calls == self.k and self.torn:
            text = json.dumps(data)
            self.layout.state.with_suffix(".json.tmp").write_text(text[: len(text) // 2])
            raise Crash("crash while writing the state")
        path = super().write_state(data)
        if self.calls == self.k:
            raise Crash("crash after writing the state")
        return path


BUDGET = 10
POPULATION = 4
# A run of BUDGET robots writes state.json once per submission and once per result.
STATE_WRITES = 2 * BUDGET
CRASHES: dict[str, Callable[[Path, int], dict[str, Any]]] = {  # a faulty evaluate or store
    "during-evaluation": lambda run_dir, k: {"evaluate": crash_on_call(k, fake_evaluate)},
    "after-evaluation": lambda run_dir, k: {
        "evaluate": crash_on_call(k, fake_evaluate, after=True)},
    "writing-robot-file": lambda run_dir, k: {"store": RobotFileCrash(run_dir, k)},
    "writing-state": lambda run_dir, k: {"store": StateWriteCrash(run_dir, 2 * k, torn=True)},
    "after-state": lambda run_dir, k: {"store": StateWriteCrash(run_dir, 2 * k)},
    "after-submit-state": lambda run_dir, k: {"store": StateWriteCrash(run_dir, 2 * k - 1)},
}


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory: pytest.TempPathFactory) -> Path:
    run_dir = tmp_path_factory.mktemp("uninterrupted")
    make_evolution(run_dir, population=POPULATION, budget=BUDGET).run()
    return run_dir


def same_run_files(a: Path, b: Path) -> None:
    pd.testing.assert_frame_equal(comparable(read_history(a)), comparable(read_history(b)))
    for name in ("population.json",):
        assert json.loads((a / name).read_text()) == json.loads((b / name).read_text())
    assert sorted(p.name for p in (a / "robots").iterdir()) == sorted(
        p.name for p in (b / "robots").iterdir()
    )
    sa, sb = (json.loads((d / "summary.json").read_text()) for d in (a, b))
    for key in ("wall_seconds", "steps_per_second"):
        sa.pop(key), sb.pop(key)
    assert sa == sb


@pytest.mark.parametrize("k", [1, POPULATION, POPULATION + 1, BUDGET])
@pytest.mark.parametrize("where", CRASHES)
def test_resume_after_a_crash_gives_the_uninterrupted_run(
    tmp_path: Path, uninterrupted: Path, where: str, k: int
) -> None:
    crashing = make_evolution(tmp_path, population=POPULATION, budget=BUDGET,
                              **CRASHES[where](tmp_path, k))
    with pytest.raises(Crash):
        crashing.run()
    # As evo/main.py does: resume when a state was saved, else start again.
    if (tmp_path / "state.json").exists():
        resumed = make_evolution(tmp_path, population=POPULATION, budget=BUDGET, seed=99)
        resumed.resume()  # the seed comes from the saved state, not the constructor
    else:
        resumed = make_evolution(tmp_path, population=POPULATION, budget=BUDGET)
    resumed.run()
    same_run_files(uninterrupted, tmp_path)
    assert not list(tmp_path.glob("*.tmp")), "a temporary file outlived the run"


def test_resume_of_a_finished_run_evaluates_nothing(
    tmp_path: Path, uninterrupted: Path
) -> None:
    make_evolution(tmp_path, population=POPULATION, budget=BUDGET).run()
    again = make_evolution(tmp_path, population=POPULATION, budget=BUDGET,
                           evaluate=crash_on_call(1, fake_evaluate))
    again.resume()
    assert again.run().complete
    same_run_files(uninterrupted, tmp_path)


def test_resume_refuses_a_directory_without_a_readable_state(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="no saved state"):
        make_evolution(tmp_path).resume()
    (tmp_path / "state.json").write_text('{"version": 1, "seed": 0')
    with pytest.raises(ValueError, match="unreadable run state"):
        make_evolution(tmp_path).resume()


# ---- python evo/main.py end to end ---------------------------------------------------------

TINY = [
    "+exp=smoke",
    "ga.population_size=3",
    "ga.robot_budget=6",
    "ga.schedule.initial=256",
    "ga.schedule.first=256",
    "ga.schedule.last=768",
    "learner.num_envs=4",
    "learner.rollout_steps=64",
    "learner.epochs=1",
    "learner.minibatch_size=128",
    "learner.hidden=[32,32]",
    "env.task.t_max=40",
]
"""A real but tiny evolution: 6 robots of a few hundred env steps each."""

ENV = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl"), "COLUMNS": "120"}

sys.path.insert(0, str(REPO / "bench"))
from kill_resume import DRIVER  # noqa: E402 - the fault-injection driver of the harness


def main_cmd(*args: str) -> list[str]:
    return [sys.executable, str(REPO / "evo" / "main.py"), *args]


def run(cmd: list[str], cwd: Path, timeout: float = 240) -> subprocess.CompletedProcess[str]:
    return subprocess.run(cmd, cwd=cwd, env=ENV, capture_output=True, text=True, timeout=timeout)


def killed(point: str, k: int, *args: str, cwd: Path) -> None:
    done = run([sys.executable, str(DRIVER), point, str(k), *args], cwd)
    assert done.returncode == -signal.SIGKILL, (point, k, done.returncode, done.stderr[-2000:])


def check_run_dir(run_dir: Path, robot_budget: int) -> pd.DataFrame:
    """Everything a finished run directory must hold."""
    for name in ("config.yaml", "state.json", "history.csv", "population.json", "summary.json"):
        assert (run_dir / name).is_file(), f"{name} missing"
    history = read_history(run_dir)
    assert sorted(history["birth"]) == list(range(robot_budget)), "births lost or repeated"
    assert (history["error"] == "").all(), list(history["error"])
    assert np.isfinite(history["fitness"]).all(), list(history["fitness"])
    robots = {p.stem for p in (run_dir / "robots").glob("*.json")}
    assert robots == set(history["name"])
    for name in history["name"]:
        robot = load_robot(run_dir / "robots" / f"{name}.json")
        assert name == robot.name or name.startswith(f"{robot.name}-"), name
        assert (run_dir / "evals" / f"{name}.pt").is_file(), f"{name}.pt missing"
        assert (run_dir / "evals" / f"{name}.csv").is_file(), f"{name}.csv missing"
    state = json.loads((run_dir / "state.json").read_text())
    assert state["next_birth"] == robot_budget and state["pending"] == []
    assert json.loads((run_dir / "summary.json").read_text())["complete"]
    assert not list(run_dir.glob("*.tmp")), "a temporary file outlived the run"
    return history


@pytest.mark.slow
def test_sigkilled_serial_run_resumes_to_the_uninterrupted_history(
    tmp_path: Path, serial_reference: Path
) -> None:
    run_dir = tmp_path / "run"
    start = [*TINY, "executor=serial", f"hydra.run.dir={run_dir}"]
    # Killed mid-write of the state (after the first result: the 4th write, after the new
    # run's empty state, the first submission and the first result), then during the
    # training of the second robot after resuming, then just after the final state was saved.
    killed("state-write", 4, *start, cwd=tmp_path)
    assert len(read_history(run_dir)) == 1
    killed("checkpoint", 2, f"resume={run_dir}", cwd=tmp_path)
    assert len(read_history(run_dir)) == 2
    (in_flight,) = json.loads((run_dir / "state.json").read_text())["pending"]
    assert (run_dir / "evals" / f"{in_flight['name']}.csv").is_file()
    assert not (run_dir / "evals" / f"{in_flight['name']}.pt").exists(), "killed mid-evaluation"
    killed("after-final-state", 6, f"resume={run_dir}", cwd=tmp_path)
    assert len(read_history(run_dir)) == 5, "history.csv lags the state by one row"
    done = run(main_cmd(f"resume={run_dir}"), tmp_path)
    assert done.returncode == 0, done.stderr[-3000:]
    history = check_run_dir(run_dir, robot_budget=6)
    pd.testing.assert_frame_equal(comparable(history), comparable(read_history(serial_reference)))


def wait_for_rows(path: Path, rows: int, proc: subprocess.Popen[str], timeout: float) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        assert proc.poll() is None, "the run ended before it could be killed"
        if path.is_file() and len(path.read_text().splitlines()) - 1 >= rows:
            return
        time.sleep(0.05)
    raise AssertionError(f"no {rows} rows in {path} after {timeout} s")


@pytest.mark.slow
@pytest.mark.parametrize("executor", ["local"])
@pytest.mark.long  # the pool's lost work: test_lost_work; serial: the test above
def test_sigkilled_run_resumes_with_every_robot_once(tmp_path: Path, executor: str) -> None:
    # The whole process group (main process and its workers) is killed from outside
    # while robots are in training, as an out-of-memory killer or a cluster would.
    run_dir = tmp_path / "run"
    cmd = main_cmd(*TINY, f"executor={executor}", f"hydra.run.dir={run_dir}")
    with subprocess.Popen(
        cmd,
        cwd=tmp_path,
        env=ENV,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    ) as proc:
        try:
            wait_for_rows(run_dir / "history.csv", 2, proc, timeout=120)
            os.killpg(proc.pid, signal.SIGKILL)
        finally:
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    assert proc.returncode == -signal.SIGKILL
    state = json.loads((run_dir / "state.json").read_text())
    assert len(state["history"]) < 6, "killed too late to test anything"
    done = run(main_cmd(f"resume={run_dir}"), tmp_path)
    assert done.returncode == 0, done.stderr[-3000:]
    check_run_dir(run_dir, robot_budget=6)
