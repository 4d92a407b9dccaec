"""rerun ``.rrd`` recording of one evaluation, for the rerun viewer (SPEC section 6).

Entities:

* ``/scene/<body>``: one per body, its geometry logged once (static) under
  ``/scene/<body>/geometry`` in the body frame, its pose as a ``Transform3D`` on the
  ``replay`` timeline (columnar ``send_columns``, one call per moving body and
  episode); ``/scene/world`` holds the floor and walls.
* ``/episode/reward/<term>``, ``/episode/return``: per-frame reward terms and the
  running return on ``replay``; ``/episode/log``: one line per recorded episode.
* ``/curve/<key>``: every learning-curve value on the ``env_step`` timeline (keys with
  ``/`` become sub-paths, ``train/loss/critic`` -> ``/curve/train/loss/critic``).
* ``/metadata/<key>`` and ``/summary``: text documents.

``replay`` is the same clock as the MCAP file's (episodes end to end, 1 s apart).
Curve rows are buffered and sent every ``flush_every`` rows as one column per key,
which costs a few microseconds per row instead of a ``log`` call per value.
The default blueprint shows the 3D scene next to tabs of curve plots.
"""

from __future__ import annotations

import ctypes
import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any, TypedDict, Unpack

import mujoco
import numpy as np
import numpy.typing as npt
import rerun as rr
import rerun.blueprint as rrb
import rerun_bindings

from evo.episode import Episode
from evo.record.base import RecorderBase, RecorderOptions
from evo.record.geometry import BOX, CYLINDER, ELLIPSOID, Geometry, scene_geometry
from evo.record.mcap_file import EPISODE_GAP_NS, RecordError
from evo.record.rows import plain
from evo.run.files import full_disk

APPLICATION = "evo"
REPLAY = "replay"
ENV_STEP = "env_step"
SCENE = "scene"


def entity(*parts: str) -> str:
    """An entity path from raw name parts (each escaped; ``/`` inside a part nests)."""
    pieces = [rr.escape_entity_path_part(p) for part in parts for p in part.split("/")]
    return "/" + "/".join(pieces)


def _rgba8(rgba: npt.NDArray[np.float64]) -> npt.NDArray[np.uint8]:
    return np.clip(np.round(rgba * 255), 0, 255).astype(np.uint8)


class _Common(TypedDict):
    """What the boxes, cylinders and ellipsoids of one kind share."""

    centers: npt.NDArray[np.float64]
    quaternions: npt.NDArray[np.float64]  # x, y, z, w (rerun's order)
    colors: npt.NDArray[np.uint8]
    fill_mode: rr.components.FillMode


def log_geometry(rec: rr.RecordingStream, path: str, geometry: Geometry) -> None:
    """Log ``geometry`` under ``path`` as static boxes, cylinders and ellipsoids."""
    solid = rr.components.FillMode.Solid
    for kind in (BOX, CYLINDER, ELLIPSOID):
        part = geometry.of_kind(kind)
        if not len(part):
            continue
        common = _Common(centers=part.pos, quaternions=part.quat[:, [1, 2, 3, 0]],
                         colors=_rgba8(part.rgba), fill_mode=solid)
        if kind == BOX:
            archetype: Any = rr.Boxes3D(half_sizes=part.half_size, **common)
        elif kind == CYLINDER:
            archetype = rr.Cylinders3D(
                lengths=2 * part.half_size[:, 2], radii=part.half_size[:, 0], **common
            )
        else:
            archetype = rr.Ellipsoids3D(half_sizes=part.half_size, **common)
        rec.log(f"{path}/{kind}", archetype, static=True)


def log_bodies(rec: rr.RecordingStream, root: str, geometry: Geometry) -> list[str]:
    """Log each body's geometry (body frame) under ``root/<body>``; returns the paths."""
    paths = [entity(root, name) for name in geometry.body_names]
    for b, path in enumerate(paths):
        part = geometry.of_body(b)
        if len(part):
            log_geometry(rec, f"{path}/geometry", part)
    return paths


def log_text(rec: rr.RecordingStream, path: str, values: Mapping[str, Any]) -> None:
    """Each value as a static text document ``path/<key>`` (JSON for non-strings)."""
    for key, value in values.items():
        text = value if isinstance(value, str) else json.dumps(plain(value), indent=1)
        rec.log(entity(path, key), rr.TextDocument(text), static=True)


def eval_blueprint() -> rrb.Blueprint:
    """3D replay on the left; learning curve, losses and episode rewards on the right."""
    curves = rrb.Tabs(
        rrb.TimeSeriesView(
            name="return", origin="/curve/train",
            contents=["/curve/train/mean_return", "/curve/train/success_rate"],
        ),
        rrb.TimeSeriesView(name="losses", origin="/curve/train/loss"),
        rrb.TimeSeriesView(name="reward terms", origin="/curve/train/reward"),
        rrb.TimeSeriesView(name="whole curve", origin="/curve"),
    )
    episode = rrb.TimeSeriesView(name="episode reward", origin="/episode")
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Spatial3DView(name="replay", origin=f"/{SCENE}"),
            rrb.Vertical(curves, episode, row_shares=[3, 2]),
            column_shares=[3, 2],
        ),
        collapse_panels=True,
    )


FOOTER_END = b"RRF2FOOT"
"""What a complete ``.rrd`` ends with, but for its last 4 bytes (the footer's version)."""

FLUSH_S = 60.0
"""Longest wait for rerun to write what was logged, seconds."""

_abandoned: list[rr.RecordingStream] = []  # streams whose writer failed (:func:`_abandon`)


def finish_rrd(rec: rr.RecordingStream, path: Path) -> Exception | None:
    """Write everything logged to ``rec``'s file ``path`` and close it (with its footer).

    rerun writes the file on a thread of its own, which a failed write ends, reported
    only in rerun's log. On a full disk (or a file-size limit reached), or when the
    flush does not end, the stream is abandoned (:func:`_abandon`) and the reason is
    returned, an ``evo.run.files.WriteFailed`` (or a ``RecordError``), for the caller
    to raise: the run stops.
    """
    if (full := full_disk(path)) is not None:
        _abandon(rec)
        return full
    try:
        rec.flush(timeout_sec=FLUSH_S)
    except RuntimeError as err:  # timed out: rerun's writer is stuck
        _abandon(rec)
        return full_disk(path) or RecordError(f"{path}: {err}")
    rec.disconnect()
    return None if _has_footer(path) else full_disk(path)


def _abandon(rec: rr.RecordingStream) -> None:
    """Leave ``rec`` alone to the end of the process.

    A stream whose writer failed can be neither flushed, disconnected nor dropped (a
    dropped stream is flushed): each waits forever when it reaches the writer thread as
    it fails (rerun 0.41). Nor can :func:`release_streams` or rerun's own shutdown at
    exit run after it, as both flush every stream. The process is stopping (a failed
    write ends the run), so the stream is kept alive past the interpreter's end, and
    the process ends without either.
    """
    _abandoned.append(rec)
    ctypes.pythonapi.Py_IncRef(ctypes.py_object(rec))  # not freed even at exit
    rr.unregister_shutdown()


def _has_footer(path: Path) -> bool:
    try:
        with path.open("rb") as file:
            file.seek(-(len(FOOTER_END) + 4), 2)
            return file.read(len(FOOTER_END)) == FOOTER_END
    except OSError:
        return False


def release_streams() -> None:
    """Free the threads of recording streams nothing refers to any more.

    rerun keeps a dropped stream's batcher threads alive until such a sweep (``rr.init``
    does one); without it every evaluation would leave idle threads behind in a
    long-lived worker process.
    """
    if not _abandoned:  # the sweep flushes every stream, an abandoned one too
        rerun_bindings.flush_and_cleanup_orphaned_recordings()


def _save(rec: rr.RecordingStream, path: Path, blueprint: rrb.Blueprint) -> None:
    """``rec.save(path, default_blueprint=blueprint)`` without its thread leak.

    ``RecordingStream.save`` turns the blueprint into a temporary blueprint stream that
    rerun 0.41 never frees (two idle threads per call, so per evaluation in a long-lived
    worker). The same steps done here let that stream be closed. Falls back to the
    public call should rerun's internals change.
    """
    try:
        stream = rr.RecordingStream._from_native(
            rerun_bindings.new_blueprint(
                application_id=APPLICATION,
                make_default=False,
                make_thread_default=False,
                default_enabled=True,
            )
        )
    except (AttributeError, TypeError):
        rec.save(path, default_blueprint=blueprint)
        return
    try:
        stream.set_time("blueprint", sequence=0)
        blueprint._log_to_stream(stream)
        memory = stream.memory_recording()
        rerun_bindings.save(
            path=str(path),
            default_blueprint=memory.storage,
            recording=rec.to_native(),
            write_footer=True,
        )
    finally:
        stream.disconnect()


def open_rrd(
    path: Path, recording_id: str, blueprint: rrb.Blueprint, scene_root: str
) -> rr.RecordingStream:
    """A recording stream saving to ``path`` (parent folders made, file replaced), with
    z up at the root and at ``scene_root`` (the 3D view's origin)."""
    rec = rr.RecordingStream(APPLICATION, recording_id=recording_id)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        _save(rec, path, blueprint)
    except Exception as err:
        raise RecordError(f"{path}: cannot create the .rrd file: {err}") from err
    for root in ("/", scene_root):
        rec.log(root, rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    return rec


class RerunRecorder(RecorderBase):
    """Writes ``evals/<robot>.rrd``: the 3D replay of sampled episodes and the curve.

    Args:
        path: The ``.rrd`` file to create.
        model: The compiled model of the whole scene (robot, arena, rocks, target).
        metadata: Robot JSON, resolved config, seed, method, ...; ``metadata["name"]``
            (else the file name) is the recording id.
        **options: :class:`evo.record.base.RecorderOptions` (buffered curve rows are
            sent every ``flush_every`` rows; bodies at rest get one transform per episode).
    """

    def __init__(self, path: str | Path, model: mujoco.MjModel, metadata: Mapping[str, Any],
                 **options: Unpack[RecorderOptions]) -> None:
        self._set_options(options)
        self.path = Path(path)
        name = str(metadata.get("name", self.path.stem))
        self._rec: rr.RecordingStream | None = open_rrd(
            self.path, name, eval_blueprint(), f"/{SCENE}"
        )
        geometry = scene_geometry(model)
        self.body_names = geometry.body_names
        self.body_paths = log_bodies(self.rec, SCENE, geometry)
        log_text(self.rec, "metadata", metadata)
        self._rows: list[Mapping[str, float]] = []
        self._clock_ns = 0

    @property
    def rec(self) -> rr.RecordingStream:
        """The open recording stream."""
        if self._rec is None:
            raise RecordError(f"{self.path}: the recorder is closed")
        return self._rec

    def curve(self, row: Mapping[str, float]) -> None:
        """Buffer one learning-curve row; send the buffer every ``flush_every`` rows."""
        if "env_steps" not in row:
            raise KeyError(f"{self.path}: a curve row needs 'env_steps', got {list(row)}")
        self._rows.append(dict(row))
        if len(self._rows) >= self.flush_every:
            self._send_curve()

    def _send_curve(self) -> None:
        rows, self._rows = self._rows, []
        if not rows:
            return
        steps = np.array([round(float(r["env_steps"])) for r in rows], dtype=np.int64)
        keys = dict.fromkeys(k for r in rows for k in r if k != "env_steps")
        for key in keys:
            have = np.array([key in r for r in rows])
            values = np.array([float(r[key]) for r in rows if key in r], dtype=np.float64)
            self.rec.send_columns(
                entity("curve", key),
                indexes=[rr.TimeColumn(ENV_STEP, sequence=steps[have])],
                columns=rr.Scalars.columns(scalars=values),
            )

    def episode(self, episode: Episode) -> None:
        """Send one episode's body poses and rewards on the ``replay`` timeline."""
        frames = self._frames(episode, self._clock_ns)
        ep, stamps = frames.episode, frames.stamps
        clock = rr.TimeColumn(REPLAY, duration=stamps.astype("timedelta64[ns]"))
        start = rr.TimeColumn(REPLAY, duration=stamps[:1].astype("timedelta64[ns]"))
        for index, bodies, rows in (
            (clock, frames.moving, slice(None)),
            (start, frames.still, slice(0, 1)),
        ):
            for b in bodies:
                self.rec.send_columns(
                    self.body_paths[b],
                    indexes=[index],
                    columns=rr.Transform3D.columns(
                        translation=ep.xpos[rows, b], quaternion=ep.xquat[rows, b][:, [1, 2, 3, 0]]
                    ),
                )
        self._send_rewards(ep, clock)
        self._clock_ns = int(stamps[-1]) + EPISODE_GAP_NS

    def _send_rewards(self, ep: Episode, clock: rr.TimeColumn) -> None:
        total = np.zeros(ep.frames)
        for term, values in ep.rewards.items():
            values = np.asarray(values, dtype=np.float64)
            total += values
            self.rec.send_columns(
                entity("episode", "reward", term),
                indexes=[clock],
                columns=rr.Scalars.columns(scalars=values),
            )
        self.rec.send_columns(
            "/episode/return", indexes=[clock], columns=rr.Scalars.columns(scalars=np.cumsum(total))
        )
        self.rec.set_time(REPLAY, duration=np.timedelta64(self._clock_ns, "ns"))
        outcome = "success" if ep.success else "no success"
        self.rec.log(
            "/episode/log",
            rr.TextLog(
                f"episode {ep.index} (env step {ep.env_step}): {outcome}, "
                f"return {float(total.sum()):.4g}"
            ),
        )

    def _close(self, summary: Mapping[str, Any]) -> None:
        try:
            self._send_curve()
            log_text(self.rec, "summary", summary)
        finally:
            failed = finish_rrd(self._rec, self.path) if self._rec is not None else None
            self._rec = None  # the last reference: rerun may now free the stream
            release_streams()
            if failed is not None:
                raise failed
