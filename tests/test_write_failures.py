"""A write that fails for want of room (``evo.run.files.WriteFailed``), in-process: the
error crosses from a pool worker intact, the first failure is the one named, and an
evaluation that meets a full disk stops the run instead of becoming a ``failed`` robot.
A full disk at each kind of write, end to end: tests/test_rundir.py.
"""

from __future__ import annotations

import errno
import functools
import json
import pickle
from concurrent.futures import Future
from pathlib import Path
from typing import Any

import pytest
from test_evolution import make_evolution

from evo.components.executors import SerialExecutor
from evo.evaluation import evaluate
from evo.pool import outcome_of
from evo.run.files import WriteFailed, write_failure
from evo.run.records import Candidate


def test_a_write_failure_names_its_file_and_crosses_from_a_worker_intact() -> None:
    err = WriteFailed(errno.ENOSPC, "No space left on device", "/runs/a/state.json")
    back = pickle.loads(pickle.dumps(err))
    assert isinstance(back, WriteFailed) and isinstance(back, OSError)
    assert (back.errno, back.strerror, back.filename) == (err.errno, err.strerror, err.filename)
    assert str(back) == "cannot write /runs/a/state.json: No space left on device (ENOSPC)"


def test_the_first_write_failure_is_named_not_those_of_closing_files() -> None:
    try:
        try:
            raise WriteFailed(errno.EFBIG, "File too large", "evals/r.pt")
        except WriteFailed:
            raise WriteFailed(errno.EFBIG, "File too large", "evals/r.mcap") from None
    except WriteFailed as last:
        first = write_failure(last)
    assert first is not None and first.filename == "evals/r.pt"
    bare = OSError(errno.EDQUOT, "Disk quota exceeded")
    assert write_failure(bare) is not None and write_failure(ValueError("x")) is None
    assert write_failure(OSError(errno.EACCES, "Permission denied")) is None


def full_disk_learner(*args: Any, **kwargs: Any) -> Any:
    raise OSError(errno.ENOSPC, "No space left on device")


def test_a_full_disk_in_an_evaluation_stops_the_run_and_keeps_the_robot_in_flight(
    tmp_path: Path,
) -> None:
    evolution = make_evolution(tmp_path, population=2, budget=3, executor=SerialExecutor(),
                               evaluate=functools.partial(evaluate, learner=full_disk_learner))
    with pytest.raises(WriteFailed, match="No space left on device"):
        evolution.run()
    state = json.loads((tmp_path / "state.json").read_text())
    assert state["history"] == [] and [t["birth"] for t in state["pending"]] == [0]
    assert not (tmp_path / "history.csv").exists(), "no robot was recorded failed"
    # The evolution loop gets it through the future as the pool would hand it over, or
    # wrapped as Ray hands over a task's error (RayTaskError keeps it as ``cause``).
    for error in (pickle.loads(pickle.dumps(WriteFailed(errno.EDQUOT, "quota", "x"))),
                  Wrapped(WriteFailed(errno.EDQUOT, "quota", "x"))):
        future: Future[Any] = Future()
        future.set_exception(error)
        with pytest.raises(WriteFailed, match="cannot write x: quota"):
            outcome_of(future, Candidate(0, "r", "{}", 1, 1), SerialExecutor())


class Wrapped(RuntimeError):
    """An executor's wrapping of a task's error, as Ray's ``RayTaskError``."""

    def __init__(self, cause: BaseException) -> None:
        super().__init__(f"task failed:\n{cause}")
        self.cause = cause
