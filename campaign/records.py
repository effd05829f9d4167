"""Typed frozen records of a campaign: what the runner logs per point and what the reports hold.

* :class:`PointRecord` -- one robot measurement (a ``point`` record of ``log.jsonl``, kind plan/check/test/verify);
* :class:`NestRecord` -- one reference-nest reading (a ``point`` record with ``set`` and ``kind`` "nest");
* :class:`CalibrationReport` -- ``report.json`` of ``campaign run``/``reprocess``;
* :class:`VerifyReport` -- ``verify.json`` of ``campaign verify``.

Each has ``to_dict()`` giving exactly the JSON written today (same keys, same order, optional keys left out when
they are absent) and ``from_dict()`` that checks the types and raises :class:`RecordError` naming the field.
Units are in the field names (``_mm``, ``_mm2``, ``_deg``, ``_s``, ``_kg``, ``_c``); frames as in the log
(``p_tracker_mm`` tracker frame, ``p_target_base_mm`` robot base frame). The reports are read-only mappings too
(``report["stages"]``), so code and tests that read them by key keep working.
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, fields, replace
from typing import Any, Iterator

from .errors import DataError

__all__ = ["RecordError", "SmrReading", "PointRecord", "NestRecord", "CalibrationReport", "VerifyReport",
           "point_from_dict"]


class RecordError(DataError):
    """A record's field is missing or of the wrong type; ``field`` names it."""

    def __init__(self, field_name: str, message: str, file: str = "<record>") -> None:
        self.field = field_name
        super().__init__(file, f"field {field_name!r}: {message}")


# --------------------------------------------------------------------------
# field checks (each names the field it checks)


def _get(data: Mapping, name: str, optional: bool = False) -> Any:
    """``data[name]``; a missing required field raises RecordError."""
    if name not in data or (data[name] is None and not optional):
        if optional:
            return None
        raise RecordError(name, "missing")
    return data[name]


def _check(data: Mapping, name: str, optional: bool, ok, expected: str, convert=lambda v: v) -> Any:
    """``convert(data[name])`` when ``ok(value)``; None for an absent optional field; RecordError otherwise."""
    v = _get(data, name, optional)
    if v is None:
        return None
    if not ok(v):
        raise RecordError(name, f"expected {expected}, got {repr(v)[:80]}")
    return convert(v)


def _is_num(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def _num(data: Mapping, name: str, optional: bool = False) -> float | None:
    """A finite number (bool refused)."""
    return _check(data, name, optional, _is_num, "a finite number", float)


def _int(data: Mapping, name: str, optional: bool = False) -> int | None:
    """A non-negative integer."""
    return _check(data, name, optional, lambda v: type(v) is int and v >= 0, "a non-negative integer")


def _str(data: Mapping, name: str, optional: bool = False) -> str | None:
    """A string."""
    return _check(data, name, optional, lambda v: isinstance(v, str), "a string")


def _obj(data: Mapping, name: str, optional: bool = False) -> dict | None:
    """A JSON object (kept as a dict)."""
    return _check(data, name, optional, lambda v: isinstance(v, Mapping), "an object", dict)


def _vec(data: Mapping, name: str, n: int | None = None, optional: bool = False) -> tuple[float, ...] | None:
    """A list of finite numbers (of length ``n`` when given)."""
    size = f"{n} " if n is not None else ""
    return _check(data, name, optional, lambda v: isinstance(v, (list, tuple)) and (n is None or len(v) == n)
                  and all(_is_num(x) for x in v), f"a list of {size}finite numbers", lambda v: tuple(map(float, v)))


def _mat3(data: Mapping, name: str, optional: bool = False) -> tuple[tuple[float, ...], ...] | None:
    """A 3 x 3 nested list of finite numbers."""
    ok = lambda v: isinstance(v, (list, tuple)) and len(v) == 3 and all(  # noqa: E731
        isinstance(r, (list, tuple)) and len(r) == 3 and all(_is_num(x) for x in r) for r in v)
    return _check(data, name, optional, ok, "a 3 x 3 list of finite numbers",
                  lambda v: tuple(tuple(float(x) for x in r) for r in v))


def _floats(values) -> list[float]:
    return [float(v) for v in values]


def _rows(matrix) -> list[list[float]]:
    return [[float(v) for v in row] for row in matrix]


# --------------------------------------------------------------------------
# log records


@dataclass(frozen=True)
class SmrReading:
    """A further SMR (k = 2, 3) of a multi-SMR tool at the same stop: mean (3,) mm tracker frame, cov (3, 3) mm^2,
    spread (mm, max sample distance from the mean), failed readings."""

    k: int
    p_tracker_mm: tuple[float, float, float]
    cov_mm2: tuple[tuple[float, ...], ...]
    spread_mm: float
    retries: int

    def to_dict(self) -> dict:
        """The ``p{k}_tracker_mm``, ``cov{k}_mm2``, ``spread{k}_mm``, ``retries{k}`` fields."""
        k = self.k
        return {f"p{k}_tracker_mm": _floats(self.p_tracker_mm), f"cov{k}_mm2": _rows(self.cov_mm2),
                f"spread{k}_mm": float(self.spread_mm), f"retries{k}": int(self.retries)}

    @classmethod
    def from_dict(cls, data: Mapping, k: int) -> "SmrReading | None":
        """SMR ``k``'s fields of a point record, or None when the record has none."""
        if f"p{k}_tracker_mm" not in data:
            return None
        return cls(k, _vec(data, f"p{k}_tracker_mm", 3), _mat3(data, f"cov{k}_mm2"), _num(data, f"spread{k}_mm"),
                   _int(data, f"retries{k}"))


_LATER_FIELDS = ("cov_source", "t_measure_s")           # optional on reading: logs of earlier versions lack them


@dataclass(frozen=True)
class PointRecord:
    """One robot measurement as the runner logs it.

    ``q_cmd_deg``/``q_read_deg`` (n,) commanded / read-back joints, deg; ``p_tracker_mm`` (3,) mean of the samples,
    mm, tracker frame; ``cov_mm2`` (3, 3) its covariance, from the tracker (``cov_source`` "device") or the spec
    ("spec"); ``spread_mm`` max sample distance from the mean; ``t_start_s``/``t_measure_s``/``t_end_s`` the
    runner's clock at the move, the first reading and the end (s; ``cov_source`` and ``t_measure_s`` are None in
    logs of versions that did not write them); ``approach`` (n,) sign of each joint's last
    motion; ``retries`` failed readings; ``p_target_base_mm`` (3,) planned SMR position in the base frame.
    Optional: ``temperatures`` (tracker environment, ``temp_c``/``pressure_hpa``/``humidity_pct``...),
    ``joint_temp_c`` (n,), ``payload_cog_flange_mm`` (3,) (with a configured payload), ``device_std_mm`` (3,) and
    ``device_cov_mm2`` (3, 3) (the tracker's own per-reading uncertainty), ``smrs`` (SMRs 2 and 3).
    """

    point_id: str
    set: str
    q_cmd_deg: tuple[float, ...]
    q_read_deg: tuple[float, ...]
    p_tracker_mm: tuple[float, float, float]
    cov_mm2: tuple[tuple[float, ...], ...]
    cov_source: str | None
    spread_mm: float
    n_samples: int
    t_start_s: float
    t_measure_s: float | None
    t_end_s: float
    approach: tuple[float, ...]
    payload_kg: float
    retries: int
    p_target_base_mm: tuple[float, float, float]
    temperatures: dict | None = None
    joint_temp_c: tuple[float, ...] | None = None
    payload_cog_flange_mm: tuple[float, float, float] | None = None
    device_std_mm: tuple[float, float, float] | None = None
    device_cov_mm2: tuple[tuple[float, ...], ...] | None = None
    smrs: tuple[SmrReading, ...] = ()

    def to_dict(self) -> dict:
        """The log record's data (plain JSON types, the runner's key order)."""
        data = {"point_id": self.point_id, "set": self.set, "q_cmd_deg": _floats(self.q_cmd_deg),
                "q_read_deg": _floats(self.q_read_deg), "p_tracker_mm": _floats(self.p_tracker_mm),
                "cov_mm2": _rows(self.cov_mm2), "cov_source": self.cov_source, "spread_mm": float(self.spread_mm),
                "n_samples": int(self.n_samples), "t_start_s": float(self.t_start_s),
                "t_measure_s": self.t_measure_s, "t_end_s": float(self.t_end_s),
                "approach": _floats(self.approach), "payload_kg": float(self.payload_kg),
                "retries": int(self.retries), "p_target_base_mm": _floats(self.p_target_base_mm)}
        for name in _LATER_FIELDS:                        # absent in logs written before these fields existed
            if data[name] is None:
                del data[name]
            elif name == "t_measure_s":
                data[name] = float(data[name])
        if self.temperatures:
            data["temperatures"] = dict(self.temperatures)
        if self.joint_temp_c is not None:
            data["joint_temp_c"] = _floats(self.joint_temp_c)
        if self.payload_cog_flange_mm is not None:
            data["payload_cog_flange_mm"] = _floats(self.payload_cog_flange_mm)
        if self.device_std_mm is not None:
            data["device_std_mm"] = _floats(self.device_std_mm)
            data["device_cov_mm2"] = _rows(self.device_cov_mm2)
        for smr in self.smrs:
            data.update(smr.to_dict())
        return data

    @classmethod
    def from_dict(cls, data: Mapping, n_joints: int | None = None) -> "PointRecord":
        """Check and convert a point record's data; RecordError names the first bad field. The joint vectors
        have ``n_joints`` values (the robot's, when known), else as many as ``q_cmd_deg``."""
        n = len(_vec(data, "q_cmd_deg", n_joints))
        smrs = tuple(s for s in (SmrReading.from_dict(data, k) for k in (2, 3)) if s is not None)
        return cls(
            _str(data, "point_id"), _str(data, "set"), _vec(data, "q_cmd_deg"), _vec(data, "q_read_deg", n),
            _vec(data, "p_tracker_mm", 3), _mat3(data, "cov_mm2"), _str(data, "cov_source", True),
            _num(data, "spread_mm"), _int(data, "n_samples"), _num(data, "t_start_s"), _num(data, "t_measure_s", True),
            _num(data, "t_end_s"), _vec(data, "approach", n), _num(data, "payload_kg"), _int(data, "retries"),
            _vec(data, "p_target_base_mm", 3), _obj(data, "temperatures", True),
            _vec(data, "joint_temp_c", n, True), _vec(data, "payload_cog_flange_mm", 3, True),
            _vec(data, "device_std_mm", 3, True),
            _mat3(data, "device_cov_mm2", "device_std_mm" not in data), smrs)


@dataclass(frozen=True)
class NestRecord:
    """One reference-nest reading (stored as a ``point`` record with ``set`` and ``kind`` "nest").

    ``p_tracker_mm`` (3,) mean of the samples, mm, tracker frame; ``cov_mm2`` (3, 3); ``spread_mm`` max sample
    distance from the mean; ``t_start_s``/``t_end_s`` the runner's clock (s; ``t_s`` = ``t_end_s``);
    ``p_nest_base_mm`` the nest's approximate position in the robot base frame from the plan;
    ``temperatures`` the tracker's environment readings (or None).
    """

    point_id: str
    nest_id: str
    p_tracker_mm: tuple[float, float, float]
    cov_mm2: tuple[tuple[float, ...], ...]
    spread_mm: float
    n_samples: int
    t_start_s: float
    t_end_s: float
    retries: int
    p_nest_base_mm: tuple[float, float, float]
    temperatures: dict | None = None
    set = "nest"                                          # class constant: records are told apart by ``set``

    def to_dict(self) -> dict:
        """The log record's data (plain JSON types)."""
        data = {"point_id": self.point_id, "set": "nest", "kind": "nest", "nest_id": self.nest_id,
                "p_tracker_mm": [float(v) for v in self.p_tracker_mm],
                "cov_mm2": [[float(v) for v in row] for row in self.cov_mm2], "spread_mm": float(self.spread_mm),
                "n_samples": int(self.n_samples), "t_start_s": float(self.t_start_s), "t_end_s": float(self.t_end_s),
                "t_s": float(self.t_end_s), "retries": int(self.retries),
                "p_nest_base_mm": [float(v) for v in self.p_nest_base_mm]}
        if self.temperatures:
            data["temperatures"] = dict(self.temperatures)
        return data

    @classmethod
    def from_dict(cls, data: Mapping) -> "NestRecord":
        """Check and convert a nest record's data; RecordError names the first bad field."""
        if data.get("set") != "nest":
            raise RecordError("set", f"expected 'nest', got {data.get('set')!r}")
        return cls(_str(data, "point_id"), _str(data, "nest_id"), _vec(data, "p_tracker_mm", 3),
                   _mat3(data, "cov_mm2"), _num(data, "spread_mm"), _int(data, "n_samples"),
                   _num(data, "t_start_s"), _num(data, "t_end_s"), _int(data, "retries"),
                   _vec(data, "p_nest_base_mm", 3), _obj(data, "temperatures", True))


def point_from_dict(data: Mapping, n_joints: int | None = None) -> PointRecord | NestRecord:
    """A log ``point`` record's data as the typed record its ``set`` says (nest or robot point with ``n_joints``
    joint values, when known)."""
    if not isinstance(data, Mapping):
        raise RecordError("data", f"expected an object, got {repr(data)[:80]}")
    return NestRecord.from_dict(data) if data.get("set") == "nest" else PointRecord.from_dict(data, n_joints)


# --------------------------------------------------------------------------
# reports


class _ReportMapping(Mapping):
    """Read-only mapping view of a report's ``to_dict()`` (``report["stages"]``, ``report.get(...)``)."""

    def to_dict(self) -> dict:  # pragma: no cover - overridden
        raise NotImplementedError

    def __getitem__(self, key: str) -> Any:
        return self.to_dict()[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self.to_dict())

    def __len__(self) -> int:
        return len(self.to_dict())


_IDENTIFICATION = ("robot_identity", "tracker_identity", "driver_versions", "software_version", "identity_check")
_N_REPORT_KEYS = 26                                       # the always-present report.json keys, before multi_smr


@dataclass(frozen=True, eq=False)
class CalibrationReport(_ReportMapping):
    """``report.json``: the calibration's figures (see ``campaign.process.process``).

    ``n`` row counts (calib/test/check/rejected); ``stages`` per-stage error statistics on the test rows (mm);
    ``noise_floor_mm`` with its source ("repeats" or "specs") and both candidates; the identified ``parameters``
    and their diagnostics; ``T_tracker_base`` (4, 4) registration (mm); the method and effect choices; optional
    ``multi_smr``; ``stop`` (``plan.stop: auto`` runs: every refit's predicted held-out RMS curve and decision,
    with the held-out RMS measured at the end); ``cell`` summary and per-point ``points`` table (HTML figures); the
    hardware ``identification`` of the run log (robot/tracker identity, driver and software versions) when processed
    from a log.
    """

    format: str
    config: str
    source: str
    n: dict
    stages: dict
    noise_floor_mm: float
    noise_floor_source: str
    noise_floor_specs_mm: float
    noise_floor_repeats_mm: float | None
    parameters: list
    unidentifiable: list
    condition_number: float
    observability: Any
    sigma0: float
    iterations: int
    converged: bool
    rejected_points: list
    excluded_points: list
    structure_note: str | None
    T_tracker_base: list
    method: dict
    effects: dict
    residual_choice: dict | None
    plausibility: dict | None
    residual_cv: dict | None
    preparation: dict | None
    multi_smr: dict | None = None
    stop: dict | None = None
    cell: Any = None
    points: Any = None
    identification: tuple[tuple[str, Any], ...] = ()

    def to_dict(self) -> dict:
        """The report.json object (the key order written so far)."""
        out = {name: getattr(self, name) for name in _REPORT_KEYS}
        if self.multi_smr is not None:
            out["multi_smr"] = self.multi_smr
        if self.stop is not None:
            out["stop"] = self.stop
        out["cell"], out["points"] = self.cell, self.points
        out.update(self.identification)
        return out

    def with_identification(self, ident: Mapping) -> "CalibrationReport":
        """A copy carrying the run log's hardware identification (``robot_identity``... ``software_version``)."""
        return replace(self, identification=tuple((k, ident[k]) for k in _IDENTIFICATION if k in ident))

    @classmethod
    def from_dict(cls, data: Mapping) -> "CalibrationReport":
        """A report.json object; RecordError names a missing field or one of the wrong kind."""
        if not isinstance(data, Mapping):
            raise RecordError("report", f"expected an object, got {type(data).__name__}")
        for check, name in ((_str, "format"), (_str, "config"), (_str, "source"), (_obj, "n"), (_obj, "stages"),
                            (_num, "noise_floor_mm"), (_get, "T_tracker_base")):
            check(data, name)
        args = {name: _get(data, name, optional=True) for name in _REPORT_KEYS}
        return cls(**args, multi_smr=_obj(data, "multi_smr", True), stop=_obj(data, "stop", True),
                   cell=data.get("cell"), points=data.get("points"),
                   identification=tuple((k, data[k]) for k in _IDENTIFICATION if k in data))


@dataclass(frozen=True, eq=False)
class VerifyReport(_ReportMapping):
    """``verify.json``: closed-loop verification of a run's test points (``campaign.correction.verify_run``).

    ``n`` test points; ``noise_floor_mm`` (RMS of the measurement sigma at the targets); ``n_uncorrected`` points
    held at their planned joints in the last pass (None when nothing was measured corrected); ``stages`` error
    statistics per stage (mm); ``passes`` one summary per pass; ``exit_status``/``reason`` of the measuring run;
    ``definitions`` of the terms; ``created_utc`` ISO time.
    """

    format: str
    run: str
    n: int
    noise_floor_mm: float
    n_uncorrected: int | None
    stages: dict
    passes: list
    exit_status: str
    reason: str
    definitions: dict
    created_utc: str

    def to_dict(self) -> dict:
        """The verify.json object."""
        return {f.name: getattr(self, f.name) for f in fields(self)}

    @classmethod
    def from_dict(cls, data: Mapping) -> "VerifyReport":
        """A verify.json object; RecordError names a missing field or one of the wrong kind."""
        if not isinstance(data, Mapping):
            raise RecordError("verify", f"expected an object, got {type(data).__name__}")
        return cls(_str(data, "format"), _str(data, "run"), _int(data, "n"), _num(data, "noise_floor_mm"),
                   _int(data, "n_uncorrected", True), _obj(data, "stages"), _check(data, "passes", False, lambda v: isinstance(v, list), "a list"),
                   _str(data, "exit_status"), _str(data, "reason"), _obj(data, "definitions"),
                   _str(data, "created_utc"))


_REPORT_KEYS = tuple(f.name for f in fields(CalibrationReport))[:_N_REPORT_KEYS]
