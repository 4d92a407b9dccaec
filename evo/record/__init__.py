"""Recording of evaluations and runs: MCAP for Foxglove and analysis, .rrd for rerun.

Per evaluation (one robot's training run) one ``Recorder`` writes
``evals/<robot>.mcap`` and ``evals/<robot>.rrd``: the scene geometry, sampled episodes
(every body's pose each control step, target, rocks, reward terms), the learning
curve (streamed, flushed every few rows) and the metadata (robot JSON, resolved
config, seed, method; fitness at close). ``RunRecorder`` writes ``run.mcap`` and
``run.rrd``: every evaluated robot and the best robots' geometry.
``evo.record.readback`` reads the MCAP files back (the source of truth for analysis).

Importing this package is cheap: the writers (and rerun) load on first use of
``McapRecorder``, ``RerunRecorder``, ``RunRecorder`` or the readers.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from evo.episode import Episode
from evo.record.base import NullRecorder, Recorder, Recorders, WrappedRecorder
from evo.record.config import (
    EpisodeChoice,
    OpenRecorder,
    RecordConfig,
    open_recorder,
    should_record,
)

if TYPE_CHECKING:
    from evo.record.geometry import Geometry, scene_geometry
    from evo.record.mcap_file import McapRecorder, RecordError
    from evo.record.playback import write_replay_rrd
    from evo.record.readback import (
        is_complete,
        read_curve,
        read_episodes,
        read_json_topic,
        read_metadata,
    )
    from evo.record.rrd import RerunRecorder
    from evo.record.run import Birth, RunRecorder, read_births

_LAZY = {
    "Geometry": "evo.record.geometry",
    "scene_geometry": "evo.record.geometry",
    "McapRecorder": "evo.record.mcap_file",
    "RecordError": "evo.record.mcap_file",
    "is_complete": "evo.record.readback",
    "read_curve": "evo.record.readback",
    "read_episodes": "evo.record.readback",
    "read_json_topic": "evo.record.readback",
    "read_metadata": "evo.record.readback",
    "RerunRecorder": "evo.record.rrd",
    "write_replay_rrd": "evo.record.playback",
    "Birth": "evo.record.run",
    "RunRecorder": "evo.record.run",
    "read_births": "evo.record.run",
}

__all__ = [
    "Birth",
    "Episode",
    "EpisodeChoice",
    "Geometry",
    "McapRecorder",
    "NullRecorder",
    "OpenRecorder",
    "RecordConfig",
    "RecordError",
    "Recorder",
    "Recorders",
    "RerunRecorder",
    "RunRecorder",
    "WrappedRecorder",
    "is_complete",
    "open_recorder",
    "read_births",
    "read_curve",
    "read_episodes",
    "read_json_topic",
    "read_metadata",
    "scene_geometry",
    "should_record",
    "write_replay_rrd",
]


def __getattr__(name: str) -> Any:
    """Load the writers and readers on first use."""
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'evo.record' has no attribute {name!r}")
    return getattr(importlib.import_module(module), name)
