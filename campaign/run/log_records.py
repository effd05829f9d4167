"""Typed frozen records of what the runner logs per point.

* :class:`PointRecord` -- one robot measurement (a ``point`` record of ``log.jsonl``, kind plan/check/test/verify);
* :class:`NestRecord` -- one reference-nest reading (a ``point`` record with ``set`` and ``kind`` "nest").

The ``event`` records and the exit status are typed in :mod:`campaign.run.log_events`.

Each has ``to_dict()`` giving exactly the JSON written today (same keys, same order, optional keys left out when
they are absent) and ``from_dict()`` that checks the types and raises :class:`RecordError` naming the field.

This module is the one owner of the point-record shape. :func:`migrate` maps foreign shapes onto the current one
before a record is read. A record of this software's log is read as the runner writes it (every field it has
always written must be there). ``foreign=True`` reads a point of any log (a log of another tool or written by
hand, which ``campaign reprocess``/``diagnose`` turn into a dataset): only ``point_id``, ``set``, ``p_tracker_mm``
and the joints (``q_cmd_deg`` and/or ``q_read_deg``; a nest: ``nest_id``) are required, the fields the runner
always writes may be absent (None). :func:`check_records` holds the rules a log's point records obey together
(set names, one joint count, an optional field in all records or none), used by the resume checks and the dataset
conversion; its errors name the file and the record's line.
Units are in the field names (``_mm``, ``_mm2``, ``_deg``, ``_s``, ``_kg``, ``_c``); frames as in the log
(``p_tracker_mm`` tracker frame, ``p_target_base_mm`` robot base frame). The reports are records of their own
(``campaign.calibrate.calibration_report``, ``campaign.correct.verify_report``).
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
import math
from typing import Any, Callable, Sequence

from campaign.errors import DataError
from campaign.io.json_fields import (RecordError, count_field, float_list, float_rows, mat3_field, number_field,
                                     object_field, text_field, vector_field)

SETS = ("calib", "test", "check", "nest")       # the sets a point record (and a dataset row) belongs to

__all__ = ["SETS", "SmrReading", "PointRecord", "NestRecord", "point_from_dict", "migrate", "check_records",
           "temp_c_of", "sigma_of", "OptionalField", "OPTIONAL_FIELDS"]


# --------------------------------------------------------------------------
# log records


def _some(convert: Callable[[Any], Any], value: Any) -> Any:
    """``convert(value)``, None for None (a field a foreign log may lack)."""
    return None if value is None else convert(value)


@dataclass(frozen=True)
class SmrReading:
    """A further SMR (k = 2, 3) of a multi-SMR tool at the same stop: mean (3,) mm tracker frame, cov (3, 3) mm^2,
    spread (mm, max sample distance from the mean), failed readings (cov, spread and retries are None only in a
    foreign log, which may give the position alone)."""

    k: int
    p_tracker_mm: tuple[float, float, float]
    cov_mm2: tuple[tuple[float, ...], ...] | None
    spread_mm: float | None
    retries: int | None

    def to_dict(self) -> dict:
        """The ``p{k}_tracker_mm``, ``cov{k}_mm2``, ``spread{k}_mm``, ``retries{k}`` fields (those present)."""
        k = self.k
        data = {f"p{k}_tracker_mm": float_list(self.p_tracker_mm), f"cov{k}_mm2": _some(float_rows, self.cov_mm2),
                f"spread{k}_mm": _some(float, self.spread_mm), f"retries{k}": _some(int, self.retries)}
        return {key: v for key, v in data.items() if v is not None}

    @classmethod
    def from_dict(cls, data: Mapping, k: int, foreign: bool = False) -> "SmrReading | None":
        """SMR ``k``'s fields of a point record, or None when the record has none."""
        if f"p{k}_tracker_mm" not in data or (foreign and data[f"p{k}_tracker_mm"] is None):
            return None
        return cls(k, vector_field(data, f"p{k}_tracker_mm", 3), mat3_field(data, f"cov{k}_mm2", foreign),
                   number_field(data, f"spread{k}_mm", foreign), count_field(data, f"retries{k}", foreign))


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
    A record read with ``foreign=True`` may have None in every field the runner always writes except ``point_id``,
    ``set``, ``p_tracker_mm`` and one of the joint vectors. ``sigma_mm`` (1-sigma of the reading, mm) and
    ``temp_c`` (a top-level cell temperature, deg C) are foreign logs' fields (None in this software's logs).
    """

    point_id: str
    set: str
    q_cmd_deg: tuple[float, ...] | None
    q_read_deg: tuple[float, ...] | None
    p_tracker_mm: tuple[float, float, float]
    cov_mm2: tuple[tuple[float, ...], ...] | None
    cov_source: str | None
    spread_mm: float | None
    n_samples: int | None
    t_start_s: float | None
    t_measure_s: float | None
    t_end_s: float | None
    approach: tuple[float, ...] | None
    payload_kg: float | None
    retries: int | None
    p_target_base_mm: tuple[float, float, float] | None
    temperatures: dict | None = None
    joint_temp_c: tuple[float, ...] | None = None
    payload_cog_flange_mm: tuple[float, float, float] | None = None
    device_std_mm: tuple[float, float, float] | None = None
    device_cov_mm2: tuple[tuple[float, ...], ...] | None = None
    smrs: tuple[SmrReading, ...] = ()
    sigma_mm: float | None = None
    temp_c: float | None = None

    def to_dict(self) -> dict:
        """The log record's data (plain JSON types, the runner's key order; absent fields left out)."""
        data = {"point_id": self.point_id, "set": self.set, "q_cmd_deg": _some(float_list, self.q_cmd_deg),
                "q_read_deg": _some(float_list, self.q_read_deg), "p_tracker_mm": float_list(self.p_tracker_mm),
                "cov_mm2": _some(float_rows, self.cov_mm2), "cov_source": self.cov_source,
                "spread_mm": _some(float, self.spread_mm), "n_samples": _some(int, self.n_samples),
                "t_start_s": _some(float, self.t_start_s), "t_measure_s": _some(float, self.t_measure_s),
                "t_end_s": _some(float, self.t_end_s), "approach": _some(float_list, self.approach),
                "payload_kg": _some(float, self.payload_kg), "retries": _some(int, self.retries),
                "p_target_base_mm": _some(float_list, self.p_target_base_mm)}
        data = {k: v for k, v in data.items() if v is not None}   # _LATER_FIELDS in logs of earlier versions
        if self.temperatures:
            data["temperatures"] = dict(self.temperatures)
        if self.joint_temp_c is not None:
            data["joint_temp_c"] = float_list(self.joint_temp_c)
        if self.payload_cog_flange_mm is not None:
            data["payload_cog_flange_mm"] = float_list(self.payload_cog_flange_mm)
        if self.device_std_mm is not None:
            data["device_std_mm"] = float_list(self.device_std_mm)
            data["device_cov_mm2"] = float_rows(self.device_cov_mm2)
        for smr in self.smrs:
            data.update(smr.to_dict())
        data.update({k: float(v) for k, v in (("sigma_mm", self.sigma_mm), ("temp_c", self.temp_c)) if v is not None})
        return data

    @classmethod
    def from_dict(cls, data: Mapping, n_joints: int | None = None, foreign: bool = False) -> "PointRecord":
        """Check and convert a point record's data; RecordError names the first bad field. The joint vectors
        have ``n_joints`` values (the robot's, when known), else as many as ``q_cmd_deg`` (or ``q_read_deg``).
        ``foreign``: a point of any log, the runner's fields optional (see the module doc). The data is in the
        current shape (:func:`point_from_dict` runs :func:`migrate` first)."""
        opt = foreign                                       # the runner's fields may be absent in a foreign log
        q_cmd = vector_field(data, "q_cmd_deg", n_joints, opt)
        q_read = vector_field(data, "q_read_deg", n_joints, True) if q_cmd is None else None
        if q_cmd is None and q_read is None:
            raise RecordError("q_cmd_deg", "missing (and no 'q_read_deg')")
        n = len(q_cmd if q_cmd is not None else q_read)
        smrs = tuple(s for s in (SmrReading.from_dict(data, k, foreign) for k in (2, 3)) if s is not None)
        return cls(
            text_field(data, "point_id"), text_field(data, "set"), q_cmd, vector_field(data, "q_read_deg", n, opt),
            vector_field(data, "p_tracker_mm", 3), mat3_field(data, "cov_mm2", opt),
            text_field(data, "cov_source", True), number_field(data, "spread_mm", opt),
            count_field(data, "n_samples", opt), number_field(data, "t_start_s", opt),
            number_field(data, "t_measure_s", True), number_field(data, "t_end_s", opt),
            vector_field(data, "approach", n, opt),
            number_field(data, "payload_kg", opt), count_field(data, "retries", opt),
            vector_field(data, "p_target_base_mm", 3, opt), object_field(data, "temperatures", True),
            vector_field(data, "joint_temp_c", n, True), vector_field(data, "payload_cog_flange_mm", 3, True),
            vector_field(data, "device_std_mm", 3, True),
            mat3_field(data, "device_cov_mm2", "device_std_mm" not in data), smrs,
            number_field(data, "sigma_mm", True), number_field(data, "temp_c", True))

    @property
    def n_joints(self) -> int:
        """Number of joint values n."""
        return len(self.q_cmd_deg if self.q_cmd_deg is not None else self.q_read_deg)

    def smr(self, k: int) -> SmrReading | None:
        """SMR ``k``'s reading (k = 2, 3), or None."""
        return next((s for s in self.smrs if s.k == k), None)


@dataclass(frozen=True)
class NestRecord:
    """One reference-nest reading (stored as a ``point`` record with ``set`` and ``kind`` "nest").

    ``p_tracker_mm`` (3,) mean of the samples, mm, tracker frame; ``cov_mm2`` (3, 3); ``spread_mm`` max sample
    distance from the mean; ``t_start_s``/``t_end_s`` the runner's clock (s; ``t_s`` = ``t_end_s``);
    ``p_nest_base_mm`` the nest's approximate position in the robot base frame from the plan;
    ``temperatures`` the tracker's environment readings (or None). Read with ``foreign=True``, every field but
    ``point_id``, ``nest_id`` and ``p_tracker_mm`` may be None; ``sigma_mm`` as in :class:`PointRecord`.
    """

    point_id: str
    nest_id: str
    p_tracker_mm: tuple[float, float, float]
    cov_mm2: tuple[tuple[float, ...], ...] | None
    spread_mm: float | None
    n_samples: int | None
    t_start_s: float | None
    t_end_s: float | None
    retries: int | None
    p_nest_base_mm: tuple[float, float, float] | None
    temperatures: dict | None = None
    sigma_mm: float | None = None
    set = "nest"                                          # class constant: records are told apart by ``set``

    def to_dict(self) -> dict:
        """The log record's data (plain JSON types; absent fields left out)."""
        data = {"point_id": self.point_id, "set": "nest", "kind": "nest", "nest_id": self.nest_id,
                "p_tracker_mm": float_list(self.p_tracker_mm), "cov_mm2": _some(float_rows, self.cov_mm2),
                "spread_mm": _some(float, self.spread_mm), "n_samples": _some(int, self.n_samples),
                "t_start_s": _some(float, self.t_start_s), "t_end_s": _some(float, self.t_end_s),
                "t_s": _some(float, self.t_end_s), "retries": _some(int, self.retries),
                "p_nest_base_mm": _some(float_list, self.p_nest_base_mm)}
        data = {k: v for k, v in data.items() if v is not None}
        if self.temperatures:
            data["temperatures"] = dict(self.temperatures)
        if self.sigma_mm is not None:
            data["sigma_mm"] = float(self.sigma_mm)
        return data

    @classmethod
    def from_dict(cls, data: Mapping, foreign: bool = False) -> "NestRecord":
        """Check and convert a nest record's data; RecordError names the first bad field."""
        if data.get("set") != "nest":
            raise RecordError("set", f"expected 'nest', got {data.get('set')!r}")
        opt = foreign
        return cls(text_field(data, "point_id"), text_field(data, "nest_id"), vector_field(data, "p_tracker_mm", 3),
                   mat3_field(data, "cov_mm2", opt), number_field(data, "spread_mm", opt),
                   count_field(data, "n_samples", opt), number_field(data, "t_start_s", opt),
                   number_field(data, "t_end_s", opt), count_field(data, "retries", opt),
                   vector_field(data, "p_nest_base_mm", 3, opt), object_field(data, "temperatures", True),
                   number_field(data, "sigma_mm", True))


def migrate(data: Mapping) -> dict:
    """A point record of a foreign log in the current shape: a check-pose record marked ``kind: "check"`` gets
    ``set: "check"`` (whatever its ``set`` says). The foreign fields ``sigma_mm`` and a top-level ``temp_c`` are
    read as they are (:class:`PointRecord`); a record without ``q_read_deg`` or ``q_cmd_deg`` has None there."""
    out = dict(data)
    if out.get("kind") == "check":
        out["set"] = "check"
    return out


def point_from_dict(data: Mapping, n_joints: int | None = None,
                    foreign: bool = False) -> PointRecord | NestRecord:
    """A log ``point`` record's data, migrated, as the typed record its ``set`` says (nest or robot point with
    ``n_joints`` joint values, when known). ``foreign``: only the fields a dataset needs are required (see the
    module doc)."""
    if not isinstance(data, Mapping):
        raise RecordError("data", f"expected an object, got {repr(data)[:80]}")
    data = migrate(data)
    if data.get("set") == "nest":
        return NestRecord.from_dict(data, foreign)
    return PointRecord.from_dict(data, n_joints, foreign)


# --------------------------------------------------------------------------
# the rules a log's point records obey together


Record = PointRecord | NestRecord


def temp_c_of(rec: Record) -> Any:
    """The cell temperature of a reading: ``temperatures["temp_c"]``, else a foreign log's top-level ``temp_c``."""
    temps = rec.temperatures
    if temps and temps.get("temp_c") is not None:
        return temps["temp_c"]
    return rec.temp_c


def sigma_of(rec: Record) -> float | None:
    """1-sigma of a reading in mm: a foreign log's ``sigma_mm``, else sqrt(trace(cov_mm2) / 3) (RMS per axis)."""
    if rec.sigma_mm is not None:
        return rec.sigma_mm
    cov = rec.cov_mm2
    return None if cov is None else math.sqrt((cov[0][0] + cov[1][1] + cov[2][2]) / 3)


@dataclass(frozen=True)
class OptionalField:
    """A value a log's point records carry in all records or in none: ``name`` (as the dataset column is called),
    ``get`` (None = absent), ``nests`` (nest records count too), ``gaps_ok`` (the records where a gap is no error,
    the column is then left out)."""
    name: str
    get: Callable[[Record], Any]
    nests: bool = False
    gaps_ok: Callable[[Sequence[Record]], bool] = lambda recs: False


OPTIONAL_FIELDS = (
    OptionalField("t_s", lambda r: r.t_end_s, nests=True),
    # tracker weather readings with gaps (a failed read) are no error: kept as env_temp_c with NaN
    OptionalField("temp_c", temp_c_of, gaps_ok=lambda recs: all(r.temp_c is None for r in recs)),
    OptionalField("payload_kg", lambda r: r.payload_kg),
    OptionalField("p2_tracker_mm", lambda r: _some(lambda s: s.p_tracker_mm, r.smr(2))),
    OptionalField("p3_tracker_mm", lambda r: _some(lambda s: s.p_tracker_mm, r.smr(3))),
    OptionalField("sigma_mm", sigma_of, nests=True),
)


def check_records(records: Sequence[Record], source: str, lines: Sequence[int] | None = None) -> None:
    """The rules the point records of one log obey together: sets the plan knows, nest records with a ``nest_id``,
    one joint count, every :data:`OPTIONAL_FIELDS` value in all records or none, nest records timed (``t_end_s``:
    drift is a function of time). A broken rule is one :class:`DataError` line naming ``source``, the record's
    line (``lines[i]``: 1-based line of record i in ``source``, when known) and its point id."""
    def fail(i: int, what: str) -> DataError:
        line = lines[i] if lines is not None and i < len(lines) else None
        return DataError(source, f"point record {i + 1} (point_id {records[i].point_id!r}): {what}", line=line)

    for i, rec in enumerate(records):
        if rec.set not in SETS:
            raise fail(i, f"set must be calib, test, check or nest, got {rec.set!r}")
        if isinstance(rec, NestRecord) and not rec.nest_id:
            raise fail(i, "a nest record without 'nest_id'")
    robot = [i for i, rec in enumerate(records) if isinstance(rec, PointRecord)]
    odd = next((i for i in robot if records[i].n_joints != records[robot[0]].n_joints), None)
    if odd is not None:
        raise fail(odd, f"{records[odd].n_joints} joint values, point record {robot[0] + 1} has "
                        f"{records[robot[0]].n_joints} (point records have different joint counts)")
    for field in OPTIONAL_FIELDS:
        rows = range(len(records)) if field.nests else robot
        missing = [i for i in rows if field.get(records[i]) is None]
        if missing and len(missing) < len(rows) and not field.gaps_ok([records[i] for i in rows]):
            raise fail(missing[0], f"has no '{field.name}' while other points do")
    if len(robot) < len(records) and all(rec.t_end_s is None for rec in records):
        nest = next(i for i, rec in enumerate(records) if isinstance(rec, NestRecord))
        raise fail(nest, "nest records need 't_end_s' (drift is a function of time)")
