"""JSON for learning-curve rows and metadata, exact both ways.

Rows are written as JSON objects that Foxglove can plot and read back to the very same
values and key order:

* ``NaN`` is written as ``null`` (JSON has no NaN) and ``+-inf`` as the strings
  ``"Infinity"`` / ``"-Infinity"``; floats use Python's shortest round-trip repr.
* Keys with slashes are nested (``train/kl`` -> ``{"train": {"kl": ...}}``) so
  Foxglove's message paths reach them (``/train/curve.train.loss.objective``). When
  nesting would change the key order or collide (``loss`` and ``loss/x`` both present)
  the row is written flat instead; flattening joins nested keys with ``/`` either way.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from pathlib import PurePath
from typing import Any, cast

import numpy as np

from evo.run.files import JSONObject, JSONValue

CURVE_AXES = ("env_steps", "wall_seconds")
"""Curve keys that are axes (what the metrics are plotted against): not namespaced."""
METRIC_NAMESPACES = ("train/", "eval/", "ga/")


def current_curve_key(key: str) -> str:
    """``key`` as curve rows name it now.

    Recordings made before metric keys were namespaced have ``mean_return``,
    ``loss/critic``, ...; each such key was a training metric and is now ``train/<key>``.
    """
    if key in CURVE_AXES or key.startswith(METRIC_NAMESPACES):
        return key
    return f"train/{key}"


_MISSING = object()
_INF = {"Infinity": math.inf, "-Infinity": -math.inf}


def json_number(key: str, value: Any) -> Any:
    """A curve value as JSON-safe data (bool, int, float, None for NaN, inf tag).

    Raises:
        TypeError: naming ``key`` when the value is not a number.
    """
    if isinstance(value, bool | np.bool_):
        return bool(value)
    if isinstance(value, int | np.integer):
        return int(value)
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise TypeError(f"curve value {key!r} must be a number, got {value!r}") from None
    if math.isnan(number):
        return None
    if math.isinf(number):
        return "Infinity" if number > 0 else "-Infinity"
    return number


def from_json_number(value: Any) -> Any:
    """Inverse of ``json_number``."""
    if value is None:
        return math.nan
    if isinstance(value, str):
        return _INF.get(value, value)
    return value


def _nest(row: Mapping[str, JSONValue]) -> JSONObject | None:
    """``row`` nested at ``/``, or None when that would reorder or collide."""
    out: JSONObject = {}
    last: str | None = None
    for key, value in row.items():
        head, sep, rest = key.partition("/")
        current = out.get(head, _MISSING)
        if not sep:
            if current is not _MISSING:
                return None
            out[key] = value
        elif current is _MISSING:
            out[head] = {rest: value}
        elif isinstance(current, dict) and last == head and rest not in current:
            current[rest] = value
        else:
            return None
        last = head
    for key, value in out.items():
        if isinstance(value, dict):
            inner = _nest(value)
            if inner is None:
                return None
            out[key] = inner
    return out


def flatten(obj: Mapping[str, JSONValue], prefix: str = "") -> JSONObject:
    """Nested objects back to ``a/b`` keys, in order."""
    out: JSONObject = {}
    for key, value in obj.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            out.update(flatten(value, f"{name}/"))
        else:
            out[name] = from_json_number(value)
    return out


def encode_row(row: Mapping[str, Any]) -> bytes:
    """One curve row as compact JSON (nested when that is exact)."""
    plain = {str(k): json_number(str(k), v) for k, v in row.items()}
    nested = _nest(plain)
    return json.dumps(
        plain if nested is None else nested, allow_nan=False, separators=(",", ":")
    ).encode()


def decode_row(data: bytes) -> dict[str, float]:
    """Inverse of ``encode_row``."""
    obj = json.loads(data)
    if not isinstance(obj, dict):
        raise ValueError(f"a curve row must be a JSON object, got {type(obj).__name__}")
    # encode_row wrote numbers only (bools and ints stay what they were)
    return cast(dict[str, float], flatten(obj))


def plain(value: Any) -> Any:
    """``value`` as JSON-ready data (numpy and paths converted, mappings as dicts)."""
    if isinstance(value, Mapping):
        return {str(k): plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [plain(v) for v in value]
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, PurePath):
        return str(value)
    return value


def object_schema(title: str, properties: Mapping[str, str | JSONObject], *,
                  description: str = "", additional: bool = False) -> JSONObject:
    """The JSON Schema of an MCAP JSON channel's messages: an object with ``properties``
    (a string is that JSON type), open to other keys when ``additional``."""
    schema: JSONObject = {"title": title}
    if description:
        schema["description"] = description
    schema["type"] = "object"
    schema["properties"] = {k: {"type": v} if isinstance(v, str) else v
                            for k, v in properties.items()}
    if additional:
        schema["additionalProperties"] = True
    return schema


_JSON_KEYS = "evo.json_keys"
"""Metadata key listing the keys whose values are JSON (the others are plain strings)."""


def encode_metadata(values: Mapping[str, Any]) -> dict[str, str]:
    """Metadata as MCAP's string map: strings as they are, anything else as JSON."""
    out: dict[str, str] = {}
    encoded: list[str] = []
    for key, value in values.items():
        if key == _JSON_KEYS:
            raise ValueError(f"metadata key {_JSON_KEYS!r} is reserved")
        if isinstance(value, str):
            out[key] = value
        else:
            try:
                out[key] = json.dumps(plain(value))
            except TypeError as err:
                raise TypeError(f"metadata {key!r} cannot be written as JSON: {err}") from None
            encoded.append(key)
    out[_JSON_KEYS] = json.dumps(encoded)
    return out


def decode_metadata(record: Mapping[str, str]) -> JSONObject:
    """Inverse of ``encode_metadata``."""
    encoded = set(json.loads(record.get(_JSON_KEYS, "[]")))
    return {k: json.loads(v) if k in encoded else v for k, v in record.items() if k != _JSON_KEYS}
