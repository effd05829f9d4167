"""Typed frozen records of the run log's ``event`` records, and how a run ends.

* :class:`ExitStatus` -- success | abort | fail | paused (a ``str`` Enum: the ``stop`` record stores its value);
* :class:`LogEvent` -- base of the event records, one subclass per event ``type`` (:data:`EVENT_TYPES`); each has
  ``to_dict()`` giving exactly the JSON written before events were typed (same keys, same values: the bytes of a
  log do not change) and ``from_dict()`` that checks every field and raises :class:`RecordError` naming it.

Point records are in :mod:`campaign.run.log_records` (this is its sibling: one module would pass the line cap).
``t_s`` is the runner's clock (s) when the event was written.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import MISSING, dataclass, field, fields
from enum import StrEnum
from typing import Any, ClassVar

from campaign.io.json_fields import RecordError, check_field, record_dict

__all__ = ["ExitStatus", "LogEvent", "EVENT_TYPES", "event_from_dict", "PauseEvent", "FaultEvent", "DevicesEvent",
           "FirstPassEvent", "EnvironmentFault", "JointTemperatureFault", "TrackerFault", "ReacquireEvent",
           "TrackerStep", "ResumeEvent", "NestReread", "ForecastEvent"]


class ExitStatus(StrEnum):
    """How a run ended (the ``stop`` record's ``exit_status``; a ``str``: stored, printed and compared as its
    value): every point measured, paused (retries spent, resumable), aborted (Ctrl-C, a signal), failed."""
    SUCCESS = "success"
    ABORT = "abort"
    FAIL = "fail"
    PAUSED = "paused"


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


# annotation -> (check, what is expected, conversion of the JSON value); numbers are kept as read (an int stays one)
_EVENT_VALUES = {
    "str": (lambda v: isinstance(v, str), "a string", None),
    "float": (_is_number, "a number", None),
    "int": (lambda v: type(v) is int, "an integer", None),
    "dict": (lambda v: isinstance(v, Mapping), "an object", dict),
    "list": (lambda v: isinstance(v, (list, tuple)), "a list", list),
    "tuple[str, ...]": (lambda v: isinstance(v, (list, tuple)) and all(isinstance(x, str) for x in v),
                        "a list of strings", tuple),
    "tuple[tuple[int, float], ...]": (
        lambda v: isinstance(v, (list, tuple)) and all(isinstance(x, (list, tuple)) and len(x) == 2
                                                       and type(x[0]) is int and _is_number(x[1]) for x in v),
        "a list of [n, value] pairs", lambda v: tuple((x[0], x[1]) for x in v)),
}


def _omitted() -> Any:
    """A field left out of the event's data when None (keys only some events of a type carry)."""
    return field(default=None, metadata={"omit_none": True})


@dataclass(frozen=True)
class LogEvent:
    """Base of the event records: ``TYPE`` is the event's ``type``; :meth:`to_dict` is the stored data (``type``,
    then the fields as they are, those marked omitted left out when None), :meth:`from_dict` checks the type and
    each field's kind (:data:`_EVENT_VALUES`, ``| None`` when null is allowed) and raises
    :class:`RecordError` naming the first bad one. Values are kept as given, so a record read back writes the
    same bytes."""
    TYPE: ClassVar[str] = ""

    def to_dict(self) -> dict:
        omit = tuple(f.name for f in fields(self) if f.metadata.get("omit_none"))
        return {"type": self.TYPE, **record_dict(self, omit)}

    @classmethod
    def from_dict(cls, data: Mapping) -> "LogEvent":
        _check_type(cls, data)
        return cls(**{f.name: _event_field(data, f) for f in fields(cls)})


def _check_type(cls: type[LogEvent], data: Mapping) -> None:
    if not isinstance(data, Mapping) or data.get("type") != cls.TYPE:
        got = data.get("type") if isinstance(data, Mapping) else data
        raise RecordError("type", f"expected {cls.TYPE!r}, got {repr(got)[:80]}")


def _event_field(data: Mapping, f) -> Any:
    """The checked value of an event's field ``f`` (its annotation says the kind and whether null is allowed; a
    field with a default may be absent)."""
    if f.name not in data and f.default is not MISSING:
        return f.default
    kind, optional = str(f.type).removesuffix(" | None"), str(f.type).endswith("| None")
    ok, expected, convert = _EVENT_VALUES[kind]
    return check_field(data, f.name, optional, ok, expected, convert or (lambda v: v))


@dataclass(frozen=True)
class PauseEvent(LogEvent):
    """The run paused (a point's retries spent); ``reason`` one line; ``t_s`` the runner's clock (s)."""
    TYPE: ClassVar[str] = "pause"
    reason: str
    t_s: float


@dataclass(frozen=True)
class FaultEvent(LogEvent):
    """A device fault ended the run: ``device`` (robot), the one-line ``reason``."""
    TYPE: ClassVar[str] = "fault"
    device: str
    reason: str
    t_s: float


@dataclass(frozen=True)
class DevicesEvent(LogEvent):
    """Before the first move of a session: the devices' identities, the caps and payload sent to the robot driver
    (when configured: ``{"max_tcp_speed_mm_s", "max_joint_speed_pct"}``, ``{"mass_kg", "cog_flange_mm"}``) and
    the controller's speed override (percent, null when not readable)."""
    TYPE: ClassVar[str] = "devices"
    robot_identity: dict
    tracker_identity: dict
    driver_versions: dict
    software_version: str
    speed_override_pct: float | None
    t_s: float
    motion_limits: dict | None = _omitted()
    payload: dict | None = _omitted()


@dataclass(frozen=True)
class FirstPassEvent(LogEvent):
    """The reduced-speed first pass: ``state`` start (with its caps) or done."""
    TYPE: ClassVar[str] = "first_pass"
    state: str
    t_s: float
    max_tcp_speed_mm_s: float | None = _omitted()
    max_joint_speed_pct: float | None = _omitted()


@dataclass(frozen=True)
class PointFault(LogEvent):
    """Base of a side reading that failed at a point (the point is kept without it): the one-line ``reason``."""
    point_id: str
    reason: str
    t_s: float


@dataclass(frozen=True)
class EnvironmentFault(PointFault):
    """The tracker's weather read failed at a point."""
    TYPE: ClassVar[str] = "environment_fault"


@dataclass(frozen=True)
class JointTemperatureFault(PointFault):
    """The robot's joint temperatures could not be read at a point."""
    TYPE: ClassVar[str] = "joint_temperature_fault"


@dataclass(frozen=True)
class TrackerFault(LogEvent):
    """A failed tracker reading: its ``kind`` (beam_broken, unstable, ...) and the point's ``attempt``-th fault."""
    TYPE: ClassVar[str] = "tracker_fault"
    point_id: str
    kind: str
    attempt: int
    reason: str
    t_s: float


@dataclass(frozen=True)
class ReacquireEvent(LogEvent):
    """A search after a beam break: ``step`` predicted (aiming at ``p_tracker_mm``, mm tracker frame) or found."""
    TYPE: ClassVar[str] = "reacquire"
    point_id: str
    step: str
    t_s: float
    p_tracker_mm: list | None = _omitted()


@dataclass(frozen=True)
class TrackerStep(LogEvent):
    """One recovery step the tracker driver reports (``details``: ``{"step": ..., ...}``, stored beside the
    point id and time)."""
    TYPE: ClassVar[str] = "tracker_step"
    point_id: str
    details: dict
    t_s: float

    def to_dict(self) -> dict:
        return {"type": self.TYPE, "point_id": self.point_id, **self.details, "t_s": self.t_s}

    @classmethod
    def from_dict(cls, data: Mapping) -> "TrackerStep":
        _check_type(cls, data)
        head = {f.name: _event_field(data, f) for f in fields(cls) if f.name != "details"}
        return cls(details={k: v for k, v in data.items() if k not in ("type", "point_id", "t_s")}, **head)


@dataclass(frozen=True)
class ResumeEvent(LogEvent):
    """A session resumed the run: the last stop's exit status (null if none) and the torn tail's bytes dropped."""
    TYPE: ClassVar[str] = "resume"
    previous_exit: str | None
    dropped_tail_bytes: int


@dataclass(frozen=True)
class NestReread(LogEvent):
    """A nest read off its first reading was read again; ``first_reading`` the set-aside :class:`NestRecord`'s data."""
    TYPE: ClassVar[str] = "nest_reread"
    reason: str
    first_reading: dict
    t_s: float


@dataclass(frozen=True)
class ForecastEvent(LogEvent):
    """When a run starts: the predicted learning curve ``[[n, mm], ...]`` and the planned and grid minutes."""
    TYPE: ClassVar[str] = "forecast"
    curve: list
    minutes_planned: float | None
    minutes_grid: float | None


EVENT_TYPES: dict[str, type[LogEvent]] = {c.TYPE: c for c in (
    PauseEvent, FaultEvent, DevicesEvent, FirstPassEvent, EnvironmentFault, JointTemperatureFault, TrackerFault,
    ReacquireEvent, TrackerStep, ResumeEvent, NestReread, ForecastEvent)}


def event_from_dict(data: Mapping) -> LogEvent:
    """An event record's data as its typed record (:data:`EVENT_TYPES` by ``type``: the run's own events; the
    adaptive plans' ``stop_check`` and ``adaptive_round`` are read by campaign.calibrate); RecordError for an
    unknown type or a bad field."""
    kind = data.get("type") if isinstance(data, Mapping) else None
    if kind not in EVENT_TYPES:
        raise RecordError("type", f"unknown event type {kind!r}")
    return EVENT_TYPES[kind].from_dict(data)
