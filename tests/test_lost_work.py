"""Lost work is run again, failed work is recorded: a local-pool worker SIGKILLed in the
middle of an evaluation and a Ray node lost while it holds one cost the run nothing (the
history equals the uninterrupted run's, no robot lost or evaluated twice), and a robot
that kills its worker every time ends ``failed`` after ``executor.retries``.

The faults come from the evaluation function the run is given (``Evolution(evaluate=)``,
the seam every in-process test of the loop uses): the functions below are importable
module-level functions, so the pool's and Ray's workers run them as they would
``evo.evaluation.evaluate``. Each attempt leaves a marker file in ``<run>/attempts/``
(``<birth>-<pid>.start``, ``.done``) by which the test finds the worker to kill and
counts the attempts.
"""

from __future__ import annotations

import os
import signal
import threading
import time
from collections.abc import Callable
from pathlib import Path

import faults
import pandas as pd
import pytest
from test_evolution import comparable, fake_evaluate, make_evolution, read_history

from evo.components.executors import EvaluationLost, LocalExecutor
from evo.evaluation import Job, Outcome
from evo.run.records import Candidate

REPO = Path(__file__).resolve().parents[1]
POPULATION, BUDGET = 3, 6
VICTIM, CRASHER = 2, 4
"""Births whose evaluations the faults hit: the victim's worker is killed once from
outside, the crasher's evaluation kills its own worker every time."""


def marked_evaluate(candidate: Candidate, job: Job) -> Outcome:
    """``fake_evaluate`` that leaves a start and a done marker. The victim's first attempt
    never ends by itself: it waits to be killed, so the kill lands in the middle of its
    evaluation however slow the machine is."""
    attempts = Path(job.run_dir) / "attempts"
    attempts.mkdir(exist_ok=True)
    mark = attempts / f"{candidate.birth}-{os.getpid()}"
    mark.with_suffix(".start").touch()
    if candidate.birth == VICTIM and len(list(attempts.glob(f"{VICTIM}-*.start"))) == 1:
        faults.wait_to_be_killed()
    outcome = fake_evaluate(candidate, job)
    mark.with_suffix(".done").touch()
    return outcome


def crashing_evaluate(candidate: Candidate, job: Job) -> Outcome:
    """The crasher's evaluation kills its own worker process, every time (as a MuJoCo
    crash on one structure would); the others are ``marked_evaluate``."""
    if candidate.birth == CRASHER:
        attempts = Path(job.run_dir) / "attempts"
        (attempts / f"{candidate.birth}-{os.getpid()}.start").touch()
        os.kill(os.getpid(), signal.SIGKILL)
    return marked_evaluate(candidate, job)


def crasher_fails(candidate: Candidate, job: Job) -> Outcome:
    """The uninterrupted run's evaluation: the crasher is a failed evaluation."""
    if candidate.birth == CRASHER:
        return Outcome(candidate.birth, candidate.name, error="crashed")
    return fake_evaluate(candidate, job)


def attempts(run_dir: Path, suffix: str) -> dict[int, int]:
    """How many markers with ``suffix`` each birth left."""
    births = [int(p.stem.split("-")[0]) for p in (run_dir / "attempts").glob(f"*{suffix}")]
    return {b: births.count(b) for b in sorted(set(births))}


def wait_for_start(run_dir: Path, birth: int, timeout: float = 300) -> int:
    """The PID of the worker that started the evaluation of ``birth``, once one has."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        found = list((run_dir / "attempts").glob(f"{birth}-*.start"))
        if found:
            return int(found[0].stem.split("-")[1])
        time.sleep(0.01)
    raise AssertionError(f"birth {birth} never started")


def when_started(run_dir: Path, birth: int, act: Callable[[int], None],
                 errors: list[BaseException]) -> threading.Thread:
    """A thread that calls ``act(pid)`` once the evaluation of ``birth`` has started."""

    def watch() -> None:
        try:
            act(wait_for_start(run_dir, birth))
        except BaseException as err:  # noqa: BLE001 - reported by the test
            errors.append(err)

    thread = threading.Thread(target=watch, daemon=True)
    thread.start()
    return thread


def uninterrupted(run_dir: Path, evaluate: Callable[[Candidate, Job], Outcome]) -> pd.DataFrame:
    """The history of the same evolution run serially, without faults."""
    make_evolution(run_dir, population=POPULATION, budget=BUDGET, evaluate=evaluate).run()
    return comparable(read_history(run_dir))


def test_a_pool_worker_sigkilled_mid_evaluation_loses_nothing_and_a_crasher_fails(
    tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    reference = uninterrupted(tmp_path / "reference", crasher_fails)
    run_dir = tmp_path / "run"
    errors: list[BaseException] = []
    killer = when_started(run_dir, VICTIM, lambda pid: os.kill(pid, signal.SIGKILL), errors)
    summary = make_evolution(run_dir, population=POPULATION, budget=BUDGET,
                             executor=LocalExecutor(workers=1, retries=1),
                             evaluate=crashing_evaluate).run()
    killer.join()
    assert not errors, errors
    assert summary.complete and summary.failed == 1
    history = comparable(read_history(run_dir))
    pd.testing.assert_frame_equal(history.drop(columns="error"), reference.drop(columns="error"))
    assert history["error"].tolist() == [
        "evaluation lost: lost 2 time(s), the last because its worker process was killed by "
        "SIGKILL (executor.retries = 1)" if birth == CRASHER else "" for birth in range(BUDGET)]
    assert attempts(run_dir, ".done") == {b: 1 for b in range(BUDGET) if b != CRASHER}, \
        "a robot evaluated twice, or lost"
    assert attempts(run_dir, ".start") == {b: 1 + (b in (VICTIM, CRASHER)) for b in range(BUDGET)}
    log = capfd.readouterr().err.splitlines()
    lost = "lost (its worker process was killed by SIGKILL); submitted again with the same seed"
    assert [line for line in log if "submitted again" in line] == [
        f"evaluation of {history.loc[VICTIM, 'name']} (birth {VICTIM}) {lost} (retry 1 of 1)",
        f"evaluation of {history.loc[CRASHER, 'name']} (birth {CRASHER}) {lost} (retry 1 of 1)",
    ], log


def test_a_dead_worker_spends_only_its_own_evaluations_retries(tmp_path: Path) -> None:
    """Python's pool fails every evaluation in flight when one worker dies; the others
    are submitted again without spending a retry."""
    executor = LocalExecutor(workers=2, retries=0)
    try:
        started, release = tmp_path / "started", tmp_path / "release"
        # The innocent runs until released; the culprit, submitted once the innocent
        # has started (so it runs in the other worker), kills its worker: the innocent
        # is in flight when the pool breaks.
        innocent = executor.submit(faults.hold, str(started), str(release))
        while not started.exists() and not innocent.done():
            time.sleep(0.01)
        culprit = executor.submit(faults.die, str(started))
        with pytest.raises(EvaluationLost, match="killed by SIGKILL"):
            culprit.result(timeout=300)
        release.touch()
        assert innocent.result(timeout=300) > 0, "resubmitted, not failed"
    finally:
        executor.shutdown()


@pytest.mark.slow
def test_a_ray_node_lost_mid_evaluation_loses_nothing(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capfd: pytest.CaptureFixture[str]
) -> None:
    """A two-node Ray cluster on this machine: the head has no CPU, so every evaluation
    runs on the second node; that node is killed (its raylet and workers) while it holds
    the victim's evaluation, and a fresh node joins, as a preempted node is replaced.

    The evolution runs in a thread: Ray starts a node only from the main thread."""
    ray = pytest.importorskip("ray", reason="the ray extra is not installed")
    from ray.cluster_utils import Cluster

    from evo.components.executors import RayExecutor

    paths = [str(REPO), str(REPO / "tests"), str(REPO / "bench"), os.environ.get("PYTHONPATH", "")]
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(p for p in paths if p))  # the workers'
    # A lost node is noticed within seconds; a node starting on a busy machine is not
    # declared dead by one late heartbeat.
    cluster = Cluster(initialize_head=True, head_node_args={
        "num_cpus": 0, "include_dashboard": False,
        "_system_config": {"health_check_initial_delay_ms": 0, "health_check_period_ms": 1000,
                           "health_check_failure_threshold": 5}})
    run_dir, outcome = tmp_path / "run", []
    try:
        second = cluster.add_node(num_cpus=1)
        ray.init(address=cluster.address, include_dashboard=False, log_to_driver=False,
                 configure_logging=False)
        executor = RayExecutor(address=cluster.address)
        assert executor.workers == 1
        evolution = make_evolution(run_dir, population=POPULATION, budget=BUDGET,
                                   executor=executor, evaluate=marked_evaluate)
        runner = threading.Thread(target=lambda: outcome.append(evolution.run()), daemon=True)
        runner.start()
        wait_for_start(run_dir, VICTIM)
        cluster.remove_node(second, allow_graceful=False)
        cluster.add_node(num_cpus=1)
        runner.join(timeout=600)
        assert not runner.is_alive(), "the evolution did not end after the node was replaced"
    finally:
        ray.shutdown()
        cluster.shutdown()
    (summary,) = outcome
    assert summary.complete and summary.failed == 0
    reference = uninterrupted(tmp_path / "reference", fake_evaluate)
    pd.testing.assert_frame_equal(comparable(read_history(run_dir)), reference)
    assert attempts(run_dir, ".done") == dict.fromkeys(range(BUDGET), 1), "evaluated twice"
    assert attempts(run_dir, ".start")[VICTIM] == 2, "the lost evaluation ran again"
    log = capfd.readouterr().err
    assert "lost (NodeDiedError" in log and "(retry 1 of 3)" in log, log[-3000:]
