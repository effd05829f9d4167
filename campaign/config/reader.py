"""Reading YAML sections with one-line errors that name the file and the dotted key path."""

from __future__ import annotations

import dataclasses
import hashlib
import math
import re
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from campaign.errors import ConfigError
from drivers.redaction import has_userinfo, redact_url, register_userinfo
from campaign.config.bounded_yaml import load_limited, read_limited

from campaign.config.values import FrozenMap

_REQUIRED: Any = object()


def field_keys(cls: type, *exclude: str) -> tuple[str, ...]:
    """YAML keys of a section: the dataclass field names."""
    return tuple(f.name for f in dataclasses.fields(cls) if f.name not in exclude)


def describe(value: Any) -> str:
    """Short YAML-flavoured rendering of a found value for error messages."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        text = repr(value)
        return text if len(text) <= 40 else text[:37] + "...'"
    if isinstance(value, (int, float)):
        return repr(value)
    if isinstance(value, list):
        return f"a list of {len(value)} item{'s' if len(value) != 1 else ''}"
    if isinstance(value, dict):
        return "a mapping"
    return f"a {type(value).__name__}"


def fmt(x: float) -> str:
    """Compact number for messages (``1450`` rather than ``1450.0``)."""
    return f"{x:.6g}"


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _bound_text(noun: str, positive: bool, lo: float | None, hi: float | None) -> str:
    """E.g. ``a positive number``, ``an integer >= 1``, ``a number in [0, 1]``."""
    if positive:
        return f"a positive {noun}"
    article = "an" if noun[0] in "aeiou" else "a"
    if lo is not None and hi is not None:
        return f"{article} {noun} in [{fmt(lo)}, {fmt(hi)}]"
    if lo is not None:
        return f"{article} {noun} >= {fmt(lo)}"
    if hi is not None:
        return f"{article} {noun} <= {fmt(hi)}"
    return f"{article} {noun}"


def _number_hint(value: Any) -> str:
    """Explain PyYAML's YAML 1.1 habit of reading ``1e-6`` as a string."""
    if isinstance(value, str):
        try:
            float(value)
        except ValueError:
            return ""
        return " (YAML reads exponents without a dot as text: write e.g. 1.0e-6)"
    return ""


class Reader:
    """Typed, validated access to one YAML mapping.

    Knows its file and key path; rejects keys outside ``allowed`` on creation.
    Getters take ``default``: omitted = the key is required.
    """

    def __init__(self, data: Any, file: str, path: str, allowed: Sequence[str]) -> None:
        self.file = file
        self.path = path
        if not isinstance(data, dict):
            raise ConfigError(file, path, f"expected a mapping, got {describe(data)}")
        self.data = data
        for key in data:
            if key not in allowed:
                raise self.error(str(key), f"unknown key (expected one of: {', '.join(sorted(allowed))})")

    # -- plumbing
    def key_path(self, key: str | int) -> str:
        """Dotted path of a child key (or ``[i]`` for an int index)."""
        if isinstance(key, int):
            return f"{self.path}[{key}]"
        return f"{self.path}.{key}" if self.path else key

    def error(self, key: str | int | None, message: str) -> ConfigError:
        """A ``ConfigError`` at ``key`` (``None`` = this section itself)."""
        return ConfigError(self.file, self.path if key is None else self.key_path(key), message)

    def _get(self, key: str, default: Any) -> tuple[Any, bool]:
        """(value, given); raises if a required key is absent."""
        value = self.data.get(key)
        if key in self.data and (value is not None or default is _REQUIRED):
            return value, True
        if default is _REQUIRED:
            raise self.error(None, f"missing required key '{key}'")
        return default, False

    # -- scalars
    def number(self, key: str, default: Any = _REQUIRED, *, positive: bool = False,
               lo: float | None = None, hi: float | None = None) -> float:
        """A finite float (int accepted, bool not) within the given bounds."""
        value, _ = self._get(key, default)
        return _check_number(value, self.error_at(key), positive=positive, lo=lo, hi=hi)

    def integer(self, key: str, default: Any = _REQUIRED, *,
                lo: int | None = None, hi: int | None = None) -> int:
        """An int (not bool, not float) within ``[lo, hi]``."""
        value, _ = self._get(key, default)
        return _check_integer(value, self.error_at(key), lo=lo, hi=hi)

    def string(self, key: str, default: Any = _REQUIRED, *, allow_empty: bool = False) -> str:
        """A string, non-blank unless ``allow_empty``."""
        value, _ = self._get(key, default)
        if not isinstance(value, str) or (not value.strip() and not allow_empty):
            raise self.error(key, f"expected a non-empty string, got {describe(value)}")
        return value

    def choice(self, key: str, options: Iterable[str], default: Any = _REQUIRED) -> str:
        """One of ``options``."""
        value, _ = self._get(key, default)
        options = tuple(options)
        if not isinstance(value, str) or value not in options:
            raise self.error(key, f"expected one of: {', '.join(options)}, got {describe(value)}")
        return value

    def url(self, key: str, schemes: Iterable[str]) -> str:
        """A driver URL ``scheme://...`` whose scheme is one of ``schemes``."""
        value = self.string(key)
        if has_userinfo(value):                 # first: no later message may show the URL
            register_userinfo(value)
            raise self.error(key, "credentials in the URL are refused (the URL is written to logs and reports): "
                                  "remove 'user:password@'; credentials go in the environment (RWS_USER, RWS_PASSWORD) "
                                  "or a file named by options.credentials.file (docs/drivers_abb.md)")
        known = ", ".join(sorted(schemes))
        scheme, sep, _ = value.partition("://")
        if not sep:
            raise self.error(key, f"expected a driver URL like 'mock://...' (drivers: {known}), got "
                                  f"{describe(redact_url(value))}")
        if scheme not in schemes:
            raise self.error(key, f"unknown driver {describe(scheme[:40])} (expected one of: {known})")
        return value

    # -- containers
    def vector(self, key: str, n: int, default: Any = _REQUIRED, *,
               positive: bool = False) -> tuple[float, ...] | None:
        """A list of exactly ``n`` finite numbers (``None`` only if that is the default)."""
        value, given = self._get(key, default)
        if value is None and not given:
            return None
        return _check_vector(value, n, self.key_path(key), self.file, positive=positive)

    def integers(self, key: str, default: Any = _REQUIRED, *,
                 lo: int | None = None, hi: int | None = None) -> tuple[int, ...]:
        """A list of distinct ints within ``[lo, hi]``."""
        value, _ = self._get(key, default)
        if not isinstance(value, (list, tuple)):
            raise self.error(key, f"expected a list of integers, got {describe(value)}")
        sub = self.child_list(key)
        out = tuple(_check_integer(v, sub.error_at(i), lo=lo, hi=hi) for i, v in enumerate(value))
        for i, v in enumerate(out):
            if v in out[:i]:
                raise sub.error(i, f"duplicate value {v}")
        return out

    def matrix(self, key: str, rows: int, cols: int, default: Any = _REQUIRED) -> tuple[tuple[float, ...], ...]:
        """A ``rows`` x ``cols`` list of lists of finite numbers."""
        value, _ = self._get(key, default)
        shape = f"expected a {rows}x{cols} matrix (a list of {rows} lists of {cols} numbers)"
        if not isinstance(value, (list, tuple)):
            raise self.error(key, f"{shape}, got {describe(value)}")
        if len(value) != rows:
            raise self.error(key, f"{shape}, got {len(value)} rows")
        path = self.key_path(key)
        return tuple(_check_vector(row, cols, f"{path}[{i}]", self.file) for i, row in enumerate(value))

    def mapping(self, key: str, default: Any = _REQUIRED) -> FrozenMap:
        """A free-form mapping of JSON-like values (string keys), frozen."""
        value, _ = self._get(key, default)
        if not isinstance(value, dict):
            raise self.error(key, f"expected a mapping, got {describe(value)}")
        return _freeze(value, self.key_path(key), self.file)

    def section(self, key: str, cls: type, *, required: bool = True) -> Reader:
        """Reader for a nested mapping whose allowed keys are ``cls``'s fields."""
        value, _ = self._get(key, _REQUIRED if required else {})
        return Reader(value, self.file, self.key_path(key), field_keys(cls))

    def items(self, key: str, default: Any = _REQUIRED, *,
              min_len: int = 0, max_len: int | None = None, what: str = "items") -> list[Any]:
        """A list (raw elements) with a length check; see ``child_list`` for element paths."""
        value, _ = self._get(key, default)
        if not isinstance(value, (list, tuple)):
            raise self.error(key, f"expected a list of {what}, got {describe(value)}")
        if len(value) < min_len or (max_len is not None and len(value) > max_len):
            span = f"{min_len} to {max_len}" if max_len is not None else f"at least {min_len}"
            raise self.error(key, f"expected a list of {span} {what}, got {len(value)}")
        return list(value)

    def child_list(self, key: str) -> ListPath:
        """Error helper for elements of the list at ``key``."""
        return ListPath(self.file, self.key_path(key))

    def error_at(self, key: str | int) -> Callable[[str], ConfigError]:
        """Factory of errors at ``key`` (for the shared checkers)."""
        return lambda message: self.error(key, message)


@dataclass(frozen=True, slots=True)
class ListPath:
    """Key-path helper for the elements of a list."""

    file: str
    path: str

    def key_path(self, index: int) -> str:
        return f"{self.path}[{index}]"

    def error(self, index: int, message: str) -> ConfigError:
        return ConfigError(self.file, self.key_path(index), message)

    def error_at(self, index: int) -> Callable[[str], ConfigError]:
        return lambda message: self.error(index, message)

    def reader(self, index: int, value: Any, cls: type) -> Reader:
        return Reader(value, self.file, self.key_path(index), field_keys(cls))


def _check_number(value: Any, error: Callable[[str], ConfigError], *, positive: bool = False,
                  lo: float | None = None, hi: float | None = None) -> float:
    """Validate one number; ``error(message)`` builds the exception."""
    expected = _bound_text("number", positive, lo, hi)
    if not _is_number(value):
        raise error(f"expected {expected}, got {describe(value)}{_number_hint(value)}")
    x = float(value)
    if not math.isfinite(x):
        raise error(f"expected a finite number, got {describe(value)}")
    if (positive and x <= 0) or (lo is not None and x < lo) or (hi is not None and x > hi):
        raise error(f"expected {expected}, got {describe(value)}")
    return x


def _check_integer(value: Any, error: Callable[[str], ConfigError], *,
                   lo: int | None = None, hi: int | None = None) -> int:
    """Validate one integer (bools and floats rejected)."""
    expected = _bound_text("integer", False, lo, hi)
    if not isinstance(value, int) or isinstance(value, bool):
        raise error(f"expected {expected}, got {describe(value)}")
    if (lo is not None and value < lo) or (hi is not None and value > hi):
        raise error(f"expected {expected}, got {value}")
    return value


def _check_vector(value: Any, n: int, path: str, file: str, *, positive: bool = False) -> tuple[float, ...]:
    """Validate a list of exactly ``n`` finite numbers at ``path``."""
    noun = "positive numbers" if positive else "numbers"
    if not isinstance(value, (list, tuple)):
        raise ConfigError(file, path, f"expected a list of {n} {noun}, got {describe(value)}")
    if len(value) != n:
        raise ConfigError(file, path, f"expected a list of {n} {noun}, got {len(value)}")
    where = ListPath(file, path)
    return tuple(_check_number(v, where.error_at(i), positive=positive) for i, v in enumerate(value))


def _freeze(value: Any, path: str, file: str) -> Any:
    """Deep-freeze JSON-like YAML data (dict -> FrozenMap, list -> tuple)."""
    if isinstance(value, dict):
        for key in value:
            if not isinstance(key, str):
                raise ConfigError(file, path, f"expected string keys, got key {describe(key)}")
        return FrozenMap((k, _freeze(v, f"{path}.{k}", file)) for k, v in value.items())
    if isinstance(value, (list, tuple)):
        return tuple(_freeze(v, f"{path}[{i}]", file) for i, v in enumerate(value))
    if value is None or isinstance(value, (str, bool, int)):
        return value
    if isinstance(value, float) and math.isfinite(value):
        return value
    raise ConfigError(file, path, f"expected JSON-like data (text, numbers, lists, mappings), got {describe(value)}")


