"""Run ``evo/main.py`` in this process and SIGKILL it at the k-th event of one kind.

    python bench/kill_at.py KIND K [overrides ...]

The run is evo's own (``evo.main.cli``) but for the code it is given
(``evo.main.EvolveCode``): a store, an evaluation's recorder and policy writer, and a
run log that count the events of KIND as they happen and kill the process at the K-th.
The kinds (:data:`KINDS`):

* ``state-write``: ``state.json`` half written to its temporary file;
* ``between``: just after a state with nothing in flight is saved;
* ``after-final-state``: just after the state with K robots and nothing in flight is
  saved (K is the number of robots, not a count of events);
* ``evaluation``: just after the K-th learning-curve row is recorded (inside training);
* ``recording``: with an episode of an evaluation, or a birth of the run, written but
  not flushed or closed;
* ``checkpoint``: before the K-th policy is saved (its training has ended).

``bench/kill_resume.py`` and ``tests/test_evolution.py`` drive their SIGKILL tests with
it. The evaluations run in this process (``executor=serial``): a pool's workers would
run evo's own code.
"""

from __future__ import annotations

import functools
import json
import os
import signal
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any, NoReturn

from evo.evolution import RunLog
from evo.learners.common import LearnerConfig, Policy, save_checkpoint
from evo.main import EvolveCode, cli
from evo.record import Episode, RecordConfig, Recorder, WrappedRecorder, open_recorder
from evo.record.run import RunMetadata
from evo.run.records import HistoryRow
from evo.run.store import RunStore

if TYPE_CHECKING:
    import mujoco

MAIN = Path(__file__).resolve().parents[1] / "evo" / "main.py"
KINDS = ("state-write", "between", "after-final-state", "evaluation", "recording",
         "checkpoint")


def die() -> NoReturn:
    """SIGKILL this process: nothing after this line runs, no cleanup either."""
    os.kill(os.getpid(), signal.SIGKILL)
    raise AssertionError("still alive after SIGKILL")


class Killer:
    """Counts the events of ``kind`` and kills the process at the ``k``-th."""

    def __init__(self, kind: str, k: int) -> None:
        self.kind, self.k, self.calls = kind, k, 0

    def hit(self, kind: str) -> bool:
        """Count an event of ``kind``; whether it is the one to die at."""
        if kind != self.kind:
            return False
        self.calls += 1
        return self.calls == self.k

    def open_recorder(self, config: RecordConfig, directory: str | Path, name: str,
                      model: mujoco.MjModel, metadata: Mapping[str, Any]) -> Recorder:
        """evo's recorder of an evaluation, in a :class:`DyingRecorder`."""
        return DyingRecorder(open_recorder(config, directory, name, model, metadata), self)

    def save_policy(self, policy: Policy, path: Path, config: LearnerConfig, *,
                    robot: str = "") -> Path:
        """evo's policy writer, killed before the k-th policy (``checkpoint``)."""
        if self.hit("checkpoint"):
            die()
        return save_checkpoint(policy, path, config, robot=robot)

    def code(self) -> EvolveCode:
        """The run's code, with every seam that counts events."""
        return EvolveCode.with_seams(
            open_recorder=self.open_recorder, save_policy=self.save_policy,
            store=functools.partial(DyingStore, killer=self),
            run_log=functools.partial(DyingLog, killer=self),
        )


class DyingStore(RunStore):
    """The run's store, killed at a write of ``state.json`` (``state-write``, ``between``,
    ``after-final-state``)."""

    def __init__(self, root: Path, *, killer: Killer) -> None:
        super().__init__(root)
        self.killer = killer

    def write_state(self, data: Mapping[str, object]) -> Path:
        if self.killer.hit("state-write"):
            text = json.dumps(data)
            self.layout.state.with_suffix(".json.tmp").write_text(text[: len(text) // 2])
            die()
        path = super().write_state(data)
        history = data["history"]
        assert isinstance(history, list)  # RunStore.save's state: its rows
        if not data["pending"] and self.killer.hit("between"):
            die()
        final = not data["pending"] and len(history) == self.killer.k
        if self.killer.kind == "after-final-state" and final:
            die()
        return path


class DyingRecorder(WrappedRecorder):
    """An evaluation's recorder, killed just after the k-th curve row (``evaluation``) or
    with the k-th episode written, not flushed (``recording``)."""

    def __init__(self, inner: Recorder, killer: Killer) -> None:
        super().__init__(inner)
        self.killer = killer

    def curve(self, row: Mapping[str, float]) -> None:
        self.inner.curve(row)
        if self.killer.hit("evaluation"):
            die()

    def episode(self, episode: Episode) -> None:
        self.inner.episode(episode)
        if self.killer.hit("recording"):
            die()


class DyingLog(RunLog):
    """The run's log, killed with the k-th birth written to the run's recordings, not
    flushed (``recording``)."""

    def __init__(self, store: RunStore, record: RecordConfig, metadata: RunMetadata, *,
                 killer: Killer) -> None:
        super().__init__(store, record, metadata)
        self.killer = killer

    def __call__(self, row: HistoryRow) -> None:
        super().__call__(row)
        if self.recorder is not None and self.killer.hit("recording"):
            die()


def main() -> None:
    if len(sys.argv) < 3 or sys.argv[1] in ("-h", "--help"):
        print(__doc__)
        return
    kind, k, overrides = sys.argv[1], int(sys.argv[2]), sys.argv[3:]
    if kind not in KINDS:
        raise SystemExit(f"KIND must be one of {', '.join(KINDS)}, got {kind!r}")
    sys.argv = [str(MAIN), *overrides]
    cli(Killer(kind, k).code())


if __name__ == "__main__":
    main()
