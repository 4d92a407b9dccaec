"""Run ``evo/main.py`` in this process and fill the disk at one kind of write.

    python tests/full_disk.py KIND AFTER evo/main.py [overrides ...]

Once AFTER new rows of ``history.csv`` have been recorded in this session, the next
write of KIND meets a full disk: just before it, the process's file-size limit
(``RLIMIT_FSIZE``, soft) drops to :data:`LIMIT` bytes, so that write, and every later
write of a file past that size, fails in the kernel with ``EFBIG`` (SIGXFSZ ignored, as
Python does anyway). Nothing else is changed: the writes are evo's own, and so is what
the run does about them. KIND is one of :data:`KINDS`.
"""

from __future__ import annotations

import resource
import runpy
import signal
import sys
from pathlib import Path
from typing import Any

import evo.evaluation as evaluation
import evo.run.files as run_files
import evo.run.store as run_store
from evo.record.mcap_file import McapRecorder
from evo.record.rrd import RerunRecorder

LIMIT = 64
"""The file-size limit once the disk is full, bytes: below every file of a run."""

KINDS = ("state", "history", "robot", "policy", "mcap", "rrd")

rows_at_start: int | None = None
rows = 0  # rows recorded in this session so far


def fill(kind: str) -> None:
    """Fill the disk when this write is of the chosen kind and its moment has come."""
    if kind == KIND and rows >= AFTER:
        resource.setrlimit(resource.RLIMIT_FSIZE, (LIMIT, resource.RLIM_INFINITY))


def hooked(kind: str, write: Any) -> Any:
    def before(*args: Any, **kwargs: Any) -> Any:
        fill(kind)
        return write(*args, **kwargs)

    return before


def write_json(path: Path, data: dict[str, Any]) -> Path:
    """``evo.run.files.write_json``, counting the rows each saved state records."""
    global rows_at_start, rows
    if path.name != "state.json":
        return real_write_json(path, data)
    fill("state")
    done = real_write_json(path, data)
    if rows_at_start is None:
        rows_at_start = len(data["history"])
    rows = len(data["history"]) - rows_at_start
    return done


real_write_json = run_files.write_json
KIND, AFTER, MAIN, ARGV = sys.argv[1], int(sys.argv[2]), sys.argv[3], sys.argv[4:]
assert KIND in KINDS, f"KIND must be one of {KINDS}, got {KIND!r}"
signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
run_files.write_json = write_json
run_store.write_history = hooked("history", run_store.write_history)
run_store.RunStore.save_robot = hooked("robot", run_store.RunStore.save_robot)
evaluation.save_checkpoint = hooked("policy", evaluation.save_checkpoint)
McapRecorder.episode = hooked("mcap", McapRecorder.episode)
RerunRecorder._close = hooked("rrd", RerunRecorder._close)
sys.argv = [MAIN, *ARGV]
runpy.run_path(MAIN, run_name="__main__")
