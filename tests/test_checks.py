"""The field range checks name the first field out of range, its bound and its value."""

from __future__ import annotations

from dataclasses import dataclass

import pytest

from evo.checks import at_least, positive, within


@dataclass
class Fields:
    a: float = 1.0
    b: float = 0.0
    c: float = -2.0


def test_at_least_names_the_first_field_below_the_bound() -> None:
    at_least(Fields(), -2, "a", "b", "c")  # every one in range: no error
    with pytest.raises(ValueError, match=r"^b must be >= 0.5 env step, got 0.0$"):
        at_least(Fields(), 0.5, "a", "b", "c", note=" env step")
    with pytest.raises(ValueError, match=r"^c must be >= 0 \(0 = off\), got -2.0$"):
        at_least(Fields(), 0, "a", "c", "b", note=" (0 = off)")


def test_positive_rejects_zero_and_below() -> None:
    positive(Fields(), "a")
    with pytest.raises(ValueError, match=r"^b must be positive, got 0.0$"):
        positive(Fields(), "a", "b")


def test_within_and_tuples_name_the_field_and_the_whole_value() -> None:
    within(Fields(), -2, 1, "a", "b", "c")
    with pytest.raises(ValueError, match=r"^a must be in \[-1, 0.5\] \(note\), got 1.0$"):
        within(Fields(), -1, 0.5, "b", "a", note=" (note)")
    with pytest.raises(ValueError, match=r"^t must be >= 0, got \(1.0, -0.5\)$"):
        at_least(Tuples(), 0, "t")
    with pytest.raises(ValueError, match=r"^t must be positive, got \(1.0, -0.5\)$"):
        positive(Tuples(), "t")


@dataclass
class Tuples:
    t: tuple[float, ...] = (1.0, -0.5)
