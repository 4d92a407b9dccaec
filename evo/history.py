"""One row of a run's history: an evaluated robot, and what the GA did with it.

``HistoryRow`` is the typed row the evolution appends after every result and hands to
its listeners (progress, ``run.mcap``/``run.rrd``). Its fields are the columns of
``history.csv``, in order (:data:`HISTORY_COLUMNS`); ``record()`` is the row as
``state.json`` and ``history.csv`` store it, where ``parents`` is one text cell, the
parents' names joined by ``;`` (:data:`PARENT_SEPARATOR`).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

PARENT_SEPARATOR = ";"
"""Joins the parents' names in the ``parents`` cell of history.csv and state.json."""

STATUSES = ("trained", "stopped-early", "failed")
"""``trained``: its whole budget; ``stopped-early``: early rejection stopped it (it never
enters the population; ``fitness`` is Eq. 8 over the episodes it completed and
``predicted`` the rule's prediction); ``failed``: the evaluation raised (``error``)."""


@dataclass(frozen=True, slots=True)
class HistoryRow:
    """One evaluated robot.

    Attributes:
        birth: Birth order in the run (0-based).
        name: The robot's unique name in the run (``robots/<name>.json``).
        method: The run's method label (``E+L``, ``R+R``, ...).
        parents: The parents' names; empty for a random robot.
        operator: How it was made (``random``, ``crossover``, ``random-fallback``, ...).
        budget: Its training budget, env steps.
        seed: Its evaluation seed.
        fitness: Eq. 8 (NaN when the evaluation failed).
        accepted: Whether it entered the population.
        replaced: The member it replaced ("" if none).
        env_steps: Env steps its training took.
        episodes: Episodes its fitness averages.
        wall_seconds: Wall time of its evaluation.
        error: The failure's traceback ("" if none).
        population_best: Best fitness in the population after it was recorded.
        population_mean: Mean fitness of the population after it was recorded.
        status: One of :data:`STATUSES`.
        predicted: Early rejection's predicted final fitness (NaN if none).
    """

    birth: int
    name: str
    method: str
    parents: tuple[str, ...]
    operator: str
    budget: int
    seed: int
    fitness: float
    accepted: bool
    replaced: str
    env_steps: int
    episodes: int
    wall_seconds: float
    error: str
    population_best: float
    population_mean: float
    status: str
    predicted: float

    def __post_init__(self) -> None:
        if self.status not in STATUSES:
            raise ValueError(f"status must be one of {', '.join(STATUSES)}, got {self.status!r}")

    @property
    def failed(self) -> bool:
        """Whether the evaluation failed."""
        return bool(self.error)

    @property
    def stopped_early(self) -> bool:
        """Whether early rejection stopped its training."""
        return self.status == "stopped-early"

    def record(self) -> dict[str, Any]:
        """The row as ``state.json`` and ``history.csv`` hold it (``parents`` joined)."""
        row = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        row["parents"] = PARENT_SEPARATOR.join(self.parents)
        return row

    @classmethod
    def from_record(cls, row: Mapping[str, Any]) -> HistoryRow:
        """The row ``record()`` wrote; a run from before ``status`` and ``predicted``
        existed gets ``trained``/``failed`` and NaN.

        Raises:
            KeyError, TypeError, ValueError: A missing column or a value of the wrong type.
        """
        parents = str(row["parents"])
        error = str(row["error"])
        return cls(
            birth=int(row["birth"]),
            name=str(row["name"]),
            method=str(row["method"]),
            parents=tuple(parents.split(PARENT_SEPARATOR)) if parents else (),
            operator=str(row["operator"]),
            budget=int(row["budget"]),
            seed=int(row["seed"]),
            fitness=float(row["fitness"]),
            accepted=bool(row["accepted"]),
            replaced=str(row["replaced"]),
            env_steps=int(row["env_steps"]),
            episodes=int(row["episodes"]),
            wall_seconds=float(row["wall_seconds"]),
            error=error,
            population_best=float(row["population_best"]),
            population_mean=float(row["population_mean"]),
            status=str(row.get("status") or ("failed" if error else "trained")),
            predicted=float(row.get("predicted", math.nan)),
        )


HISTORY_COLUMNS = tuple(f.name for f in dataclasses.fields(HistoryRow))
"""The columns of history.csv, in order (one row per evaluated robot)."""
