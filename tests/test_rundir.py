"""Run directories that cannot be lost, shared or silently overwritten, and clean shutdown.

End to end through ``python evo/main.py`` in subprocesses with real (tiny) training:

* a resume that fails leaves every byte of the directory as it was;
* ``resume=`` of a directory without ``state.json`` refuses and says what is there;
* one process owns a run directory; a second is refused with the holder's PID, and a
  SIGKILLed holder does not block the next resume;
* SIGTERM and SIGINT stop a run with one line and exit 143 or 130, leave no worker
  process alive, and the resumed run is the uninterrupted one (serial);
* SIGKILL of the main process alone takes its workers with it, even a worker whose
  cleanup no signal reaches;
* a full disk at each kind of write (state, history, robot file, policy, MCAP and rerun
  recordings) stops the run with one line and exit 1, and the resumed run is the
  uninterrupted one;
* ``resume=DIR ga.robot_budget=N`` ends a run early or extends a finished one (the run of
  N robots), and refuses an N below the robots born or one the schedule would give them
  other budgets under.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest
from omegaconf import DictConfig, OmegaConf
from test_evolution import (
    ENV,
    REPO,
    TINY,
    check_run_dir,
    comparable,
    killed,
    main_cmd,
    read_history,
    run,
)

from evo.components.ga import GAConfig
from evo.config import ConfigError, typed
from evo.edge import typed_config
from evo.main import _state_to_continue, check_robot_budget
from evo.record import mcap_file, rrd
from evo.robot.tree import Robot
from evo.run.files import RunDirectoryBusy, RunLock, is_locked
from evo.run.records import Candidate, HistoryRow
from evo.run.store import RunStore, SavedState, rng_state

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from kill_resume import kill_and_resume, unreadable_files  # noqa: E402

SLOWER = [*TINY, "ga.schedule.initial=4096", "ga.schedule.first=4096", "ga.schedule.last=4096"]
"""TINY with a few seconds per robot: long enough to be caught in the middle."""


def tree_hash(folder: Path) -> dict[str, str]:
    """Every file under ``folder`` (relative path) with the SHA-256 of its bytes."""
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}




def truncate_state(d: Path) -> None:
    (d / "state.json").write_text((d / "state.json").read_text()[:2000])


def drop_a_robot(d: Path) -> None:
    next((d / "robots").glob("*.json")).unlink()


def history_of_another_run(d: Path) -> None:
    history = pd.read_csv(d / "history.csv")
    history.loc[0, "name"] = "robot-00000000"
    history.to_csv(d / "history.csv", index=False)


def bad_seed(d: Path) -> None:
    text = (d / "config.yaml").read_text()
    (d / "config.yaml").write_text(text.replace("\nseed: 0\n", "\nseed: -1\n"))


def inconsistent_births(d: Path) -> None:
    state = json.loads((d / "state.json").read_text())
    state["next_birth"] += 1
    (d / "state.json").write_text(json.dumps(state))


BREAKAGES: dict[str, tuple[Callable[[Path], None], str]] = {
    "truncated state": (truncate_state, "unreadable run state"),
    "missing state": (lambda d: (d / "state.json").unlink(), "has no state.json"),
    "missing robot": (drop_a_robot, "needs robot"),
    "foreign history.csv": (history_of_another_run, "do not match"),
    "bad seed": (bad_seed, "seed: expected a non-negative integer, got -1"),
    "inconsistent births": (inconsistent_births, "inconsistent run state"),
}


def resume_checks(run_dir: Path) -> None:
    """What ``resume=run_dir`` checks before it writes anything: the config it was
    started with, then the saved state (``evo/main.py``'s own functions, in-process)."""
    typed_config(OmegaConf.load(run_dir / "config.yaml"))
    _state_to_continue(RunStore(run_dir), resuming=True)


@pytest.mark.parametrize("breakage", sorted(BREAKAGES))
def test_a_failing_resume_leaves_every_byte_as_it_was(
    serial_reference: Path, tmp_path: Path, breakage: str
) -> None:
    run_dir = tmp_path / "run"
    shutil.copytree(serial_reference, run_dir)
    damage, message = BREAKAGES[breakage]
    damage(run_dir)
    before = tree_hash(run_dir)
    with pytest.raises(ConfigError, match=re.escape(message)):
        resume_checks(run_dir)
    assert tree_hash(run_dir) == before, "a failed resume changed the run directory"


@pytest.mark.slow
def test_a_failing_resume_on_the_command_line_is_one_line_and_changes_nothing(
    serial_reference: Path, tmp_path: Path
) -> None:
    run_dir = tmp_path / "run"
    shutil.copytree(serial_reference, run_dir)
    damage, message = BREAKAGES["truncated state"]
    damage(run_dir)
    before = tree_hash(run_dir)
    done = run(main_cmd(f"resume={run_dir}"), tmp_path)
    assert done.returncode == 2, done.stderr[-2000:]
    assert message in done.stderr and "Traceback" not in done.stderr, done.stderr
    assert tree_hash(run_dir) == before, "a failed resume changed the run directory"


@pytest.mark.slow
@pytest.mark.long  # in-process: test_a_failing_resume_leaves_every_byte_as_it_was
def test_resume_without_state_says_what_is_there(serial_reference: Path, tmp_path: Path) -> None:
    run_dir = tmp_path / "run"
    shutil.copytree(serial_reference, run_dir)
    (run_dir / "state.json").unlink()
    done = run(main_cmd(f"resume={run_dir}"), tmp_path)
    assert done.returncode == 2
    assert "history.csv with 6 row(s)" in done.stderr and "robots/ with 6" in done.stderr
    assert "hydra.run.dir" in done.stderr, "says how to start afresh"
    assert len(read_history(run_dir)) == 6, "the old run is untouched"


def test_the_lock_refuses_a_second_holder_and_is_freed_when_released(tmp_path: Path) -> None:
    first = RunLock(tmp_path).acquire()
    first.claim()
    assert is_locked(tmp_path)
    with pytest.raises(RunDirectoryBusy, match=f"PID {os.getpid()}"):
        RunLock(tmp_path).acquire()
    first.release()
    assert not is_locked(tmp_path)
    with RunLock(tmp_path):
        assert is_locked(tmp_path)


def signal_self() -> None:
    os.kill(os.getpid(), signal.SIGINT)


class McapOpened(mcap_file.McapRecorder):
    """An MCAP recorder that signals as soon as its file is open (not yet handed over)."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        signal_self()


class RerunOpened(rrd.RerunRecorder):
    """A rerun recorder that signals as soon as its file is open (not yet handed over)."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        signal_self()


class McapClosing(mcap_file.McapRecorder):
    """An MCAP recorder that signals as it starts to finish its file."""

    def _close(self, summary: Mapping[str, Any]) -> None:
        signal_self()
        super()._close(summary)


SIGNAL_AT = {  # the recorders an evaluation opens, one of them signalling
    "opening the MCAP file": (McapOpened, rrd.RerunRecorder),
    "opening the rerun file": (mcap_file.McapRecorder, RerunOpened),
    "closing the MCAP file": (McapClosing, rrd.RerunRecorder),
}


@pytest.mark.parametrize("moment", list(SIGNAL_AT))
def test_a_signal_while_recordings_open_or_close_leaves_them_readable(
    tmp_path: Path, moment: str
) -> None:
    """A real SIGINT, sent by the process to itself at ``moment``, is held back until
    the files are safe: the evaluation then stops and every recording reads back."""
    from test_early_rejection import NEAR, TINY_LEARNER, real_candidate

    from evo.evaluation import Job, evaluate
    from evo.interrupt import Interrupted, handle_signals
    from evo.record import RecordConfig, Recorder, Recorders, read_metadata
    from evo.robot.builder import PhysicsParams

    mcap, rerun = SIGNAL_AT[moment]

    def open_recorder(config: RecordConfig, directory: str | Path, name: str, model: Any,
                      metadata: Mapping[str, Any]) -> Recorder:
        """Both files, as ``evo.record.open_recorder`` opens them, by these classes."""
        meta, folder = {"name": name, **metadata}, Path(directory)
        return Recorders([mcap(folder / f"{name}.mcap", model, meta),
                          rerun(folder / f"{name}.rrd", model, meta)])

    candidate = real_candidate(float("-inf"))
    with handle_signals(), pytest.raises(Interrupted):
        evaluate(candidate, Job(PhysicsParams(), NEAR, TINY_LEARNER, str(tmp_path)),
                 open_recorder=open_recorder)
    files = sorted(p.name for p in (tmp_path / "evals").iterdir())
    assert f"{candidate.name}.mcap" in files and f"{candidate.name}.rrd" in files, files
    assert unreadable_files(tmp_path) == []
    status = read_metadata(tmp_path / "evals" / f"{candidate.name}.mcap").get("status")
    assert status == ("complete" if moment.startswith("closing") else "failed")


def test_a_signal_that_cleanup_turns_into_another_error_is_not_a_failed_robot(
    tmp_path: Path,
) -> None:
    """A real SIGINT during training, which library code unwinding from it replaces with an
    ordinary error (as tensordict's ``__bool__`` can in a ``finally``), still stops the
    evaluation as an interrupt: the robot is pending for the resume, not recorded failed."""
    from test_early_rejection import NEAR, TINY_LEARNER, real_candidate

    from evo.evaluation import Job, evaluate
    from evo.interrupt import Interrupted, handle_signals
    from evo.robot.builder import PhysicsParams

    ppo = TINY_LEARNER.train_function()

    def converting(robot: Robot, **kwargs: Any) -> Any:
        """The real learner, whose curve callback is unwound by such a library ``finally``."""
        on_curve = kwargs.pop("on_curve")

        def signalled(row: dict[str, float]) -> bool:
            try:
                os.kill(os.getpid(), signal.SIGINT)
                return bool(on_curve(row))
            finally:
                raise RuntimeError("Converting a tensordict to boolean value is not permitted")

        return ppo(robot, on_curve=signalled, **kwargs)

    with handle_signals(), pytest.raises(Interrupted) as stop:
        evaluate(real_candidate(float("-inf")),
                 Job(PhysicsParams(), NEAR, TINY_LEARNER, str(tmp_path)), learner=converting)
    assert stop.value.signum == signal.SIGINT
    assert isinstance(stop.value.__cause__, RuntimeError)


def children_of(pid: int) -> list[int]:
    """PIDs of the live child processes of ``pid`` (from /proc)."""
    kids = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid and fields[0] != "Z":
            kids.append(int(stat.parent.name))
    return kids


def alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


def describe(pid: int) -> str:
    """``pid``'s command line and state, for a failure message."""
    try:
        cmd = Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return f"{pid}: gone"
    return f"{pid} [{state}]: {cmd[:200]}"


def wait_until(condition: Callable[[], bool], timeout: float, what: str) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if condition():
            return
        time.sleep(0.05)
    raise AssertionError(f"not within {timeout} s: {what}")


def start(args: list[str], cwd: Path) -> subprocess.Popen[str]:
    return subprocess.Popen(main_cmd(*args), cwd=cwd, env=ENV, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True)


def rows(run_dir: Path) -> int:
    path = run_dir / "history.csv"
    return len(path.read_text().splitlines()) - 1 if path.is_file() else 0


HOLD = """
import sys, time
from pathlib import Path
from evo.run.files import RunLock
lock = RunLock(Path(sys.argv[1])).acquire()
lock.claim()
print("held", flush=True)
time.sleep(600)
"""


@pytest.mark.slow
@pytest.mark.long  # the lock in-process: test_the_lock_refuses_a_second_holder_...
def test_a_second_process_is_refused_and_a_killed_holder_does_not_block(
    serial_reference: Path, tmp_path: Path
) -> None:
    run_dir = tmp_path / "run"
    shutil.copytree(serial_reference, run_dir)
    holder = subprocess.Popen([sys.executable, "-c", HOLD, str(run_dir)], env=ENV,
                              stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    try:
        assert holder.stdout is not None and holder.stdout.readline().strip() == "held"
        for second in (main_cmd(f"resume={run_dir}"),
                       main_cmd(*TINY, "executor=serial", f"hydra.run.dir={run_dir}")):
            before = tree_hash(run_dir)
            done = run(second, tmp_path)
            assert done.returncode == 2, done.stderr[-2000:]
            assert f"{run_dir} is in use by PID {holder.pid}" in done.stderr, done.stderr
            assert "since" in done.stderr and "Traceback" not in done.stderr
            assert tree_hash(run_dir) == before, "the refused process wrote"
        holder.kill()  # SIGKILL: the kernel drops the lock
    finally:
        holder.kill()
        holder.wait()
    done = run(main_cmd(f"resume={run_dir}"), tmp_path)
    assert done.returncode == 0, done.stderr[-3000:]
    check_run_dir(run_dir, robot_budget=6)


def interrupt(args: list[str], cwd: Path, run_dir: Path, sig: int) -> tuple[int, str, list[int]]:
    """Start a run, send ``sig`` once it has a result and workers, return its exit code,
    stderr and the PIDs of the children it had."""
    proc = start(args, cwd)
    try:
        wait_until(lambda: rows(run_dir) >= 1, 120, "a first result")
        kids = children_of(proc.pid)
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    return proc.returncode, err, kids


@pytest.mark.slow
def test_sigterm_stops_the_run_cleanly_and_no_worker_outlives_it(tmp_path: Path) -> None:
    from evo.run.store import RunStore

    run_dir = tmp_path / "run"
    returncode, err, kids = interrupt(
        [*SLOWER, "executor=local", "executor.workers=2", f"hydra.run.dir={run_dir}"],
        tmp_path, run_dir, signal.SIGTERM)
    assert returncode == 143, err[-2000:]
    assert err.strip().splitlines()[-1] == (
        f"interrupted; continue with: python evo/main.py resume={run_dir}"), err[-2000:]
    assert "Traceback" not in err, err[-3000:]
    assert kids, "the run had worker processes"
    wait_until(lambda: not any(alive(k) for k in kids), 5, "every worker gone")
    saved = RunStore(run_dir).load()  # resumable: what was in flight is pending
    assert saved.history and saved.pending
    assert unreadable_files(run_dir) == [], "every recording closed, in-flight ones too"


@pytest.mark.slow
@pytest.mark.long  # SIGTERM's test covers the handler
def test_sigint_stops_the_run_with_exit_code_130(tmp_path: Path) -> None:
    run_dir = tmp_path / "run"
    returncode, err, _ = interrupt([*SLOWER, "executor=serial", f"hydra.run.dir={run_dir}"],
                                   tmp_path, run_dir, signal.SIGINT)
    assert returncode == 130 and "Traceback" not in err, err[-3000:]
    assert "interrupted; continue with: python evo/main.py resume=" in err
    assert unreadable_files(run_dir) == [], "every recording closed"


@pytest.mark.slow
@pytest.mark.long  # serial SIGKILL and resume: test_evolution
def test_a_sigtermed_serial_run_resumes_to_the_uninterrupted_history(
    tmp_path: Path, serial_reference: Path
) -> None:
    run_dir = tmp_path / "run"
    returncode, err, _ = interrupt([*TINY, "executor=serial", f"hydra.run.dir={run_dir}"],
                                   tmp_path, run_dir, signal.SIGTERM)
    assert returncode == 143 and "Traceback" not in err, err[-3000:]
    assert len(read_history(run_dir)) < 6, "stopped before the end"
    done = run(main_cmd(f"resume={run_dir}"), tmp_path)
    assert done.returncode == 0, done.stderr[-3000:]
    history = check_run_dir(run_dir, robot_budget=6)
    pd.testing.assert_frame_equal(comparable(history), comparable(read_history(serial_reference)))


@pytest.mark.slow
def test_workers_die_with_a_sigkilled_main_process(tmp_path: Path) -> None:
    run_dir = tmp_path / "run"
    proc = start([*SLOWER, "executor=local", "executor.workers=2", f"hydra.run.dir={run_dir}"],
                 tmp_path)
    try:
        wait_until(lambda: rows(run_dir) >= 1, 120, "a first result")
        kids = children_of(proc.pid)
        assert kids
        proc.kill()  # the main process alone, not its group
        proc.wait()
        # A worker killed mid-training first closes its files; on two shared cores busy
        # with other tests that takes seconds, so the bound is generous: what is tested
        # is that no worker outlives its parent, not how fast it goes.
        def survivors() -> list[int]:
            return [k for k in kids if alive(k)]

        try:
            wait_until(lambda: not survivors(), 30, "every worker gone")
        except AssertionError as late:
            raise AssertionError(f"{late}: {[describe(k) for k in survivors()]}") from None
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


ORPHAN = """
import os, signal, subprocess, sys, time
if sys.argv[1] == "worker":
    import evo.interrupt
    evo.interrupt.worker_init(os.getppid(), grace_s=1.0)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)  # a cleanup that no signal reaches
    print("ready", flush=True)
    time.sleep(120)
else:
    worker = subprocess.Popen([sys.executable, "-c", sys.argv[2], "worker"],
                              stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    assert worker.stdout is not None and worker.stdout.readline() == "ready\\n"
    print(worker.pid, flush=True)
    os._exit(0)  # the parent dies; its worker is left
"""


def test_a_worker_deaf_to_signals_still_dies_with_its_parent() -> None:
    parent = subprocess.run([sys.executable, "-c", ORPHAN, "parent", ORPHAN], env=ENV, cwd=REPO,
                            capture_output=True, text=True, timeout=60)
    assert parent.returncode == 0, parent.stderr[-3000:]
    worker = int(parent.stdout)
    try:
        wait_until(lambda: not alive(worker), 15, "the orphaned worker gone")
    finally:
        if alive(worker):
            os.kill(worker, signal.SIGKILL)


@pytest.mark.slow
@pytest.mark.long  # the harness's own check; SIGKILL and resume: test_evolution
def test_the_kill_and_resume_harness_loses_nothing(tmp_path: Path) -> None:
    verdict = kill_and_resume(1, seed=1, out=tmp_path / "harness", log=False)
    assert verdict.landed == 1, verdict
    assert verdict.lost == 0 and verdict.twice == 0, verdict
    assert verdict.identical and not verdict.unreadable, verdict


# ---- a full disk ---------------------------------------------------------------------------
# tests/full_disk.py runs evo/main.py, with a store and an evaluation that watch evo's own
# writes, and lowers the process's real file-size limit (RLIMIT_FSIZE) just before one
# write of the kind under test, which then fails in the
# kernel (EFBIG) as on a full disk. One run directory goes through a session per kind,
# each a resume of the one before: each records its rows, then meets the full disk; the
# last resume, with room again, must give the uninterrupted run's history.

SESSIONS = [  # kind of write, rows this session records first, the file it names
    ("robot", 1, "robots/"),
    ("policy", 1, ".pt"),
    ("mcap", 1, ".mcap"),
    ("rrd", 1, ".rrd"),
    ("state", 1, "state.json"),
    ("history", 0, "history.csv"),
]
IN_EVALUATION = {"policy", "mcap", "rrd"}
"""Kinds written by the evaluation: the robot stays in flight, evaluated again on resume."""

KEY = ["birth", "name", "fitness", "accepted"]

SDK_LOG = ("re_log_encoding::", "re_sdk::")
"""rerun's own log lines on stderr (its writer thread reports the failed write there)."""


def full_disk_cmd(kind: str, after: int, *args: str) -> list[str]:
    return [sys.executable, str(REPO / "tests" / "full_disk.py"), kind, str(after), *args]


def evo_lines(stderr: str) -> list[str]:
    return [line for line in stderr.splitlines()
            if line.strip() and not any(tag in line for tag in SDK_LOG)]


@pytest.mark.slow
@pytest.mark.long  # seven sessions of one run; in-process: tests/test_write_failures.py
def test_a_full_disk_at_each_kind_of_write_stops_the_run_and_resume_completes_it(
    tmp_path: Path, serial_reference: Path
) -> None:
    run_dir = tmp_path / "run"
    reference = comparable(read_history(serial_reference))
    matrix, rows = [], 0
    for i, (kind, after, named) in enumerate(SESSIONS):
        args = [*TINY, "executor=serial", f"hydra.run.dir={run_dir}"] if i == 0 else [
            f"resume={run_dir}"]
        done = run(full_disk_cmd(kind, after, *args), tmp_path, timeout=120)
        lines = evo_lines(done.stderr)
        matrix.append((kind, done.returncode, lines[-1] if lines else ""))
        assert done.returncode == 1, (kind, done.returncode, done.stderr[-3000:])
        assert "Traceback" not in done.stderr, done.stderr[-3000:]
        assert len(lines) == 1, (kind, lines)
        (line,) = lines
        assert line.startswith(f"error: cannot write {run_dir}/") and named in line, line
        assert "File too large (EFBIG)" in line and line.endswith(f"resume={run_dir}"), line
        # The state on disk is whole and consistent, and holds this session's new rows.
        saved = RunStore(run_dir).load()
        rows += after
        assert len(saved.history) == rows, (kind, len(saved.history))
        kept = [(r.birth, r.name, r.fitness, r.accepted) for r in saved.history]
        assert kept == list(reference[KEY].itertuples(index=False, name=None))[:rows], kind
        pending = [t.birth for t in saved.pending]
        assert pending == ([rows] if kind in IN_EVALUATION else []), (kind, pending)
    done = run(main_cmd(f"resume={run_dir}"), tmp_path)
    assert done.returncode == 0, done.stderr[-3000:]
    history = check_run_dir(run_dir, robot_budget=6)
    identical = comparable(history).equals(reference)
    print("\nkind     exit  message\n" + "\n".join(f"{k:8} {c:4}  {m}" for k, c, m in matrix)
          + f"\nresumed with room: exit {done.returncode}, history identical: {identical}")
    pd.testing.assert_frame_equal(comparable(history), reference)


# ---- another robot budget on resume --------------------------------------------------------


def tiny(**values: object) -> list[str]:
    """TINY with some of its values replaced (``tiny(**{"ga.robot_budget": 4})``)."""
    return [f"{key}={values[key]}" if key in values else arg
            for arg in TINY for key in [arg.partition("=")[0]]]


FIXED = {"ga.schedule.last": 256}
"""TINY's schedule with first = last: every offspring's budget is the same whatever the
robot budget, so a run may stop earlier or go on."""


@pytest.fixture(scope="module")
def fixed_reference(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A finished tiny serial run of 6 robots at the :data:`FIXED` schedule."""
    run_dir = tmp_path_factory.mktemp("fixed") / "run"
    done = run(main_cmd(*tiny(**FIXED), "executor=serial", f"hydra.run.dir={run_dir}"),
               run_dir.parent)
    assert done.returncode == 0, done.stderr[-3000:]
    return run_dir


def robot_budget_in(run_dir: Path) -> int:
    return int(OmegaConf.load(run_dir / "config.yaml").ga.robot_budget)


@pytest.mark.slow
def test_a_larger_robot_budget_extends_a_finished_run_to_the_run_of_that_many(
    fixed_reference: Path, tmp_path: Path
) -> None:
    run_dir = tmp_path / "run"
    short = tiny(**FIXED, **{"ga.robot_budget": 4})
    done = run(main_cmd(*short, "executor=serial", f"hydra.run.dir={run_dir}"), tmp_path)
    assert done.returncode == 0, done.stderr[-3000:]
    first = check_run_dir(run_dir, robot_budget=4)
    done = run(main_cmd(f"resume={run_dir}", "ga.robot_budget=6"), tmp_path)
    assert done.returncode == 0, done.stderr[-3000:]
    assert f"{run_dir}: ga.robot_budget changed from 4 to 6 robots" in done.stdout, done.stdout
    history = check_run_dir(run_dir, robot_budget=6)  # summary.json: complete
    assert robot_budget_in(run_dir) == 6
    assert json.loads((run_dir / "summary.json").read_text())["robot_budget"] == 6
    pd.testing.assert_frame_equal(comparable(history).head(4), comparable(first))
    pd.testing.assert_frame_equal(comparable(history),
                                  comparable(read_history(fixed_reference)))


@pytest.mark.slow
def test_a_robot_budget_at_the_robots_done_ends_a_stopped_run_at_once(
    fixed_reference: Path, tmp_path: Path
) -> None:
    run_dir = tmp_path / "run"
    killed("after-final-state", 4, *tiny(**FIXED), "executor=serial",
           f"hydra.run.dir={run_dir}", cwd=tmp_path)
    assert len(RunStore(run_dir).load().history) == 4 and robot_budget_in(run_dir) == 6
    done = run(main_cmd(f"resume={run_dir}", "ga.robot_budget=4"), tmp_path)
    assert done.returncode == 0, done.stderr[-3000:]
    assert "ga.robot_budget changed from 6 to 4 robots" in done.stdout, done.stdout
    history = check_run_dir(run_dir, robot_budget=4)  # no new robot; complete
    assert robot_budget_in(run_dir) == 4
    reference = comparable(read_history(fixed_reference))
    pd.testing.assert_frame_equal(comparable(history), reference.head(4))


@pytest.mark.slow
def test_a_robot_budget_below_a_robot_in_flight_drops_it_and_ends_at_once(
    fixed_reference: Path, tmp_path: Path
) -> None:
    # Killed as robot 5 (birth 4) ends its training: 4 evaluated, the fifth in flight.
    run_dir = tmp_path / "run"
    killed("checkpoint", 5, *tiny(**FIXED), "executor=serial", f"hydra.run.dir={run_dir}",
           cwd=tmp_path)
    saved = RunStore(run_dir).load()
    assert len(saved.history) == 4 and [t.birth for t in saved.pending] == [4]
    flying = saved.pending[0].name
    assert (run_dir / "evals" / f"{flying}.csv").is_file(), "its training wrote nothing"
    done = run(main_cmd(f"resume={run_dir}", "ga.robot_budget=4"), tmp_path)
    assert done.returncode == 0, done.stderr[-3000:]
    assert (f"robot {flying} (birth 4), in flight, dropped: a run of 4 robots does not "
            f"breed it") in done.stdout, done.stdout
    history = check_run_dir(run_dir, robot_budget=4)  # robots/ holds the history's only
    assert not list((run_dir / "evals").glob(f"{flying}.*")), "its evaluation's files stay"
    reference = comparable(read_history(fixed_reference))
    pd.testing.assert_frame_equal(comparable(history), reference.head(4))
    again = run(main_cmd(f"resume={run_dir}"), tmp_path)  # complete: nothing to do
    assert again.returncode == 0 and "dropped" not in again.stdout, again.stdout


def test_a_state_ends_at_a_robot_budget_by_dropping_the_robots_in_flight_past_it() -> None:
    saved = saved_with(7, in_flight=3)  # 0-3 evaluated, 4-6 in flight
    assert saved.ending_at(7) == (saved, []) and saved.ending_at(60) == (saved, [])
    ended, dropped = saved.ending_at(5)
    assert [t.birth for t in dropped] == [5, 6] and [t.birth for t in ended.pending] == [4]
    assert ended.next_birth == 5 and ended.history == saved.history
    assert saved.ending_at(4)[0].next_birth == 4 and saved.ending_at(4)[0].pending == []
    with pytest.raises(ValueError, match=re.escape("robots ['robot-3'] are evaluated and "
                                                   "born at 3 or later")):
        saved.ending_at(3)


@pytest.mark.slow
def test_a_robot_budget_a_resume_cannot_take_is_refused_and_changes_nothing(
    serial_reference: Path, tmp_path: Path
) -> None:
    # serial_reference: 6 robots done, population 3, schedule 256 rising to 768. One
    # copy per case: the resumes run at once.
    cases = [
        (["ga.robot_budget=5"], "ga.robot_budget: the run has evaluated robots up to birth "
         "5, which it cannot un-evaluate; expected at least 6, got 5"),
        (["ga.robot_budget=2"], "ga: robot_budget (2) must be >= population_size (3)"),
        (["ga.robot_budget=8"], "ga.robot_budget: ga.schedule (initial 256, first 256, "
         "last 768) depends on ga.robot_budget, so 8 instead of 6 would give robot 4"),
        (["ga.robot_budget=8", "executor=local"], "resume: a resumed run keeps the config it "
         "was started with ({}) but for ga.robot_budget=...; drop the other overrides: "
         "executor=local"),
    ]
    run_dirs = [shutil.copytree(serial_reference, tmp_path / f"run{i}")
                for i in range(len(cases))]
    before = tree_hash(run_dirs[0])
    procs = [subprocess.Popen(main_cmd(f"resume={d}", *args), cwd=tmp_path, env=ENV,
                              stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
             for d, (args, _) in zip(run_dirs, cases, strict=True)]
    for d, (args, expected), proc in zip(run_dirs, cases, procs, strict=True):
        _, err = proc.communicate(timeout=180)
        assert proc.returncode == 2, (args, proc.returncode, err[-2000:])
        expected = expected.format(d / "config.yaml")
        assert f"error: bad config: {expected}" in err and "Traceback" not in err, (args, err)
        assert tree_hash(d) == before, f"{args}: a refused resume changed the run directory"


def saved_with(born: int, in_flight: int = 0) -> SavedState:
    """A saved state with ``born`` robots born, the last ``in_flight`` of them in flight
    (the births ``with_robot_budget`` and ``SavedState.ending_at`` read)."""
    done = born - in_flight
    rows = [HistoryRow(b, f"robot-{b}", "E+L", (), "random", 1, 1, -1.0, True, "", 1, 1, 0.0,
                       "", -1.0, -1.0, "trained", float("nan")) for b in range(done)]
    flying = [Candidate(b, f"robot-{b}", "{}", 1, b) for b in range(done, born)]
    return SavedState(0, born, rng_state(np.random.default_rng(0)), [], rows, flying, 0.0)


def with_robot_budget(cfg: DictConfig, robot_budget: object, saved: SavedState) -> GAConfig:
    """The ``ga`` group of a run started with ``cfg``, resumed with ``ga.robot_budget``
    given (checked as ``evo/main.py`` checks it)."""
    ga = OmegaConf.to_container(cfg.ga)
    assert isinstance(ga, dict)
    changed = typed(GAConfig, {**ga, "robot_budget": robot_budget}, "ga")
    check_robot_budget(typed(GAConfig, cfg.ga, "ga"), changed, saved)
    return changed


def test_another_robot_budget_must_keep_the_budgets_of_the_robots_born() -> None:
    rising = OmegaConf.create({"ga": {"population_size": 3, "robot_budget": 6, "schedule": {
        "initial": 100, "first": 200, "last": 400}}})
    # Only initial robots born: any N; robot 3 too: 200 steps at 6 robots and at 8.
    for born, n in ((3, 4), (3, 60), (0, 3), (4, 8)):
        assert with_robot_budget(rising, n, saved_with(born)).robot_budget == n
    assert rising.ga.robot_budget == 6, "the config given is left alone"
    # Robots 3-4 in flight at N = 3 are dropped: robot 3 would have another budget, but
    # the robots kept (0-2, initial) keep theirs.
    assert with_robot_budget(rising, 3, saved_with(5, in_flight=2)).robot_budget == 3
    for born, n, message in (
        (5, 8, "would give robot 4, already born, 250 env steps instead of 300 (1 of the 5"),
        (5, 5, "would give robot 4, already born, 400 env steps instead of 300 (1 of the 5"),
        (4, 4, "would give robot 3, already born, 400 env steps instead of 200 (1 of the 4"),
        (5, 4, "evaluated robots up to birth 4, which it cannot un-evaluate; expected at "
               "least 5, got 4"),
        (3, "six", "ga.robot_budget: expected an integer, got 'six'"),
    ):
        with pytest.raises(ConfigError, match=re.escape(message)):
            with_robot_budget(rising, n, saved_with(born))
    fixed = OmegaConf.create({"ga": {"population_size": 3, "robot_budget": 6, "schedule": {
        "initial": 100, "first": 300, "last": 300}}})
    for born, n in ((4, 4), (6, 6), (6, 600)):  # first = last: any N from the robots born
        assert with_robot_budget(fixed, n, saved_with(born)).robot_budget == n
