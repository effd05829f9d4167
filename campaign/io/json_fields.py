"""Typed field checks of the JSON records (log records, reports): each names the field it checks and raises
``RecordError``."""
from __future__ import annotations

from collections.abc import Mapping
import math
from typing import Any, Iterator

from campaign.errors import DataError


class RecordError(DataError):
    """A record's field is missing or of the wrong type; ``field`` names it."""

    def __init__(self, field_name: str, message: str, file: str = "<record>") -> None:
        self.field = field_name
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
# reports


class ReportMapping(Mapping):
    """Read-only mapping view of a report's ``to_dict()`` (``report["stages"]``, ``report.get(...)``)."""

    def to_dict(self) -> dict:  # pragma: no cover - overridden
        raise NotImplementedError

    def __getitem__(self, key: str) -> Any:
        return self.to_dict()[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self.to_dict())

    def __len__(self) -> int:
        return len(self.to_dict())
