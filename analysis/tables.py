"""The tidy tables every analysis function works on, and a check that a table fits.

The run loader fills these from run directories; the statistics, early-slope and plot
functions take them as plain :class:`pandas.DataFrame` objects and never read files.

**Robots table**: one row per evaluated robot.

============  =======  ==============================================================
column        dtype    meaning
============  =======  ==============================================================
``run``       str      run directory id (one GA run of one method with one seed)
``method``    str      ``"R+R"``, ``"R+L"``, ``"E+R"`` or ``"E+L"``: structure strategy
                       (Random / Evolved) + behaviour strategy (Random / Learned);
                       ``+I`` after it when offspring inherit a parent's policy
                       (``"E+L+I"``, :data:`EXTRA_METHODS`)
``seed``      int      GA seed; the unit of replication for the ``E`` methods
``birth``     int      0-based birth order within the run
``name``      str      ``robot-xxxxxxxx``
``budget``    int      env steps the robot's behaviour was trained (or run) for
``fitness``   float    mean return of every episode completed in that training
                       (paper Eq. 8)
``accepted``  bool     whether the robot entered the population
``parents``   str      parent names joined by ``;`` as in history.csv; empty for
                       random structures
============  =======  ==============================================================

**Curves table**: one row per collector batch of one robot's training.

======================  =====  ====================================================
column                  dtype  meaning
======================  =====  ====================================================
``run``                 str    run directory id
``name``                str    robot name, as in the robots table
``env_steps``           int    env steps so far in this robot's training (cumulative)
``train/mean_return``   float  mean return of the episodes completed in the batch;
                               NaN if none completed
``train/episodes``      int    number of episodes completed in the batch
``train/success_rate``  float  share of those episodes that reached the target
======================  =====  ====================================================

Curves recorded before metric keys were namespaced (``mean_return``, ...) load under
these names (:func:`evo.record.read_curve`).

``(run, name)`` identifies a robot in both tables.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np
import pandas as pd

METHODS: tuple[str, ...] = ("R+R", "R+L", "E+R", "E+L")
"""The four ablation methods (paper §8), in the order tables and plots list them."""
EXTRA_METHODS: tuple[str, ...] = ("E+L+I",)
"""Arms beyond the paper's four, listed after them: ``E+L+I`` is E+L whose offspring
start from a parent's trained policy (``ga.inheritance``). The paper's tests leave them
out; each answers a question of its own (:data:`analysis.ablation.nested.EXTRA_PAIRS`)."""

ROBOT_COLUMNS: tuple[str, ...] = (
    "run", "method", "seed", "birth", "name", "budget", "fitness", "accepted", "parents",
)
CURVE_COLUMNS: tuple[str, ...] = (
    "run", "name", "env_steps", "train/mean_return", "train/episodes", "train/success_rate",
)


def require_columns(table: pd.DataFrame, columns: Iterable[str], what: str) -> None:
    """Raise a readable error when ``table`` lacks any of ``columns``.

    Args:
        table: The table handed to an analysis function.
        columns: The columns that function needs.
        what: The table's role in words (``"robots table"``), used in the message.

    Raises:
        ValueError: Naming the missing columns and the ones the table has.
    """
    missing = [c for c in columns if c not in table.columns]
    if missing:
        raise ValueError(
            f"{what} lacks column(s) {missing}; it has {list(table.columns)} "
            "(schemas: analysis.tables)"
        )


def is_evolved(method: str) -> bool:
    """Whether a method evolves structures (``E+R``, ``E+L``) rather than sampling them."""
    return method.startswith("E")


def method_order(methods: Iterable[str]) -> list[str]:
    """The distinct ``methods`` in :data:`METHODS` then :data:`EXTRA_METHODS` order,
    unknown ones after, sorted."""
    present = set(methods)
    known = METHODS + EXTRA_METHODS
    return [m for m in known if m in present] + sorted(present - set(known))


def paper_rows(table: pd.DataFrame) -> pd.DataFrame:
    """The rows of ``table`` (with a ``method`` column) the paper's tests compare: all but
    those of :data:`EXTRA_METHODS`."""
    return table[~table["method"].isin(EXTRA_METHODS)]


def fully_trained(robots: pd.DataFrame) -> pd.DataFrame:
    """The robots with a fitness from their whole budget: neither failed nor stopped
    early by early rejection (whose fitness covers only part of a budget, and which the
    fitness statistics leave out and say so)."""
    finite = np.isfinite(robots["fitness"].to_numpy(dtype=float))
    stopped = (robots["status"] == "stopped-early") if "status" in robots else False
    return robots[finite & ~np.asarray(stopped, dtype=bool)]
