"""Run-directory I/O: atomic files and the lock that makes one process own a directory.

Every file a run rewrites goes through :func:`write_json` or :func:`write_csv`: written
to ``<name>.tmp`` and renamed over the old one, so a crash leaves the old file or the
new one, never half of either.

**The lock.** A run (or a resume, or a one-robot training) owns its directory for its
whole life through an exclusive ``flock`` on the directory itself, taken with
:meth:`RunLock.acquire` before anything is read or written. The kernel releases it
when the process ends however it ends, SIGKILL included, so a killed run never
blocks the next resume, and no PID file is trusted. Once the run has checked its
inputs it calls :meth:`RunLock.claim`, which records who holds the lock (PID, host,
start time) in ``lock.json``: what a second process names when it is refused. The
analysis tools never take the lock; :func:`is_locked` only asks whether a run is live.
"""

from __future__ import annotations

import fcntl
import json
import os
import socket
import time
from pathlib import Path
from typing import Any

import pandas as pd

from evo.run.layout import RunLayout


def write_json(path: Path, data: dict[str, Any]) -> Path:
    """Write ``data`` as JSON atomically (a crash leaves the old file or the new one)."""
    tmp = path.with_suffix(path.suffix + ".tmp")
    tmp.write_text(json.dumps(data, indent=2, sort_keys=True) + "\n")
    tmp.replace(path)
    return path


def write_csv(path: Path, table: pd.DataFrame) -> Path:
    """Write ``table`` as CSV (no index) atomically."""
    tmp = path.with_suffix(path.suffix + ".tmp")
    table.to_csv(tmp, index=False)
    tmp.replace(path)
    return path


class RunDirectoryBusy(RuntimeError):
    """Another live process holds the run directory's lock; the message names it."""


class RunLock:
    """The exclusive lock on one run directory (see the module docstring)."""

    def __init__(self, run_dir: Path) -> None:
        self.run_dir = run_dir
        self._fd: int | None = None

    def acquire(self) -> RunLock:
        """Take the lock, writing nothing.

        Raises:
            RunDirectoryBusy: When another process holds it, naming the directory, the
                holder's PID and since when.
        """
        fd = os.open(self.run_dir, os.O_RDONLY)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            raise RunDirectoryBusy(busy_message(self.run_dir)) from None
        self._fd = fd
        return self

    def claim(self) -> None:
        """Record this process as the holder (after the run's inputs are checked)."""
        assert self._fd is not None, "claim() needs acquire() first"
        since = time.strftime("%Y-%m-%d %H:%M:%S %z")
        write_json(RunLayout(self.run_dir).lock,
                   {"pid": os.getpid(), "host": socket.gethostname(), "since": since})

    def release(self) -> None:
        """Let go of the lock (the kernel also does when the process ends)."""
        if self._fd is not None:
            fcntl.flock(self._fd, fcntl.LOCK_UN)
            os.close(self._fd)
            self._fd = None

    def __enter__(self) -> RunLock:
        return self.acquire()

    def __exit__(self, *exc: object) -> None:
        self.release()


def busy_message(run_dir: Path) -> str:
    """What a process refused a held run directory is told."""
    return f"{run_dir} is in use by {holder(run_dir)}; wait for it to end, or stop it first"


def holder(run_dir: Path) -> str:
    """Who holds ``run_dir``'s lock, as recorded by :meth:`RunLock.claim`."""
    try:
        info = json.loads(RunLayout(run_dir).lock.read_text())
        return f"PID {info['pid']} on {info['host']} since {info['since']}"
    except (OSError, ValueError, KeyError, TypeError):
        return "another process (it has not recorded its PID yet)"


def is_locked(run_dir: Path) -> bool:
    """Whether a live process holds ``run_dir``'s lock (probed with a shared lock,
    released at once; nothing is written)."""
    try:
        fd = os.open(run_dir, os.O_RDONLY)
    except OSError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except BlockingIOError:
        return True
    finally:
        os.close(fd)  # closing drops a shared lock taken here
    return False
