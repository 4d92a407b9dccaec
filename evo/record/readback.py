"""Reading recordings back from MCAP, the source of truth for analysis.

All readers scan the file once, record by record, so they also read a file whose
writer was killed: everything up to the last flush comes back (``is_complete`` tells
whether the file was closed properly). Precision: times, rewards and the poses of
moving bodies come back bit for bit (float64 protobuf doubles, shortest-repr JSON
floats); a body the recorder found at rest (within its ``still_tolerance``, 1e-6 m by
default: the target, resting rocks) comes back at its first frame's pose for the whole
episode. Curve values come back exactly, ``NaN`` and ``+-inf`` included.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from mcap.exceptions import InvalidMagic
from mcap.records import Channel, Footer, Message, Metadata, Schema
from mcap.stream_reader import StreamReader
from mcap_protobuf.decoder import DecoderFactory

from evo.episode import Episode
from evo.record.mcap_file import (
    METADATA,
    SUMMARY,
    TOPIC_CURVE,
    TOPIC_EPISODE,
    TOPIC_STEP,
    TOPIC_TF,
    EpisodeInfo,
    EpisodeStep,
    RecordError,
)
from evo.record.rows import current_curve_key, decode_metadata, decode_row, from_json_number
from evo.run.files import JSONObject


@dataclass
class _Scan:
    """What one pass over an MCAP file found."""

    messages: dict[str, list[Message]] = field(default_factory=dict)
    schemas: dict[str, Schema | None] = field(default_factory=dict)
    schema_ids: dict[int, Schema] = field(default_factory=dict)
    channels: dict[int, Channel] = field(default_factory=dict)
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    complete: bool = False
    error: str | None = None


def _scan(path: str | Path, topics: Iterable[str] = ()) -> _Scan:
    """Messages of ``topics``, metadata records and whether the file is complete."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such MCAP file")
    if path.stat().st_size == 0:
        raise RecordError(f"{path}: empty file, not an MCAP recording")
    wanted = set(topics)
    scan = _Scan(messages={t: [] for t in wanted})
    seen = False
    with path.open("rb") as stream:
        records = iter(StreamReader(stream).records)
        while True:
            try:
                record = next(records)
            except StopIteration:
                break
            except InvalidMagic as err:
                if not seen:
                    raise RecordError(f"{path}: not an MCAP file ({err})") from None
                scan.error = f"bad closing magic: {err}"
                break
            except Exception as err:  # noqa: BLE001 - a cut-off file ends in any decode error
                scan.error = f"{type(err).__name__}: {err}"
                break
            seen = True
            _take(scan, record, wanted)
    scan.complete = scan.complete and scan.error is None  # footer and closing magic
    return scan


def _take(scan: _Scan, record: object, wanted: set[str]) -> None:
    """File one MCAP record into ``scan``."""
    if isinstance(record, Schema):
        scan.schema_ids[record.id] = record
    elif isinstance(record, Channel):
        scan.channels[record.id] = record
        scan.schemas[record.topic] = scan.schema_ids.get(record.schema_id)
    elif isinstance(record, Message):
        topic = scan.channels[record.channel_id].topic
        if topic in wanted:
            scan.messages[topic].append(record)
    elif isinstance(record, Metadata):
        scan.metadata[record.name] = dict(record.metadata)
    elif isinstance(record, Footer):
        scan.complete = True


def is_complete(path: str | Path) -> bool:
    """Whether the file was closed properly (has its footer and summary)."""
    return _scan(path).complete


def read_metadata(path: str | Path) -> JSONObject:
    """The metadata given when recording started, updated with the summary given at
    close (``fitness`` ...; absent when the writer died first).

    Raises:
        RecordError: when the file has no ``evo.metadata`` record.
    """
    scan = _scan(path)
    if METADATA not in scan.metadata:
        raise RecordError(f"{path}: no '{METADATA}' record; not an evo recording")
    values = decode_metadata(scan.metadata[METADATA])
    if SUMMARY in scan.metadata:
        values.update(decode_metadata(scan.metadata[SUMMARY]))
    return values


def read_curve(path: str | Path) -> pd.DataFrame:
    """The learning curve of an evaluation's ``.mcap`` file (or of a curve ``.csv``): one
    row per ``curve`` call, columns in first-seen order.

    Equals ``pandas.DataFrame(rows)`` of the rows written (up to the last flush). Keys
    of recordings made before metric keys were namespaced come under their current
    names (:func:`evo.record.rows.current_curve_key`).
    """
    if Path(path).suffix == ".csv":
        curve = pd.read_csv(path)
    else:
        scan = _scan(path, [TOPIC_CURVE])
        curve = pd.DataFrame([decode_row(m.data) for m in scan.messages[TOPIC_CURVE]])
    return curve.rename(columns=current_curve_key)


def read_json_topic(path: str | Path, topic: str) -> list[JSONObject]:
    """Every JSON message of ``topic`` in file order (as written)."""
    scan = _scan(path, [topic])
    return [json.loads(m.data) for m in scan.messages[topic]]


def _tf_decoder(path: str | Path, scan: _Scan) -> Callable[[bytes], Any]:
    schema = scan.schemas.get(TOPIC_TF)
    decoder = DecoderFactory().decoder_for("protobuf", schema) if schema else None
    if decoder is None:
        raise RecordError(f"{path}: {TOPIC_TF} has no protobuf schema")
    return decoder


def _fill(
    xpos: np.ndarray, xquat: np.ndarray, frames: slice, transforms: Any, index: dict[str, int]
) -> None:
    """Write the poses of one ``FrameTransforms`` message into ``frames`` of the arrays."""
    for tr in transforms:
        b = index[tr.child_frame_id]
        p, q = tr.translation, tr.rotation
        xpos[frames, b] = p.x, p.y, p.z
        xquat[frames, b] = q.w, q.x, q.y, q.z


def _episode(
    info: EpisodeInfo,
    tf: list[Message],
    steps: list[EpisodeStep],
    decode: Callable[[bytes], Any],
) -> Episode:
    """One episode from its info, its ``/tf`` messages (the still bodies' first, if
    any) and its step rows."""
    bodies = info["bodies"]
    index = {name: b for b, name in enumerate(bodies)}
    frames = int(info["frames"])
    xpos = np.zeros((frames, len(bodies), 3))
    xquat = np.zeros((frames, len(bodies), 4))
    xquat[:, 0, 0] = 1.0
    if info["still"]:
        _fill(xpos, xquat, slice(None), decode(tf[0].data).transforms, index)
    for t, message in enumerate(tf[-frames:]):
        _fill(xpos, xquat, slice(t, t + 1), decode(message.data).transforms, index)
    rewards = {
        term: np.array([from_json_number(s["reward"][term]) for s in steps], dtype=np.float64)
        for term in info["reward_terms"]
    }
    time = np.array([from_json_number(s["sim_time"]) for s in steps], dtype=np.float64)
    return Episode(
        index=int(info["index"]),
        env_step=int(info["env_step"]),
        time=time,
        xpos=xpos,
        xquat=xquat,
        target=np.array(info["target"], dtype=np.float64),
        rewards=rewards,
        success=bool(info["success"]),
    )


def read_episodes(path: str | Path) -> list[Episode]:
    """The recorded episodes, in recording order, as ``Episode`` values.

    Times, rewards and moving bodies' poses equal what was recorded bit for bit (after
    the recorder's frame stride); bodies at rest keep their first frame's pose; the
    world body (index 0) comes back at the origin. An episode cut short by a crash is
    left out.
    """
    scan = _scan(path, [TOPIC_EPISODE, TOPIC_TF, TOPIC_STEP])
    infos: list[EpisodeInfo] = [json.loads(m.data) for m in scan.messages[TOPIC_EPISODE]]
    if not infos:
        return []
    decode = _tf_decoder(path, scan)
    tf, steps = scan.messages[TOPIC_TF], scan.messages[TOPIC_STEP]
    episodes: list[Episode] = []
    tf_at = step_at = 0
    for info in infos:
        frames = int(info["frames"])
        tf_end = tf_at + frames + (1 if info["still"] else 0)
        step_end = step_at + frames
        if tf_end > len(tf) or step_end > len(steps):
            break
        rows: list[EpisodeStep] = [json.loads(m.data) for m in steps[step_at:step_end]]
        episodes.append(_episode(info, tf[tf_at:tf_end], rows, decode))
        tf_at, step_at = tf_end, step_end
    return episodes
