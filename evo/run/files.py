"""Run-directory I/O: atomic files and the lock that makes one process own a directory.

Every file a run rewrites goes through :func:`write_json` or :func:`write_csv`: written
to ``<name>.tmp`` and renamed over the old one, so a crash leaves the old file or the
new one, never half of either.

**A write that fails** (a full disk, a quota, a file-size limit) raises
:class:`WriteFailed`, an ``OSError`` that names the file and the cause. It is never a
robot's fault: the run stops with that one line (exit 1) and resumes once there is
room again (the state on disk is the last one written whole). The recording SDKs write
from native code and report a failed write only in their own log, so their writers ask
:func:`full_disk` why a file came out short.

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

import errno
import fcntl
import json
import os
import resource
import socket
import time
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path
from typing import TypeAlias

import pandas as pd

from evo.run.layout import RunLayout

JSONValue: TypeAlias = "None | bool | int | float | str | list[JSONValue] | dict[str, JSONValue]"
"""A value of a JSON document as ``json.loads`` gives it."""

JSONObject: TypeAlias = dict[str, JSONValue]
"""A JSON object whose keys are open (curve metrics, metadata, a JSON Schema), or the JSON
form of a record whose dataclass lists its keys (``record()`` in ``evo.run.records``); a
document with known keys and no such dataclass is a ``TypedDict`` of its own."""

DISK_FULL = frozenset({errno.ENOSPC, errno.EFBIG, errno.EDQUOT})
"""The ``errno`` of a full disk, a file-size limit (``RLIMIT_FSIZE``) and a full quota."""

FULL_BELOW = 1 << 20
"""A file system with less room than this (bytes) counts as full (:func:`full_disk`)."""


class WriteFailed(OSError):
    """A file of the run could not be written; ``filename`` names it, ``strerror`` and
    ``errno`` say why. Picklable, so it crosses from a pool worker to the run."""

    def __str__(self) -> str:
        code = errno.errorcode.get(self.errno or 0)
        return f"cannot write {self.filename}: {self.strerror}" + (f" ({code})" if code else "")


@contextmanager
def writing(path: Path) -> Iterator[Path]:
    """Turn an ``OSError`` raised inside the block into :class:`WriteFailed` naming ``path``."""
    try:
        yield path
    except WriteFailed:
        raise
    except OSError as err:
        raise WriteFailed(err.errno, err.strerror or str(err), str(path)) from err


def write_failure(err: BaseException) -> WriteFailed | None:
    """The first write failure behind ``err``: ``err`` itself or an exception it was
    raised while handling (closing files on the way out fails too on a full disk). An
    ``OSError`` of a full disk raised where no run file was named counts, unnamed."""
    chain: list[BaseException] = []
    seen: BaseException | None = err
    while seen is not None and seen not in chain:
        chain.append(seen)
        seen = seen.__context__
    named = [e for e in chain if isinstance(e, WriteFailed)]
    if named:
        return named[-1]
    full = [e for e in chain if isinstance(e, OSError) and e.errno in DISK_FULL]
    first = full[-1] if full else None
    if isinstance(first, OSError):
        return WriteFailed(first.errno, first.strerror, str(first.filename or "a file"))
    return None


def full_disk(path: Path) -> WriteFailed | None:
    """Why ``path`` could not grow, when the reason is the disk's: the process's
    file-size limit is reached (``EFBIG``) or its file system has no room (``ENOSPC``);
    None when neither holds (a quota cannot be told from here)."""
    try:
        size = path.stat().st_size
        room = os.statvfs(path.parent)
    except OSError:
        return None
    limit, _ = resource.getrlimit(resource.RLIMIT_FSIZE)
    if limit != resource.RLIM_INFINITY and size >= limit:
        return WriteFailed(errno.EFBIG, os.strerror(errno.EFBIG), str(path))
    free = room.f_bfree if os.geteuid() == 0 else room.f_bavail
    if free * room.f_frsize < FULL_BELOW:
        return WriteFailed(errno.ENOSPC, os.strerror(errno.ENOSPC), str(path))
    return None


def write_bytes(path: Path, data: bytes) -> Path:
    """Write ``data`` atomically (a crash leaves the old file or the new one)."""
    tmp = path.with_suffix(path.suffix + ".tmp")
    with writing(path):
        tmp.write_bytes(data)
        tmp.replace(path)
    return path


def write_text(path: Path, text: str) -> Path:
    """Write ``text`` atomically."""
    return write_bytes(path, text.encode())


def write_json(path: Path, data: Mapping[str, object]) -> Path:
    """Write ``data`` (a JSON document: a ``TypedDict`` or a :data:`JSONObject`) as JSON
    atomically (a crash leaves the old file or the new one)."""
    return write_text(path, json.dumps(data, indent=2, sort_keys=True) + "\n")


def write_csv(path: Path, table: pd.DataFrame) -> Path:
    """Write ``table`` as CSV (no index) atomically."""
    return write_text(path, table.to_csv(index=False))


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
