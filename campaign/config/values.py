"""The allowed values of config keys (choice tables, size limits) and the value types every section shares
(``Vec3``, ``Matrix4``, ``FrozenMap``). Imports nothing of the config room: the schema modules
(:mod:`campaign.config.schema`, :mod:`campaign.config.plan_schema`) and the section readers build on it."""
from __future__ import annotations

import re
from collections.abc import Iterable, Iterator, Mapping
from typing import Any

CONVENTIONS = ("dh", "mdh")
CALIBRATION_METHODS = ("robust_ridge", "lm")
WEIGHT_FUNCTIONS = ("igg3", "huber", "none")
RESIDUAL_MODELS = ("idw", "gpr", "joint_gp", "trend_gpr", "none", "auto")
OUTLIER_SCREENS = ("local", "none")
JOINT_SETS = ("auto", "commanded", "readback")
PLAN_ORDERS = ("serpentine", "random")
PLAN_KINDS = ("grid", "optimal", "adaptive", "iso9283")
STOP_RULES = ("off", "auto")
CORRECTION_GENERATORS = ("ensemble", "yin", "fixed", "add", "multiply", "euler_zyz", "euler_xyz", "quaternion")
ERROR_FUNCTIONS = ("position", "pose")
MAX_JOINTS = 12

ORTHONORMAL_TOL = 1e-3
NAME_RE = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]*\Z")
FILE_NAME_MAX = 255                                      # bytes in one path component (ext4, XFS, APFS, NTFS)
MAX_NAME_CHARS = FILE_NAME_MAX - len("-YYYYmmdd-HHMMSS-NNNN")   # the name + a run directory's timestamp fit

Vec3 = tuple[float, float, float]
Matrix4 = tuple[tuple[float, float, float, float], ...]


class FrozenMap(Mapping[str, Any]):
    """Immutable, hashable string-keyed mapping (driver options, effect params).

    Values are JSON-like scalars, tuples and nested ``FrozenMap``s.
    """

    __slots__ = ("_data",)

    def __init__(self, items: Mapping[str, Any] | Iterable[tuple[str, Any]] = ()) -> None:
        self._data = dict(items)

    def __getitem__(self, key: str) -> Any:
        return self._data[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self._data)

    def __len__(self) -> int:
        return len(self._data)

    def __hash__(self) -> int:
        return hash(frozenset(self._data.items()))

    def __repr__(self) -> str:
        return f"FrozenMap({self._data!r})"
