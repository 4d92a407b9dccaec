"""What to record (``conf/record/*.yaml``) and the choice of episodes.

This module stays light (no rerun or foxglove import) so the environment and the
learner can call ``should_record`` for every finished episode at no cost.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

from evo.checks import at_least

if TYPE_CHECKING:
    import mujoco

    from evo.record.base import Recorder


@dataclass(frozen=True, slots=True)
class EpisodeChoice:
    """Which episodes of an evaluation are recorded.

    Attributes:
        first: Record the first episode (index 0).
        last: Record the last episode.
        every: Also record episodes 0, k, 2k, ... (0 = none of these).
    """

    first: bool = True
    last: bool = True
    every: int = 100

    def __post_init__(self) -> None:
        at_least(self, 0, "every", note=" (0 = off)")


@dataclass(frozen=True, slots=True)
class RecordConfig:
    """One ``conf/record/*.yaml``.

    Attributes:
        mcap: Write MCAP files (``evals/<robot>.mcap``, ``run.mcap``): for Foxglove,
            and the learning curves analysis reads.
        rerun: Write rerun files (``evals/<robot>.rrd``, ``run.rrd``): 3D replay and
            curve plots in the rerun viewer.
        episodes: Which episodes to record.
        frame_stride: Keep every n-th control step of a recorded episode (1 = all, at
            20 Hz).
        still_tolerance: A body that moves less than this during an episode (m, and
            quaternion units) is stored once for the episode (0 = every frame).
        flush_every: Flush the files every n learning-curve rows (a crash keeps every
            row up to the last flush).
    """

    mcap: bool = True
    rerun: bool = True
    episodes: EpisodeChoice = field(default_factory=EpisodeChoice)
    frame_stride: int = 1
    still_tolerance: float = 1e-6
    flush_every: int = 10

    def __post_init__(self) -> None:
        at_least(self, 1, "frame_stride", "flush_every")
        at_least(self, 0, "still_tolerance")

    @property
    def enabled(self) -> bool:
        """Whether any file is written."""
        return self.mcap or self.rerun


def should_record(config: RecordConfig, episode_index: int, is_last: bool) -> bool:
    """Whether episode ``episode_index`` (0-based) of an evaluation is recorded.

    Args:
        config: The record config.
        episode_index: The episode's number within the evaluation.
        is_last: Whether it is the evaluation's last episode.
    """
    if not config.enabled:
        return False
    choice = config.episodes
    return (
        (choice.first and episode_index == 0)
        or (choice.last and is_last)
        or (choice.every > 0 and episode_index % choice.every == 0)
    )


class OpenRecorder(Protocol):
    """Opens the recorder of one evaluation (:func:`open_recorder` is evo's own).

    ``evo.evaluation.evaluate`` takes one, the way it takes a learner: a recorder of
    another format, or one that wraps evo's (to also send the curve elsewhere), is an
    opener of this signature. It is called inside a critical section
    (``evo.interrupt.critical``), so a signal waits until the recorder it returns is
    in the evaluation's hands.
    """

    def __call__(
        self,
        config: RecordConfig,
        directory: str | Path,
        name: str,
        model: mujoco.MjModel,
        metadata: Mapping[str, Any],
    ) -> Recorder: ...


def open_recorder(
    config: RecordConfig,
    directory: str | Path,
    name: str,
    model: mujoco.MjModel,
    metadata: Mapping[str, Any],
) -> Recorder:
    """The recorder of one evaluation: ``directory/<name>.mcap`` and/or ``.rrd``.

    Args:
        config: What to write.
        directory: Folder of the evaluation files (``<run>/evals``).
        name: The robot's name; the files are named after it.
        model: The compiled model of the whole scene.
        metadata: Robot JSON, resolved config, seed, method, ...

    Returns:
        A ``Recorders`` fan-out, or a ``NullRecorder`` when recording is off.
    """
    from evo.record.base import NullRecorder, RecorderOptions, Recorders
    from evo.run.layout import MCAP_SUFFIX, RRD_SUFFIX

    folder = Path(directory)
    meta = {"name": name, **metadata}
    options: RecorderOptions = {
        "flush_every": config.flush_every,
        "frame_stride": config.frame_stride,
        "still_tolerance": config.still_tolerance,
    }
    recorders: list[Recorder] = []
    if config.mcap:
        from evo.record.mcap_file import McapRecorder

        recorders.append(McapRecorder(folder / f"{name}{MCAP_SUFFIX}", model, meta, **options))
    if config.rerun:
        from evo.record.rrd import RerunRecorder

        try:
            recorders.append(RerunRecorder(folder / f"{name}{RRD_SUFFIX}", model, meta, **options))
        except BaseException:
            for r in recorders:
                r.close({"status": "failed", "error": "could not open the .rrd file"})
            raise
    if not recorders:
        return NullRecorder()
    return Recorders(recorders)
