"""Light fault-injecting tasks for executor tests: they import nothing of evo, so a pool
worker runs them without loading the learners."""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path
from typing import NoReturn


def hold(started: str, release: str) -> int:
    """Touch ``started``, wait until the file ``release`` exists, then return this
    worker's pid."""
    Path(started).touch()
    while not Path(release).exists():
        time.sleep(0.01)
    return os.getpid()


def wait_to_be_killed(guard_s: float = 600) -> NoReturn:
    """Wait until this process is killed from outside; after ``guard_s`` seconds without
    the kill, raise (a guard against a test that hangs, not a measure of anything)."""
    deadline = time.monotonic() + guard_s
    while time.monotonic() < deadline:
        time.sleep(0.01)
    raise RuntimeError(f"not killed within {guard_s} s")


def die(when: str) -> None:
    """Kill this worker process with SIGKILL once the file ``when`` exists."""
    while not Path(when).exists():
        time.sleep(0.01)
    os.kill(os.getpid(), signal.SIGKILL)
