"""MCAP recording of one evaluation, for Foxglove and for analysis (SPEC section 6).

Topics (all with self-describing schemas):

================  =========================  ===========================================
topic             schema                     content
================  =========================  ===========================================
``/scene``        ``foxglove.SceneUpdate``   once: one entity per body (frame = body
                                             name, primitives in the body frame), and
                                             ``world`` for the floor and walls
``/tf``           ``foxglove.FrameTransforms``  world -> every moving body, one per
                                             frame; bodies at rest (within
                                             ``still_tolerance``): once per episode
``/episode``      JSON ``evo.Episode``       one per recorded episode: index, env step,
                                             success, target, body names, reward terms
``/episode/step`` JSON ``evo.EpisodeStep``   one per frame: sim time, reward terms
                                             and the running return
``/train/curve``  JSON ``evo.CurveRow``      one learning-curve row per collector batch
================  =========================  ===========================================

Metadata records: ``evo.metadata`` (robot JSON, resolved config, seed, method, ...) at
the start and ``evo.summary`` (fitness, ...) at close.

Time: MCAP has one clock per file; here it is a replay clock. Recorded episodes are
laid end to end on it (each starts 1 s after the previous one ended, frames at
``start + sim_time - sim_time[0]``), so Foxglove plays them one after another.
A curve row is stamped with the clock's current position; plot curves against their
``env_steps`` field.

Crash safety: the file is flushed (the open chunk closed and written) after the scene,
after every episode and every ``flush_every`` curve rows; a killed process leaves a
file whose messages up to the last flush ``evo.record.readback`` recovers.
"""

from __future__ import annotations

import json
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path
from typing import Any, TypedDict, Unpack

import foxglove
import mujoco
import numpy as np
import numpy.typing as npt
from foxglove.channels import SceneUpdateChannel
from foxglove.mcap import MCAPCompression, MCAPWriteOptions
from foxglove.messages import (
    Color,
    CubePrimitive,
    CylinderPrimitive,
    FrameTransforms,
    Pose,
    Quaternion,
    SceneEntity,
    SceneUpdate,
    SpherePrimitive,
    TextPrimitive,
    Vector3,
)

from evo.episode import Episode
from evo.record.base import RecorderBase, RecorderOptions
from evo.record.geometry import BOX, CYLINDER, Geometry, scene_geometry
from evo.record.rows import encode_metadata, encode_row, json_number, object_schema, plain
from evo.record.transforms import PARENT_FRAME, TransformEncoder
from evo.run.files import JSONObject, JSONValue, full_disk

TOPIC_SCENE = "/scene"
TOPIC_TF = "/tf"
TOPIC_EPISODE = "/episode"
TOPIC_STEP = "/episode/step"
TOPIC_CURVE = "/train/curve"
METADATA = "evo.metadata"
SUMMARY = "evo.summary"
PROFILE = "evo"
F64 = npt.NDArray[np.float64]
EPISODE_GAP_NS = 1_000_000_000
"""Gap between two recorded episodes on the replay clock, ns."""

_CURVE_SCHEMA = object_schema(
    "evo.CurveRow", {"env_steps": "number"}, additional=True,
    description="One learning-curve row; keys with '/' nest (train/kl -> train.kl).")
_EPISODE_SCHEMA = object_schema("evo.Episode", {
    "index": "integer", "env_step": "integer", "success": "boolean", "frames": "integer",
    "target": {"type": "array", "items": {"type": "number"}}})
_STEP_SCHEMA = object_schema("evo.EpisodeStep", {
    "episode": "integer", "step": "integer", "sim_time": "number",
    "reward": {"type": "object", "additionalProperties": {"type": "number"}},
    "return": "number"})


class EpisodeInfo(TypedDict):
    """A message of ``/episode``: one recorded episode, before its frames."""

    index: int
    env_step: int
    success: bool
    frames: int
    target: list[float]
    clock_start: int  # replay-clock ns of its first frame
    clock_end: int
    bodies: list[str]  # the model's bodies, in order
    moving: list[str]  # those with a transform per frame
    still: list[str]  # those with one transform at the start
    reward_terms: list[str]


EpisodeStep = TypedDict("EpisodeStep", {
    "episode": int, "step": int, "sim_time": float | str | None,
    "reward": dict[str, float | str | None], "return": float | str | None})
"""A message of ``/episode/step`` (numbers as ``evo.record.rows.json_number`` writes
them: NaN as null, infinities as strings)."""


class RecordError(RuntimeError):
    """A recording file cannot be written or read; the message names the file."""


def _colour(rgba: np.ndarray) -> Color:
    return Color(r=float(rgba[0]), g=float(rgba[1]), b=float(rgba[2]), a=float(rgba[3]))


def _pose(pos: np.ndarray, quat_wxyz: np.ndarray) -> Pose:
    w, x, y, z = (float(v) for v in quat_wxyz)
    return Pose(
        position=Vector3(x=float(pos[0]), y=float(pos[1]), z=float(pos[2])),
        orientation=Quaternion(x=x, y=y, z=z, w=w),
    )


def scene_entity(
    geometry: Geometry, entity_id: str, frame_id: str, texts: list[TextPrimitive] | None = None
) -> SceneEntity:
    """All of ``geometry`` (and ``texts``) as one Foxglove entity drawn in ``frame_id``.

    Foxglove sizes are full extents (MuJoCo's are halves); cylinders get both end
    scales 1 (the default 0 draws an invisible cone).
    """
    cubes, cylinders, spheres = [], [], []
    for i, kind in enumerate(geometry.kind):
        pose = _pose(geometry.pos[i], geometry.quat[i])
        sx, sy, sz = (2 * float(v) for v in geometry.half_size[i])
        size, colour = Vector3(x=sx, y=sy, z=sz), _colour(geometry.rgba[i])
        if kind == BOX:
            cubes.append(CubePrimitive(pose=pose, size=size, color=colour))
        elif kind == CYLINDER:
            cylinders.append(
                CylinderPrimitive(
                    pose=pose, size=size, bottom_scale=1.0, top_scale=1.0, color=colour
                )
            )
        else:
            spheres.append(SpherePrimitive(pose=pose, size=size, color=colour))
    return SceneEntity(
        frame_id=frame_id,
        id=entity_id,
        frame_locked=True,
        cubes=cubes,
        cylinders=cylinders,
        spheres=spheres,
        texts=texts or [],
    )


def body_scene(geometry: Geometry) -> SceneUpdate:
    """One entity per body that has primitives, each locked to its body's frame."""
    entities = []
    for b, name in enumerate(geometry.body_names):
        part = geometry.of_body(b)
        if len(part):
            frame = PARENT_FRAME if b == 0 else name
            entities.append(scene_entity(part, entity_id=name, frame_id=frame))
    return SceneUpdate(entities=entities)


class McapFile:
    """A Foxglove MCAP writer with its own context, metadata and close-time summary.

    Args:
        path: File to create (parent folders are made; an existing file is replaced).
        metadata: Written at once as the ``evo.metadata`` record.
    """

    def __init__(self, path: str | Path, metadata: Mapping[str, Any]) -> None:
        self.path = Path(path)
        self.context = foxglove.Context()
        self.channels: list[foxglove.Channel] = []
        options = MCAPWriteOptions(
            compression=MCAPCompression.Zstd,
            compression_level=1,
            compression_threads=0,
            profile=PROFILE,
        )
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self.writer = foxglove.open_mcap(
                self.path, allow_overwrite=True, context=self.context, writer_options=options
            )
        except Exception as err:
            raise RecordError(f"{self.path}: cannot create the MCAP file: {err}") from err
        with self._writing():
            self.writer.write_metadata(METADATA, encode_metadata(metadata))

    @contextmanager
    def _writing(self) -> Iterator[None]:
        """A failed write of the writer's (which names no cause: the cause goes to its own
        log) is ``evo.run.files.WriteFailed`` when the disk is why."""
        try:
            yield
        except Exception as err:
            if (full := full_disk(self.path)) is not None:
                raise full from err
            raise

    def channel(self, topic: str, schema: foxglove.Schema | JSONObject,
                message_encoding: str) -> foxglove.Channel:
        """A channel of this file, released when the file is closed."""
        channel = foxglove.Channel(
            topic, schema=schema, message_encoding=message_encoding, context=self.context
        )
        self.channels.append(channel)
        return channel

    def json_channel(self, topic: str, schema: Mapping[str, JSONValue]) -> foxglove.Channel:
        """A JSON channel with a JSON schema (``title`` names the schema)."""
        return self.channel(topic, dict(schema), "json")

    def flush(self) -> None:
        """Close the open chunk and write it to disk."""
        with self._writing():
            self.writer.flush()

    def close(self, summary: Mapping[str, Any]) -> None:
        """Write ``summary`` as the ``evo.summary`` record and finish the file."""
        try:
            with self._writing():
                self.writer.write_metadata(SUMMARY, encode_metadata(summary))
        finally:
            try:
                with self._writing():
                    self.writer.close()
            finally:
                self._release_channels()

    def _release_channels(self) -> None:
        """Close this file's channels and drop them from foxglove's registry.

        ``foxglove.Channel`` registers every channel in a module-level dict that nothing
        ever empties (foxglove-sdk 0.30), so without this each recorded evaluation would
        leave its channels behind in a long-lived worker process.
        """
        registry = getattr(foxglove.channel, "_channels_by_id", {})
        for channel in self.channels:
            registry.pop(channel.id(), None)
            channel.close()
        self.channels.clear()


def _step_lines(episode: Episode) -> list[bytes]:
    """The ``/episode/step`` JSON messages of ``episode``, one per frame."""
    terms = list(episode.rewards)
    values = np.zeros((episode.frames, len(terms)))
    for j, term in enumerate(terms):
        values[:, j] = episode.rewards[term]
    table = np.column_stack([episode.time, values, np.cumsum(values.sum(axis=1))])
    rows = table.tolist()
    if not np.isfinite(table).all():
        return [_step_json(episode.index, k, terms, row) for k, row in enumerate(rows)]
    # Fast path: every value finite, so Python's float repr is valid, exact JSON.
    reward = ",".join(json.dumps(t).replace("%", "%%") + ":%r" for t in terms)
    fmt = '{"episode":%d,"step":%d,"sim_time":%r,"reward":{' + reward + '},"return":%r}'
    return [(fmt % (episode.index, k, *row)).encode() for k, row in enumerate(rows)]


def _step_json(index: int, step: int, terms: list[str], row: list[float]) -> bytes:
    """One ``/episode/step`` message with non-finite values encoded as in curve rows."""
    safe = [json_number("reward", v) for v in row]
    obj = {
        "episode": index,
        "step": step,
        "sim_time": safe[0],
        "reward": dict(zip(terms, safe[1:-1], strict=True)),
        "return": safe[-1],
    }
    return json.dumps(obj, allow_nan=False, separators=(",", ":")).encode()


class McapRecorder(RecorderBase):
    """Writes ``evals/<robot>.mcap``: geometry, sampled episodes, curve and metadata.

    Args:
        path: The MCAP file to create.
        model: The compiled model of the whole scene (robot, arena, rocks, target).
        metadata: Robot JSON, resolved config, seed, method, ... (JSON-able values).
        **options: :class:`evo.record.base.RecorderOptions` (flush to disk every
            ``flush_every`` curve rows).
    """

    def __init__(self, path: str | Path, model: mujoco.MjModel, metadata: Mapping[str, Any],
                 **options: Unpack[RecorderOptions]) -> None:
        self._set_options(options)
        self.file = McapFile(path, metadata)
        self.path = self.file.path
        geometry = scene_geometry(model)
        self.body_names = geometry.body_names
        self._encoders: dict[tuple[str, ...], TransformEncoder] = {}
        ctx = self.file.context
        self._scene = SceneUpdateChannel(TOPIC_SCENE, context=ctx)
        self._tf = self.file.channel(TOPIC_TF, FrameTransforms.get_schema(), "protobuf")
        self._episode = self.file.json_channel(TOPIC_EPISODE, _EPISODE_SCHEMA)
        self._step = self.file.json_channel(TOPIC_STEP, _STEP_SCHEMA)
        self._curve = self.file.json_channel(TOPIC_CURVE, _CURVE_SCHEMA)
        self._scene.log(body_scene(geometry), log_time=0)
        self.file.flush()
        self._clock_ns = 0
        self._rows = 0

    def curve(self, row: Mapping[str, float]) -> None:
        """Write one learning-curve row; flush every ``flush_every`` rows."""
        self._check_open()
        if "env_steps" not in row:
            raise KeyError(f"{self.path}: a curve row needs 'env_steps', got {list(row)}")
        self._curve.log(encode_row(row), log_time=self._clock_ns)
        self._rows += 1
        if self._rows % self.flush_every == 0:
            self.file.flush()

    def _check_open(self) -> None:
        if self.closed:
            raise RecordError(f"{self.path}: the recorder is closed")

    def _encoder(self, names: tuple[str, ...]) -> TransformEncoder:
        if names not in self._encoders:
            self._encoders[names] = TransformEncoder(names)
        return self._encoders[names]

    def episode(self, episode: Episode) -> None:
        """Write one episode (info, transforms, per-frame rewards) and flush.

        Bodies at rest (the target, resting rocks; see ``still_tolerance``) get one
        transform at the episode's start instead of one per frame.
        """
        self._check_open()
        frames = self._frames(episode, self._clock_ns)
        ep, stamps = frames.episode, frames.stamps.tolist()
        names = np.array(self.body_names)
        moving, still = names[frames.moving].tolist(), names[frames.still].tolist()
        info: EpisodeInfo = {
            "index": ep.index,
            "env_step": ep.env_step,
            "success": bool(ep.success),
            "frames": ep.frames,
            "target": plain(np.asarray(ep.target, np.float64)),
            "clock_start": stamps[0],
            "clock_end": stamps[-1],
            "bodies": list(self.body_names),
            "moving": moving,
            "still": still,
            "reward_terms": list(ep.rewards),
        }
        self._episode.log(json.dumps(info).encode(), log_time=stamps[0])
        if still:
            first = self._encoder(tuple(still)).encode(
                stamps[:1], ep.xpos[:1, frames.still], ep.xquat[:1, frames.still]
            )
            self._tf.log(first[0], log_time=stamps[0])
        tf = self._encoder(tuple(moving)).encode(
            stamps, ep.xpos[:, frames.moving], ep.xquat[:, frames.moving]
        )
        log_tf, log_step = self._tf.log, self._step.log
        for stamp, message in zip(stamps, tf, strict=True):
            log_tf(message, log_time=stamp)
        for stamp, line in zip(stamps, _step_lines(ep), strict=True):
            log_step(line, log_time=stamp)
        self._clock_ns = stamps[-1] + EPISODE_GAP_NS
        self.file.flush()

    def _close(self, summary: Mapping[str, Any]) -> None:
        self.file.close(summary)
