"""Typed frozen records of what the runner logs per point.

* :class:`PointRecord` -- one robot measurement (a ``point`` record of ``log.jsonl``, kind plan/check/test/verify);
* :class:`NestRecord` -- one reference-nest reading (a ``point`` record with ``set`` and ``kind`` "nest").

Each has ``to_dict()`` giving exactly the JSON written today (same keys, same order, optional keys left out when
they are absent) and ``from_dict()`` that checks the types and raises :class:`RecordError` naming the field.
Units are in the field names (``_mm``, ``_mm2``, ``_deg``, ``_s``, ``_kg``, ``_c``); frames as in the log
(``p_tracker_mm`` tracker frame, ``p_target_base_mm`` robot base frame). The reports are records of their own
(``campaign.calibrate.calibration_report``, ``campaign.correct.verify_report``).
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from campaign.io.json_fields import (RecordError, count_field, float_list, float_rows, mat3_field, number_field,
                                     object_field, text_field, vector_field)


__all__ = ["SmrReading", "PointRecord", "NestRecord", "point_from_dict"]


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
        return {f"p{k}_tracker_mm": float_list(self.p_tracker_mm), f"cov{k}_mm2": float_rows(self.cov_mm2),
                f"spread{k}_mm": float(self.spread_mm), f"retries{k}": int(self.retries)}

    @classmethod
    def from_dict(cls, data: Mapping, k: int) -> "SmrReading | None":
        """SMR ``k``'s fields of a point record, or None when the record has none."""
        if f"p{k}_tracker_mm" not in data:
            return None
        return cls(k, vector_field(data, f"p{k}_tracker_mm", 3), mat3_field(data, f"cov{k}_mm2"), number_field(data, f"spread{k}_mm"),
                   count_field(data, f"retries{k}"))


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
        data = {"point_id": self.point_id, "set": self.set, "q_cmd_deg": float_list(self.q_cmd_deg),
                "q_read_deg": float_list(self.q_read_deg), "p_tracker_mm": float_list(self.p_tracker_mm),
                "cov_mm2": float_rows(self.cov_mm2), "cov_source": self.cov_source, "spread_mm": float(self.spread_mm),
                "n_samples": int(self.n_samples), "t_start_s": float(self.t_start_s),
                "t_measure_s": self.t_measure_s, "t_end_s": float(self.t_end_s),
                "approach": float_list(self.approach), "payload_kg": float(self.payload_kg),
                "retries": int(self.retries), "p_target_base_mm": float_list(self.p_target_base_mm)}
        for name in _LATER_FIELDS:                        # absent in logs written before these fields existed
            if data[name] is None:
                del data[name]
            elif name == "t_measure_s":
                data[name] = float(data[name])
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
        return data

    @classmethod
    def from_dict(cls, data: Mapping, n_joints: int | None = None) -> "PointRecord":
        """Check and convert a point record's data; RecordError names the first bad field. The joint vectors
        have ``n_joints`` values (the robot's, when known), else as many as ``q_cmd_deg``."""
        n = len(vector_field(data, "q_cmd_deg", n_joints))
        smrs = tuple(s for s in (SmrReading.from_dict(data, k) for k in (2, 3)) if s is not None)
        return cls(
            text_field(data, "point_id"), text_field(data, "set"), vector_field(data, "q_cmd_deg"), vector_field(data, "q_read_deg", n),
            vector_field(data, "p_tracker_mm", 3), mat3_field(data, "cov_mm2"), text_field(data, "cov_source", True),
            number_field(data, "spread_mm"), count_field(data, "n_samples"), number_field(data, "t_start_s"), number_field(data, "t_measure_s", True),
            number_field(data, "t_end_s"), vector_field(data, "approach", n), number_field(data, "payload_kg"), count_field(data, "retries"),
            vector_field(data, "p_target_base_mm", 3), object_field(data, "temperatures", True),
            vector_field(data, "joint_temp_c", n, True), vector_field(data, "payload_cog_flange_mm", 3, True),
            vector_field(data, "device_std_mm", 3, True),
            mat3_field(data, "device_cov_mm2", "device_std_mm" not in data), smrs)


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
        return cls(text_field(data, "point_id"), text_field(data, "nest_id"), vector_field(data, "p_tracker_mm", 3),
                   mat3_field(data, "cov_mm2"), number_field(data, "spread_mm"), count_field(data, "n_samples"),
                   number_field(data, "t_start_s"), number_field(data, "t_end_s"), count_field(data, "retries"),
                   vector_field(data, "p_nest_base_mm", 3), object_field(data, "temperatures", True))


def point_from_dict(data: Mapping, n_joints: int | None = None) -> PointRecord | NestRecord:
    """A log ``point`` record's data as the typed record its ``set`` says (nest or robot point with ``n_joints``
    joint values, when known)."""
    if not isinstance(data, Mapping):
        raise RecordError("data", f"expected an object, got {repr(data)[:80]}")
    return NestRecord.from_dict(data) if data.get("set") == "nest" else PointRecord.from_dict(data, n_joints)
