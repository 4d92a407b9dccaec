"""Run-level recording: ``run.mcap`` and ``run.rrd`` in the run directory.

One ``Birth`` per evaluated robot (birth order, name, fitness, accepted or not, the
population's best and mean fitness after it, plus any extra columns such as the
generation or the budget), and the geometry of chosen robots (the best ones) as a
static scene: robots stand side by side along +y, in the order they were logged,
each with its name and fitness as a label.

``run.mcap`` topics: ``/ga/births`` (JSON ``evo.Birth``; time = birth index in
seconds) and ``/ga/robots`` (``foxglove.SceneUpdate``, one entity per robot).
``run.rrd``: ``/ga/fitness/accepted`` and ``/ga/fitness/rejected`` as points,
``/ga/population/best`` and ``/ga/population/mean`` as lines on the ``birth``
timeline, ``/ga/log`` one text line per birth, and ``/robots/<name>``.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypedDict

import mujoco
import numpy as np
import pandas as pd
import rerun as rr
import rerun.blueprint as rrb
from foxglove.channels import SceneUpdateChannel
from foxglove.messages import Color, Pose, SceneUpdate, TextPrimitive, Vector3

from evo.record.base import RecorderBase
from evo.record.geometry import Geometry, rest_pose, scene_geometry
from evo.record.mcap_file import McapFile, scene_entity
from evo.record.readback import read_json_topic
from evo.record.rows import flatten, json_number, object_schema, plain
from evo.record.rrd import entity, finish_rrd, log_geometry, open_rrd, release_streams
from evo.run.files import JSONObject
from evo.run.layout import RunLayout

TOPIC_BIRTHS = "/ga/births"
TOPIC_ROBOTS = "/ga/robots"
BIRTH = "birth"
ROBOT_SPACING = 0.4
"""Distance between neighbouring robots in the run's robot scene, m."""

_BIRTH_SCHEMA = object_schema("evo.Birth", {
    "birth": "integer", "name": "string", "fitness": "number", "accepted": "boolean",
    "population_best": "number", "population_mean": "number"}, additional=True)


@dataclass(frozen=True)
class Birth:
    """One evaluated robot, as the GA loop saw it.

    Attributes:
        index: Birth order, 0 for the first robot evaluated.
        name: The robot's name (``robot-<hash8>``).
        fitness: Its fitness.
        accepted: Whether it entered the population.
        population_best: Best fitness in the population after this birth.
        population_mean: Mean fitness of the population after this birth.
        extra: More columns (generation, budget, parents, wall time, ...).
    """

    index: int
    name: str
    fitness: float
    accepted: bool
    population_best: float
    population_mean: float
    extra: Mapping[str, Any] = field(default_factory=dict)

    def row(self) -> JSONObject:
        """The birth as one flat JSON-ready row."""
        row: JSONObject = {
            "birth": self.index,
            "name": self.name,
            "fitness": json_number("fitness", self.fitness),
            "accepted": bool(self.accepted),
            "population_best": json_number("population_best", self.population_best),
            "population_mean": json_number("population_mean", self.population_mean),
        }
        for key, value in self.extra.items():
            if key in row:
                raise ValueError(f"birth extra {key!r} clashes with a standard column")
            row[key] = json_number(key, value) if isinstance(value, float) else plain(value)
        return row


def robot_geometry(model: mujoco.MjModel, offset: np.ndarray) -> Geometry:
    """The robot's primitives in the world, in its rest pose, moved by ``offset``.

    Keeps the bodies of the tree rooted at ``brain`` (all non-world bodies if the
    model has none), so a whole-scene model gives just the robot.
    """
    geometry = scene_geometry(model)
    names = geometry.body_names
    if "brain" in names:
        root = names.index("brain")
        keep = model.body_rootid[geometry.body] == root
    else:
        keep = geometry.body != 0
    xpos, xquat = rest_pose(model)
    xpos = xpos + offset
    return geometry.select(keep).posed(xpos, xquat)


def read_births(path: str | Path) -> pd.DataFrame:
    """The births of a ``run.mcap``, one row each, in birth order."""
    return pd.DataFrame([flatten(row) for row in read_json_topic(path, TOPIC_BIRTHS)])


class RunMetadata(TypedDict):
    """What ``run.mcap`` records when it opens (``evo.evolution.RunLog``)."""

    config: str  # the resolved config.yaml
    seed: int
    method: str
    name: str  # the run directory's name


class RunRecorder(RecorderBase):
    """Writes ``run.mcap`` and ``run.rrd`` for a whole evolution run.

    Args:
        directory: The run directory (made if missing).
        metadata: Resolved config, seed, method, ... (JSON-able values).
        mcap: Write ``run.mcap``.
        rerun: Write ``run.rrd``.
    """

    def __init__(
        self,
        directory: str | Path,
        metadata: Mapping[str, Any] | None = None,
        *,
        mcap: bool = True,
        rerun: bool = True,
    ) -> None:
        self.directory = Path(directory)
        meta = dict(metadata or {})
        layout = RunLayout(self.directory)
        self.mcap = McapFile(layout.run_mcap, meta) if mcap else None
        self.rec: rr.RecordingStream | None = None
        if rerun:
            try:
                name = str(meta.get("name", "run"))
                self.rec = open_rrd(layout.run_rrd, name, _blueprint(), "/robots")
            except BaseException:
                if self.mcap is not None:
                    self.mcap.close({"status": "failed", "error": "could not open run.rrd"})
                raise
        self._robots = 0
        self._last_birth = 0
        if self.mcap is not None:
            self._births = self.mcap.json_channel(TOPIC_BIRTHS, _BIRTH_SCHEMA)
            self._scene = SceneUpdateChannel(TOPIC_ROBOTS, context=self.mcap.context)
            self.mcap.flush()
        if self.rec is not None:
            _style_series(self.rec)

    def birth(self, birth: Birth) -> None:
        """Record one evaluated robot (flushed at once: births are rare).

        MCAP log time counts results in the order they arrived (one second each), so it
        stays monotonic when parallel evaluations finish out of birth order.
        """
        self._last_birth += 1
        if self.mcap is not None:
            self._births.log(
                json.dumps(birth.row(), allow_nan=False).encode(),
                log_time=self._last_birth * 1_000_000_000,
            )
            self.mcap.flush()
        if self.rec is not None:
            self._rrd_birth(birth)

    def _rrd_birth(self, birth: Birth) -> None:
        assert self.rec is not None
        rec = self.rec
        rec.set_time(BIRTH, sequence=birth.index)
        kind = "accepted" if birth.accepted else "rejected"
        rec.log(f"/ga/fitness/{kind}", rr.Scalars(float(birth.fitness)))
        rec.log("/ga/population/best", rr.Scalars(float(birth.population_best)))
        rec.log("/ga/population/mean", rr.Scalars(float(birth.population_mean)))
        rec.log(
            "/ga/log",
            rr.TextLog(f"birth {birth.index}: {birth.name} fitness {birth.fitness:.4g} ({kind})"),
        )

    def robot(self, name: str, model: mujoco.MjModel, *, fitness: float | None = None) -> None:
        """Add a robot's geometry (rest pose) to the run's static robot scene.

        Args:
            name: The robot's name (its entity id).
            model: Its compiled model (robot alone or in a scene).
            fitness: Shown in the label when given.
        """
        offset = np.array([0.0, ROBOT_SPACING * self._robots, 0.0])
        self._robots += 1
        geometry = robot_geometry(model, offset)
        label = name if fitness is None else f"{name}  F={fitness:.4g}"
        top = offset + [
            0.0,
            0.0,
            float((geometry.pos[:, 2] + geometry.half_size.max(1)).max(initial=0.0)) + 0.05,
        ]
        if self.mcap is not None:
            self._scene_robot(name, geometry, label, top)
        if self.rec is not None:
            path = entity("robots", name)
            log_geometry(self.rec, path, geometry)
            self.rec.log(f"{path}/label", rr.Points3D([top], labels=[label]), static=True)

    def _scene_robot(self, name: str, geometry: Geometry, label: str, top: np.ndarray) -> None:
        assert self.mcap is not None
        text = TextPrimitive(
            pose=Pose(position=Vector3(x=float(top[0]), y=float(top[1]), z=float(top[2]))),
            billboard=True,
            font_size=14.0,
            scale_invariant=True,
            color=Color(r=1.0, g=1.0, b=1.0, a=1.0),
            text=label,
        )
        item = scene_entity(geometry, entity_id=name, frame_id="world", texts=[text])
        self._scene.log(SceneUpdate(entities=[item]), log_time=self._last_birth * 1_000_000_000)
        self.mcap.flush()

    def _close(self, summary: Mapping[str, Any]) -> None:
        """Finish both files with ``summary`` (best fitness, ...)."""
        try:
            if self.mcap is not None:
                self.mcap.close(summary)
        finally:
            if self.rec is not None:
                failed = finish_rrd(self.rec, RunLayout(self.directory).run_rrd)
                self.rec = None  # the last reference: rerun may now free the stream
                release_streams()
                if failed is not None:
                    raise failed


def _style_series(rec: rr.RecordingStream) -> None:
    """Colours and names of the fitness plot's series (static)."""
    rec.log(
        "/ga/fitness/accepted",
        rr.SeriesPoints(colors=[[60, 180, 75]], names=["accepted"], marker_sizes=[3.0]),
        static=True,
    )
    rec.log(
        "/ga/fitness/rejected",
        rr.SeriesPoints(colors=[[200, 60, 60]], names=["rejected"], marker_sizes=[3.0]),
        static=True,
    )
    rec.log(
        "/ga/population/best", rr.SeriesLines(colors=[[240, 190, 40]], names=["best"]), static=True
    )
    rec.log(
        "/ga/population/mean", rr.SeriesLines(colors=[[90, 140, 230]], names=["mean"]), static=True
    )


def _blueprint() -> rrb.Blueprint:
    """Fitness over births on the left, the best robots on the right."""
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(
                rrb.TimeSeriesView(name="fitness", origin="/ga"),
                rrb.TextLogView(name="births", origin="/ga/log"),
                row_shares=[3, 1],
            ),
            rrb.Spatial3DView(name="best robots", origin="/robots"),
            column_shares=[3, 2],
        ),
        collapse_panels=True,
    )
