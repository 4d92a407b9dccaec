"""Light fault-injecting tasks for executor tests: they import nothing of evo, so a pool
worker runs them without loading the learners."""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path


def nap(seconds: float, started: str) -> int:
    """Touch ``started``, sleep, then return this worker's pid."""
    Path(started).touch()
    time.sleep(seconds)
    return os.getpid()


def die(when: str) -> None:
    """Kill this worker process with SIGKILL once the file ``when`` exists."""
    while not Path(when).exists():
        time.sleep(0.01)
    os.kill(os.getpid(), signal.SIGKILL)
