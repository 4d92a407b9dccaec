"""The recorder seam: what the learner hands over (episodes, curve rows) and the
``Recorder`` protocol every file format implements.

One recorder belongs to one evaluation (one robot's training run). The learner calls
``curve`` once per collector batch and ``episode`` for each episode chosen by
``should_record``; the evaluation ends with ``close(summary)`` (fitness and the like).
Every recorder is a context manager: leaving the ``with`` block through an exception
closes it with ``{"status": "failed", "error": ...}``, so the files stay readable.
Closing is a critical section (``evo.interrupt.critical``): a SIGINT or SIGTERM that
arrives while the files are being finished waits until they are.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import Any, Protocol, Self, TypedDict, runtime_checkable

import numpy as np
import numpy.typing as npt

from evo.checks import at_least
from evo.episode import Episode
from evo.interrupt import critical

F64 = npt.NDArray[np.float64]


STILL_TOLERANCE = 1e-6
"""Default bound (m, and quaternion units) under which a body counts as at rest."""


def moving_bodies(xpos: F64, xquat: F64, tolerance: float = 0.0) -> npt.NDArray[np.bool_]:
    """(B,) mask of the bodies whose pose leaves its first frame's by more than
    ``tolerance`` (any coordinate, or any quaternion component) over frames (T, B, .)."""
    moved = np.any(np.abs(xpos - xpos[:1]) > tolerance, axis=(0, 2))
    turned = np.any(np.abs(xquat - xquat[:1]) > tolerance, axis=(0, 2))
    return np.asarray(moved | turned, dtype=np.bool_)


@dataclass(frozen=True)
class Frames:
    """An episode made ready for writing, shared by the file formats.

    Attributes:
        episode: The episode after the frame stride.
        stamps: (T,) replay-clock time of each frame, int64 ns.
        moving: Ids of the bodies written every frame (world excluded).
        still: Ids of the bodies at rest, written once at the episode's start.
    """

    episode: Episode
    stamps: npt.NDArray[np.int64]
    moving: npt.NDArray[np.intp]
    still: npt.NDArray[np.intp]


class RecorderOptions(TypedDict, total=False):
    """The keyword options of every evaluation recorder.

    Attributes:
        flush_every: Flush (MCAP) or send (rerun) the curve every this many rows (10).
        frame_stride: Keep every n-th frame of an episode (1; see ``Episode.strided``).
        still_tolerance: A body whose pose stays this close (m, quaternion units) to its
            first frame's all episode long is written once per episode; 0 = only exactly
            still (``STILL_TOLERANCE``).
    """

    flush_every: int
    frame_stride: int
    still_tolerance: float


@runtime_checkable
class Recorder(Protocol):
    """Writes one evaluation: learning curve, sampled episodes, summary."""

    def curve(self, row: Mapping[str, float]) -> None:
        """One learning-curve row per collector batch; ``row["env_steps"]`` is present."""

    def episode(self, episode: Episode) -> None:
        """One recorded episode."""

    def close(self, summary: Mapping[str, Any]) -> None:
        """Finish the files with the evaluation's summary (fitness ...); idempotent."""

    def __enter__(self) -> Self: ...

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None: ...


class WrappedRecorder:
    """A recorder that passes every call on to ``inner``: subclass it to act around one
    call (count rows, stop at an episode) and leave the others as they are."""

    def __init__(self, inner: Recorder) -> None:
        self.inner = inner

    def curve(self, row: Mapping[str, float]) -> None:
        self.inner.curve(row)

    def episode(self, episode: Episode) -> None:
        self.inner.episode(episode)

    def close(self, summary: Mapping[str, Any]) -> None:
        self.inner.close(summary)

    def __enter__(self) -> Self:
        self.inner.__enter__()
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.inner.__exit__(exc_type, exc, tb)


class RecorderBase:
    """Context-manager behaviour and the ``closed`` flag shared by the recorders.

    Subclasses implement ``_close(summary)``; ``close`` runs it once.
    """

    closed: bool = False
    flush_every: int
    frame_stride: int
    still_tolerance: float
    path: Path
    body_names: tuple[str, ...]

    def _set_options(self, options: RecorderOptions) -> None:
        """Check and keep the :class:`RecorderOptions` (defaults for those not given)."""
        self.flush_every = options.get("flush_every", 10)
        self.frame_stride = options.get("frame_stride", 1)
        self.still_tolerance = options.get("still_tolerance", STILL_TOLERANCE)
        at_least(self, 1, "flush_every", "frame_stride")
        at_least(self, 0, "still_tolerance")

    def _frames(self, episode: Episode, clock_ns: int) -> Frames:
        """``episode`` checked against the recorder's model, strided (``frame_stride``),
        its bodies split into moving and still (``still_tolerance``) and placed on the
        replay clock from ``clock_ns`` (the time of its first frame, ns)."""
        nbody = len(self.body_names)
        if episode.nbody != nbody:
            raise ValueError(f"{self.path}: episode {episode.index} has {episode.nbody} "
                             f"bodies, the model has {nbody}")
        ep = episode.strided(self.frame_stride)
        stamps = clock_ns + np.round((ep.time - ep.time[0]) * 1e9).astype(np.int64)
        mask = moving_bodies(ep.xpos[:, 1:], ep.xquat[:, 1:], self.still_tolerance)
        return Frames(ep, stamps, 1 + np.flatnonzero(mask), 1 + np.flatnonzero(~mask))

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if exc is None:
            self.close({})
        else:
            self.close({"status": "failed", "error": f"{type(exc).__name__}: {exc}"})

    def close(self, summary: Mapping[str, Any]) -> None:
        """Finish the files with ``summary``; later calls do nothing."""
        with critical():
            if self.closed:
                return
            self.closed = True
            self._close(summary)

    def _close(self, summary: Mapping[str, Any]) -> None:
        raise NotImplementedError


class NullRecorder(RecorderBase):
    """Records nothing (recording switched off)."""

    def curve(self, row: Mapping[str, float]) -> None:
        """Ignore ``row``."""

    def episode(self, episode: Episode) -> None:
        """Ignore ``episode``."""

    def _close(self, summary: Mapping[str, Any]) -> None:
        return None


class Recorders(RecorderBase):
    """Fan-out: every call goes to each recorder in turn.

    ``close`` closes all of them even when one fails, then raises the first error.
    """

    def __init__(self, recorders: Sequence[Recorder]) -> None:
        self.recorders = tuple(recorders)

    def curve(self, row: Mapping[str, float]) -> None:
        """Pass ``row`` to every recorder."""
        for r in self.recorders:
            r.curve(row)

    def episode(self, episode: Episode) -> None:
        """Pass ``episode`` to every recorder."""
        for r in self.recorders:
            r.episode(episode)

    def _close(self, summary: Mapping[str, Any]) -> None:
        errors: list[BaseException] = []
        for r in self.recorders:
            try:
                r.close(summary)
            except Exception as err:  # noqa: BLE001 - re-raised below after closing the rest
                errors.append(err)
        if errors:
            raise errors[0]
