"""Typed field checks of the JSON records (log records, reports): each names the field it checks and raises
``RecordError``."""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import fields
import math
from typing import Any

from campaign.errors import DataError


class RecordError(DataError):
    """A record's field is missing or of the wrong type; ``field`` names it."""

    def __init__(self, field_name: str, message: str, file: str = "<record>") -> None:
        self.field = field_name
        self.detail = message
        super().__init__(file, f"field {field_name!r}: {message}")


# --------------------------------------------------------------------------
# field checks (each names the field it checks)


def get_field(data: Mapping, name: str, optional: bool = False) -> Any:
    """``data[name]``; a missing required field raises RecordError."""
    if name not in data or (data[name] is None and not optional):
        if optional:
            return None
        raise RecordError(name, "missing")
    return data[name]


def check_field(data: Mapping, name: str, optional: bool, ok, expected: str, convert=lambda v: v) -> Any:
    """``convert(data[name])`` when ``ok(value)``; None for an absent optional field; RecordError otherwise."""
    v = get_field(data, name, optional)
    if v is None:
        return None
    if not ok(v):
        raise RecordError(name, f"expected {expected}, got {repr(v)[:80]}")
    return convert(v)


def is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def number_field(data: Mapping, name: str, optional: bool = False) -> float | None:
    """A finite number (bool refused)."""
    return check_field(data, name, optional, is_number, "a finite number", float)


def count_field(data: Mapping, name: str, optional: bool = False) -> int | None:
    """A non-negative integer."""
    return check_field(data, name, optional, lambda v: type(v) is int and v >= 0, "a non-negative integer")


def text_field(data: Mapping, name: str, optional: bool = False) -> str | None:
    """A string."""
    return check_field(data, name, optional, lambda v: isinstance(v, str), "a string")


def object_field(data: Mapping, name: str, optional: bool = False) -> dict | None:
    """A JSON object (kept as a dict)."""
    return check_field(data, name, optional, lambda v: isinstance(v, Mapping), "an object", dict)


def vector_field(data: Mapping, name: str, n: int | None = None, optional: bool = False) -> tuple[float, ...] | None:
    """A list of finite numbers (of length ``n`` when given)."""
    size = f"{n} " if n is not None else ""
    return check_field(data, name, optional, lambda v: isinstance(v, (list, tuple)) and (n is None or len(v) == n)
                  and all(is_number(x) for x in v), f"a list of {size}finite numbers", lambda v: tuple(map(float, v)))


def mat3_field(data: Mapping, name: str, optional: bool = False) -> tuple[tuple[float, ...], ...] | None:
    """A 3 x 3 nested list of finite numbers."""
    ok = lambda v: isinstance(v, (list, tuple)) and len(v) == 3 and all(  # noqa: E731
        isinstance(r, (list, tuple)) and len(r) == 3 and all(is_number(x) for x in r) for r in v)
    return check_field(data, name, optional, ok, "a 3 x 3 list of finite numbers",
                  lambda v: tuple(tuple(float(x) for x in r) for r in v))


def float_list(values) -> list[float]:
    return [float(v) for v in values]


def float_rows(matrix) -> list[list[float]]:
    return [[float(v) for v in row] for row in matrix]


# --------------------------------------------------------------------------
# report records: nested sections, JSON out


def figure_field(data: Mapping, name: str) -> float | None:
    """A report figure: a number (NaN and infinity kept, bool refused), or None (null or absent)."""
    return check_field(data, name, True, lambda v: isinstance(v, (int, float)) and not isinstance(v, bool),
                       "a number or null")


def list_field(data: Mapping, name: str, optional: bool = False) -> list | None:
    """A JSON array (kept as it is)."""
    return check_field(data, name, optional, lambda v: isinstance(v, list), "a list")


def _object(path: str, v: Any) -> Mapping:
    if not isinstance(v, Mapping):
        raise RecordError(path, f"expected an object, got {repr(v)[:80]}")
    return v


def _nested(name: str, parse, value):
    """``parse(value)``; a RecordError inside names its path below ``name`` (``stages.kinematic.test.rms_mm``)."""
    try:
        return parse(value)
    except RecordError as exc:
        raise RecordError(f"{name}.{exc.field}", exc.detail) from None


def record_field(data: Mapping, name: str, parse, optional: bool = False):
    """The nested record ``parse(data[name])`` of a JSON object (None for an absent optional one)."""
    v = object_field(data, name, optional)
    return None if v is None else _nested(name, parse, v)


def records_field(data: Mapping, name: str, parse, optional: bool = False) -> tuple | None:
    """A JSON array of objects, each ``parse``d (a tuple)."""
    items = list_field(data, name, optional)
    if items is None:
        return None
    return tuple(_nested(f"{name}.{i}", parse, _object(f"{name}.{i}", v)) for i, v in enumerate(items))


def record_map_field(data: Mapping, name: str, parse, optional: bool = False) -> dict | None:
    """A JSON object whose values are objects, each ``parse``d (a dict, key order kept)."""
    v = object_field(data, name, optional)
    if v is None:
        return None
    return {k: _nested(f"{name}.{k}", parse, _object(f"{name}.{k}", x)) for k, x in v.items()}


def json_value(value: Any) -> Any:
    """A record field as JSON: records by their ``to_dict()``, tuples as lists, dicts key by key; anything else
    (numbers, text, JSON lists and objects kept as read) as it is."""
    if hasattr(value, "to_dict"):
        return value.to_dict()
    if isinstance(value, tuple):
        return [json_value(v) for v in value]
    if isinstance(value, dict):
        return {k: json_value(v) for k, v in value.items()}
    return value


def record_dict(record, omit_none: tuple[str, ...] = ()) -> dict:
    """A frozen dataclass record as its JSON object: every field in declaration order (:func:`json_value`), the
    fields named in ``omit_none`` left out when None (keys that only some reports carry)."""
    return {f.name: json_value(v) for f in fields(record)
            if not ((v := getattr(record, f.name)) is None and f.name in omit_none)}
