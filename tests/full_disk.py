"""Run ``evo/main.py`` in this process and fill the disk at one kind of write.

    python tests/full_disk.py KIND AFTER [overrides ...]

Once AFTER new rows of ``history.csv`` have been recorded in this session, the next
write of KIND meets a full disk: just before it, the process's file-size limit
(``RLIMIT_FSIZE``, soft) drops to :data:`LIMIT` bytes, so that write, and every later
write of a file past that size, fails in the kernel with ``EFBIG`` (SIGXFSZ ignored, as
Python does anyway). Nothing else is changed: the writes are evo's own, and so is what
the run does about them. The run is given the code that watches the writes
(``evo.main.EvolveCode``): a store (state, history, robot files) and an evaluation's
policy writer and recorders (MCAP, rerun). KIND is one of :data:`KINDS`.
"""

from __future__ import annotations

import functools
import resource
import signal
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

from evo.learners.common import LearnerConfig, Policy, save_checkpoint
from evo.main import EvolveCode, cli
from evo.record import (
    Episode,
    RecordConfig,
    Recorder,
    Recorders,
    WrappedRecorder,
    open_recorder,
)
from evo.record.mcap_file import McapRecorder
from evo.record.rrd import RerunRecorder
from evo.robot.tree import Robot
from evo.run.records import HistoryRow
from evo.run.store import RunStore

if TYPE_CHECKING:
    import mujoco

MAIN = Path(__file__).resolve().parents[1] / "evo" / "main.py"

LIMIT = 64
"""The file-size limit once the disk is full, bytes: below every file of a run."""

KINDS = ("state", "history", "robot", "policy", "mcap", "rrd")


class Disk:
    """Fills when a write of ``kind`` comes once ``after`` rows were recorded."""

    def __init__(self, kind: str, after: int) -> None:
        self.kind, self.after = kind, after
        self.rows_at_start: int | None = None
        self.rows = 0  # rows recorded in this session so far

    def fill(self, kind: str) -> None:
        """Fill the disk when this write is of the chosen kind and its moment has come."""
        if kind == self.kind and self.rows >= self.after:
            resource.setrlimit(resource.RLIMIT_FSIZE, (LIMIT, resource.RLIM_INFINITY))

    def saved(self, state: dict[str, Any]) -> None:
        """Count the rows a saved state records."""
        if self.rows_at_start is None:
            self.rows_at_start = len(state["history"])
        self.rows = len(state["history"]) - self.rows_at_start

    def open_recorder(self, config: RecordConfig, directory: str | Path, name: str,
                      model: mujoco.MjModel, metadata: Mapping[str, Any]) -> Recorder:
        """evo's recorders of an evaluation, each in a :class:`FillingRecorder`."""
        opened = open_recorder(config, directory, name, model, metadata)
        if isinstance(opened, Recorders):
            return Recorders([FillingRecorder(r, self) for r in opened.recorders])
        return opened

    def save_policy(self, policy: Policy, path: Path, config: LearnerConfig, *,
                    robot: str = "") -> Path:
        """evo's policy writer, after :meth:`fill` (``policy``)."""
        self.fill("policy")
        return save_checkpoint(policy, path, config, robot=robot)

    def code(self) -> EvolveCode:
        """The run's code, with every seam that watches writes."""
        return EvolveCode.with_seams(
            open_recorder=self.open_recorder, save_policy=self.save_policy,
            store=functools.partial(FillingStore, disk=self),
        )


class FillingStore(RunStore):
    """The run's store: ``state.json`` (whose rows it counts), ``history.csv`` and the
    robot files each written after :meth:`Disk.fill`."""

    def __init__(self, root: Path, *, disk: Disk) -> None:
        super().__init__(root)
        self.disk = disk

    def write_state(self, data: dict[str, Any]) -> Path:
        self.disk.fill("state")
        done = super().write_state(data)
        self.disk.saved(data)
        return done

    def write_history(self, rows: list[HistoryRow]) -> Path:
        self.disk.fill("history")
        return super().write_history(rows)

    def save_robot(self, name: str, robot: Robot) -> Path:
        self.disk.fill("robot")
        return super().save_robot(name, robot)


class FillingRecorder(WrappedRecorder):
    """One file's recorder of an evaluation: an MCAP episode (``mcap``) or the closing
    of a rerun file (``rrd``) is written after :meth:`Disk.fill`."""

    def __init__(self, inner: Recorder, disk: Disk) -> None:
        super().__init__(inner)
        self.disk = disk

    def episode(self, episode: Episode) -> None:
        if isinstance(self.inner, McapRecorder):
            self.disk.fill("mcap")
        self.inner.episode(episode)

    def close(self, summary: Mapping[str, Any]) -> None:
        if isinstance(self.inner, RerunRecorder) and not self.inner.closed:
            self.disk.fill("rrd")
        self.inner.close(summary)


def main() -> None:
    kind, after, overrides = sys.argv[1], int(sys.argv[2]), sys.argv[3:]
    assert kind in KINDS, f"KIND must be one of {KINDS}, got {kind!r}"
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    sys.argv = [str(MAIN), *overrides]
    cli(Disk(kind, after).code())


if __name__ == "__main__":
    main()
