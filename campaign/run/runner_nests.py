"""Reference-nest readings of a run: :class:`NestReader`, the runner's collaborator.

A nest point: the robot does not move; the tracker aims at the nest (``tracker.select_nest(nest_id, guess)``, or
``reacquire(guess)`` at the nest's last reading, the first time at its ``plan.nests`` ``p_tracker_mm``, required for
such drivers) and the reading becomes a :class:`NestRecord`. A reading more than ``max_move_mm`` from the nest's
first reading is read once more (a misread; the first reading is kept in a ``nest_reread`` event); when the second
reading is off too, the run pauses (tracker stand or nest disturbed).
"""
from __future__ import annotations

from typing import Callable, Protocol

import numpy as np

from drivers.base import Clock, DriverError, SelectsNest, TrackerError, TrackerReading, can_reacquire, device_url

from campaign.config.plan_schema import NestsConfig
from campaign.errors import one_line
from campaign.plan.points import PlanPoint
from .log_events import NestReread
from .log_records import NestRecord
from .log_writer import RunLog

# mean (3,) mm tracker frame, spread (mm), the readings, failed readings
Readings = tuple[np.ndarray, float, list[TrackerReading], int]


class PointFailed(Exception):
    """A point could not be measured within the retry limits (the run pauses)."""


class NestHost(Protocol):
    """What a :class:`NestReader` uses of its runner: the clock, the logged covariance (3,) mm -> (3, 3) mm^2, the
    readings at the tracker's current aim (``smr=0``: not the robot's SMR, a beam break does not search there), the
    tracker's environment, and aiming back at the robot's SMR 1."""
    clock: Clock
    covariance: Callable[[np.ndarray], np.ndarray]

    def measure_readings(self, point: PlanPoint, log: RunLog, smr: int = 1) -> Readings: ...

    def tracker_environment(self, point: PlanPoint, log: RunLog) -> dict: ...

    def aim_at_robot_smr(self) -> None: ...


class NestReader:
    """Reads the plan's reference nests with ``tracker`` for ``host`` (the runner); ``first``/``last`` hold each
    nest's first and last reading of the run (tracker frame, mm). DriverError at construction when the tracker
    cannot aim at the plan's nests."""

    def __init__(self, tracker, nests: NestsConfig | None, host: NestHost) -> None:
        self.tracker, self.nests, self.host = tracker, nests or NestsConfig(), host
        if self.nests.points and not isinstance(tracker, SelectsNest):
            if not can_reacquire(tracker):
                raise DriverError(f"{device_url(tracker, 'tracker')}: the plan has reference nests but this "
                                  "tracker driver cannot aim at a fixed point (no select_nest or reacquire)")
            blind = [n.id for n in self.nests.points if n.p_tracker_mm is None]
            if blind:
                raise DriverError(f"{device_url(tracker, 'tracker')}: this tracker driver aims by position only "
                                  f"(reacquire): give plan.nests p_tracker_mm for nest {blind[0]}")
        self.first: dict[str, np.ndarray] = {}
        self.last: dict[str, np.ndarray] = {}

    def remember(self, record: NestRecord) -> None:
        """A reading of an earlier session (resume), so that the bound refers to the run's start."""
        p = np.asarray(record.p_tracker_mm, float)
        self.first.setdefault(record.nest_id, p)
        self.last[record.nest_id] = p

    def read(self, point: PlanPoint, log: RunLog) -> NestRecord:
        """A nest reading; one more when it is more than ``max_move_mm`` from the nest's first reading (a misread:
        the first reading is kept in a ``nest_reread`` event of the log, the second one is returned)."""
        record = self.measure(point, log)
        moved = self._move_mm(record)
        if moved > self.nests.max_move_mm:
            log.append_event(NestReread(f"nest {record.nest_id} read {moved:.3f} mm from its first reading",
                                        record.to_dict(), self.host.clock.now()))
            record = self.measure(point, log)
        return record

    def check(self, record: NestRecord) -> None:
        """Pause (PointFailed) when the nest, read twice (:meth:`read`), reads more than ``max_move_mm`` from its
        first reading; the reading becomes the nest's last (and first, the first time)."""
        nest_id, p = record.nest_id, np.asarray(record.p_tracker_mm, float)
        first = self.first.setdefault(nest_id, p)
        self.last[nest_id] = p
        moved = float(np.linalg.norm(p - first))
        if moved > self.nests.max_move_mm:
            raise PointFailed(f"nest {nest_id} moved {moved:.3f} mm since its first reading (bound "
                              f"{self.nests.max_move_mm:g} mm, plan.nests.max_move_mm; read twice): tracker stand "
                              "or nest disturbed; check them before resuming")

    def measure(self, point: PlanPoint, log: RunLog) -> NestRecord:
        """One reading of a reference nest (the robot stays where it is); returns the log record."""
        host, nest_id = self.host, point.point_id.rsplit("@", 1)[0]
        t_start = host.clock.now()
        self._aim(nest_id)
        try:
            mean, spread, readings, retries = host.measure_readings(point, log, smr=0)
        finally:
            host.aim_at_robot_smr()
        env = host.tracker_environment(point, log)
        return NestRecord(point.point_id, nest_id, tuple(mean), tuple(map(tuple, host.covariance(mean))), spread,
                          len(readings), t_start, host.clock.now(), retries, tuple(point.p_base_mm), env or None)

    def _guess(self, nest_id: str) -> np.ndarray | None:
        """Where to aim (tracker frame, mm): the nest's last reading, else its configured ``p_tracker_mm``."""
        if nest_id in self.last:
            return self.last[nest_id]
        given = next((n.p_tracker_mm for n in self.nests.points if n.id == nest_id), None)
        return None if given is None else np.asarray(given, float)

    def _aim(self, nest_id: str) -> None:
        """Aim the tracker at the nest; a failed search pauses the run (PointFailed) with the reason."""
        guess = self._guess(nest_id)
        try:
            if isinstance(self.tracker, SelectsNest):
                self.tracker.select_nest(nest_id, None if guess is None else tuple(float(v) for v in guess))
            else:
                self.tracker.reacquire(tuple(float(v) for v in guess))
        except TrackerError as exc:
            raise PointFailed(f"nest {nest_id}: tracker cannot find it ({one_line(exc)})") from None

    def _move_mm(self, record: NestRecord) -> float:
        """Distance (mm) of a nest reading from the nest's first reading of the run (0 for the first one)."""
        first = self.first.get(record.nest_id)
        return 0.0 if first is None else float(np.linalg.norm(np.asarray(record.p_tracker_mm, float) - first))
