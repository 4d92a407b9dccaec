"""The store of an evolution run: saves, loads and checks its resumable state.

The whole state (population, history, breeding RNG, next birth, robots in flight) is
``state.json``, written atomically after every submission and every result, before the
files derived from it (``history.csv``, ``population.json``, ``summary.json``).
:meth:`RunStore.load` reads it back and checks it against the files it refers to,
writing nothing. The evolution loop is given a store (``evo.evolution.Evolution``), and
``python evo/main.py`` makes it through ``evo.main.EvolveCode``: a store that also keeps
its files elsewhere, or one that fails at a chosen write (as the fault tests do), is a
subclass that overrides ``save_robot``, ``write_state``, ``write_json`` or ``write_history``.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, TypedDict, cast

import numpy as np

from evo.robot.io import RobotFileError, load_robot, save_robot
from evo.robot.tree import Robot
from evo.robot.validate import InvalidRobotError
from evo.run import files
from evo.run.layout import RunLayout
from evo.run.records import (
    Candidate,
    HistoryRow,
    Member,
    RunSummary,
    read_history,
    write_history,
    write_run_summary,
)

STATE_VERSION = 1


class RngState(TypedDict):
    """The breeding generator's ``bit_generator.state`` (numpy's ``PCG64``), as
    ``state.json`` holds it."""

    bit_generator: str
    state: dict[str, int]  # the 128-bit ``state`` and ``inc``
    has_uint32: int
    uinteger: int


def rng_state(rng: np.random.Generator) -> RngState:
    """``rng``'s state to save (a copy: the generator goes on drawing)."""
    return cast(RngState, dict(rng.bit_generator.state))


@dataclass(frozen=True)
class SavedState:
    """A run's resumable state (what ``state.json`` holds), checked when loaded.

    Attributes:
        seed: The run's root seed.
        next_birth: The birth number of the next robot.
        rng: The breeding generator's ``bit_generator.state``.
        population: The population's members.
        history: Every evaluated robot, in the order recorded.
        pending: The robots in flight.
        wall_seconds: Wall time over every session so far.
    """

    seed: int
    next_birth: int
    rng: RngState
    population: list[Member]
    history: list[HistoryRow]
    pending: list[Candidate]
    wall_seconds: float

    def ending_at(self, robot_budget: int) -> tuple[SavedState, list[Candidate]]:
        """This state for a run of ``robot_budget`` robots, and the robots in flight it
        drops: those born at ``robot_budget`` or later, which a run of that many never
        breeds (a run stopped after its N-th result, with robot N+1 in flight, then
        resumed with ``ga.robot_budget=N``). The breeding generator stays where it is:
        extended again later, the run breeds its robots from N on with other draws than
        a straight run would.

        Raises:
            ValueError: A robot born at ``robot_budget`` or later is evaluated already.
        """
        past = [r.name for r in self.history if r.birth >= robot_budget]
        if past:
            raise ValueError(f"robots {past} are evaluated and born at {robot_budget} or "
                             f"later: a run of {robot_budget} robots cannot hold them")
        dropped = [t for t in self.pending if t.birth >= robot_budget]
        if not dropped:
            return self, []
        kept = [t for t in self.pending if t.birth < robot_budget]
        return replace(self, next_birth=robot_budget, pending=kept), dropped


class RunStore:
    """The files of one evolution run directory (``evo.run.layout.RunLayout``)."""

    def __init__(self, root: Path) -> None:
        self.layout = RunLayout(root)

    @property
    def root(self) -> Path:
        """The run directory."""
        return self.layout.root

    def prepare(self) -> None:
        """Make the run directory and its ``robots/`` folder, if missing."""
        self.layout.robots.mkdir(parents=True, exist_ok=True)

    # ---- robots ---------------------------------------------------------------------------
    def save_robot(self, name: str, robot: Robot) -> Path:
        """Write ``robots/<name>.json`` (atomically; a failure is ``files.WriteFailed``)."""
        with files.writing(self.layout.robot(name)) as path:
            return save_robot(robot, path)

    def discard(self, name: str) -> list[Path]:
        """Remove a robot that the saved state no longer holds (dropped from flight:
        :meth:`SavedState.ending_at`): its ``robots/<name>.json`` and whatever its
        evaluation had written to ``evals/``; returns the files removed."""
        layout = self.layout
        paths = (layout.robot(name), layout.policy(name), layout.curve(name),
                 layout.mcap(name), layout.rrd(name), layout.error_log(name))
        removed = [path for path in paths if path.exists()]
        for path in removed:
            path.unlink()
        return removed

    def load_robot(self, name: str) -> Robot:
        """Read ``robots/<name>.json``.

        Raises:
            RobotFileError, InvalidRobotError: The file is missing or not a valid robot.
        """
        return load_robot(self.layout.robot(name))

    # ---- the state ------------------------------------------------------------------------
    def has_state(self) -> bool:
        """Whether the run has saved a state."""
        return self.layout.state.exists()

    def save(self, state: SavedState, summary: RunSummary) -> None:
        """Write the state first (atomically), then the files derived from it."""
        population = [member.record() for member in state.population]
        self.write_state({
            "version": STATE_VERSION,
            "seed": state.seed,
            "next_birth": state.next_birth,
            "rng": state.rng,
            "population": population,
            "history": [row.record() for row in state.history],
            "pending": [t.record() for t in state.pending],
            "wall_seconds": state.wall_seconds,
        })
        if state.history:
            self.write_history(state.history)
        self.write_json(self.layout.population, {"population": population})
        write_run_summary(self.layout.summary, summary)

    def write_state(self, data: Mapping[str, object]) -> Path:
        """Write ``state.json`` atomically (through :meth:`write_json`)."""
        return self.write_json(self.layout.state, data)

    def write_json(self, path: Path, data: Mapping[str, object]) -> Path:
        """Write one of the run's JSON files atomically (``evo.run.files.write_json``)."""
        return files.write_json(path, data)

    def write_history(self, rows: list[HistoryRow]) -> Path:
        """Write ``history.csv`` atomically (``evo.run.records.write_history``)."""
        return write_history(self.layout.history, rows)

    def load(self) -> SavedState:
        """Read and check ``state.json`` and the files it refers to, writing nothing.

        Checked: the state parses, has this version, its RNG state loads, every birth up
        to ``next_birth`` is either in the history or in flight (once), every robot it
        names is a valid file in ``robots/``, the population's members are in the
        history, and ``history.csv`` (derived from the state, and rebuilt from it) holds
        no row the state does not.

        Raises:
            ValueError: Naming the file and what is wrong with it.
        """
        path = self.layout.state
        state = self._read_state()
        try:
            np.random.default_rng().bit_generator.state = state["rng"]
            history = [HistoryRow.from_record(row) for row in state["history"]]
            pending = [Candidate.from_record(t) for t in state["pending"]]
            fitness = {str(m["name"]): float(m["fitness"]) for m in state["population"]}
            seed, next_birth = int(state["seed"]), int(state["next_birth"])
            wall_seconds = float(state["wall_seconds"])
        except (KeyError, TypeError, ValueError, AttributeError) as err:
            raise ValueError(f"{path}: unreadable run state ({err})") from None
        births = sorted([r.birth for r in history] + [t.birth for t in pending])
        names = [r.name for r in history] + [t.name for t in pending]
        if births != list(range(next_birth)):
            raise ValueError(f"{path}: inconsistent run state (births {births} recorded or "
                             f"in flight, expected each of 0..{next_birth - 1} once)")
        if not set(fitness) <= set(names):
            raise ValueError(f"{path}: inconsistent run state (population members "
                             f"{sorted(set(fitness) - set(names))} are not in its history)")
        robots = {}
        for name in dict.fromkeys(names):
            try:
                robots[name] = self.load_robot(name)
            except (RobotFileError, InvalidRobotError) as err:
                raise ValueError(f"{path} needs robot {name}: {err}") from None
        self._check_history_csv([r.name for r in history])
        population = [Member(name, robots[name], f) for name, f in fitness.items()]
        return SavedState(seed, next_birth, state["rng"], population, history, pending,
                          wall_seconds)

    def _read_state(self) -> dict[str, Any]:
        """``state.json`` parsed, of this version."""
        path = self.layout.state
        try:
            state = json.loads(path.read_text())
        except FileNotFoundError:
            raise ValueError(f"{path}: no saved state; is this an evo run directory?") from None
        except (OSError, ValueError) as err:
            raise ValueError(f"{path}: unreadable run state ({err})") from None
        if not isinstance(state, dict) or state.get("version") != STATE_VERSION:
            version = state.get("version") if isinstance(state, dict) else None
            raise ValueError(f"{path}: unreadable run state (state version {version!r}, "
                             f"expected {STATE_VERSION})")
        return state

    def _check_history_csv(self, names: list[str]) -> None:
        """``history.csv`` may lag the state by a row, never lead it or disagree with it."""
        path = self.layout.history
        if not path.exists():
            return
        try:
            rows = read_history(path)["name"].astype(str).tolist()
        except (OSError, ValueError, KeyError) as err:
            raise ValueError(f"{path}: unreadable ({err}); it is rebuilt from state.json if "
                             "you move it away") from None
        if rows != names[: len(rows)]:
            raise ValueError(f"{path}: its rows do not match state.json's history (is it "
                             "from another run?); it is rebuilt from state.json if you move "
                             "it away")

    # ---- what an earlier run left -------------------------------------------------------
    def evaluated_before(self) -> bool:
        """Whether the directory holds results of evaluations (a history or policies)."""
        return self.layout.history.exists() or self.layout.policy_count() > 0

    def leftovers(self) -> list[str]:
        """What the directory holds of an earlier run, in words (empty: nothing)."""
        found = []
        if self.layout.history.is_file():
            rows = max(0, len(self.layout.history.read_text().splitlines()) - 1)
            found.append(f"{self.layout.history.name} with {rows} row(s)")
        policies = self.layout.policy_count()
        if policies:
            found.append(f"{self.layout.evals.name}/ with {policies} trained "
                         f"polic{'y' if policies == 1 else 'ies'}")
        if self.layout.robots.is_dir():
            found.append(f"{self.layout.robots.name}/ with "
                         f"{len(self.layout.robot_names())} robot(s)")
        return found
