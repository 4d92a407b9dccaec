"""Range checks of dataclass fields, for ``__post_init__``.

Each raises one ``ValueError`` that names the field, the bound and the value found
(``"epochs must be >= 1, got 0"``); :func:`evo.config.typed` prefixes it with the
config key, so a user sees ``learner: epochs must be >= 1, got 0``. A field holding a
tuple of numbers (``friction``, ``hidden``) is checked element by element.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping


def _values(value: object) -> Iterable[float]:
    if isinstance(value, tuple | list):
        return value
    return (value,)  # type: ignore[return-value]


def at_least(obj: object, minimum: float, *names: str, note: str = "") -> None:
    """Raise unless every field ``names`` of ``obj`` is ``>= minimum``.

    Args:
        obj: The object whose attributes are checked.
        minimum: The smallest allowed value.
        names: Attribute names, checked in order; the first one below names the error.
        note: Said after the bound (``" env step"``, ``" (0 = off)"``).
    """
    for name in names:
        value = getattr(obj, name)
        if any(v < minimum for v in _values(value)):
            raise ValueError(f"{name} must be >= {minimum:g}{note}, got {value}")


def positive(obj: object, *names: str) -> None:
    """Raise unless every field ``names`` of ``obj`` is ``> 0``."""
    for name in names:
        value = getattr(obj, name)
        if any(v <= 0 for v in _values(value)):
            raise ValueError(f"{name} must be positive, got {value}")


def within(obj: object, low: float, high: float, *names: str, note: str = "") -> None:
    """Raise unless every field ``names`` of ``obj`` lies in ``[low, high]``."""
    for name in names:
        value = getattr(obj, name)
        if any(not low <= v <= high for v in _values(value)):
            raise ValueError(f"{name} must be in [{low:g}, {high:g}]{note}, got {value}")


SWAPPABLE: Mapping[str, object] = {"swappable": True}
"""The ``metadata`` of a dataclass field that is a swappable part
(``field(default_factory=Roulette, metadata=SWAPPABLE)``): its config node names its
class with ``_target_`` (each item's, for a tuple), so a config may name a subclass. The
defaults :mod:`evo.schemas` registers carry that ``_target_``."""
