"""Reference-nest readings of the runner (mixed into :class:`campaign.run.runner.Runner`).

A nest point: the robot does not move; the tracker aims at the nest (``tracker.select_nest(nest_id, guess)``, or
``reacquire(guess)`` at the nest's last reading, the first time at its ``plan.nests`` ``p_tracker_mm``, required for
such drivers) and the reading becomes a :class:`NestRecord`. A reading more than ``max_move_mm`` from the nest's
first reading is read once more (a misread; the first reading is kept in a ``nest_reread`` event); when the second
reading is off too, the run pauses (tracker stand or nest disturbed).
"""
from __future__ import annotations

import numpy as np

from drivers.base import DriverError, TrackerError

from campaign.config.plan_schema import NestsConfig
from campaign.plan.points import PlanPoint
from .log_records import NestRecord
from .log_writer import RunLog


class PointFailed(Exception):
    """A point could not be measured within the retry limits (the run pauses)."""


class NestReadings:
    """The runner's nest methods; the runner provides ``tracker``, ``clock``, ``covariance``, ``p_last``,
    ``q_read``, ``predict_p_tracker_mm`` and ``_measure_with_retries``."""

    def _init_nests(self, tracker, nests: NestsConfig | None) -> None:
        """Check that the tracker driver can aim at the plan's nests; empty first/last readings."""
        self.nests = nests or NestsConfig()
        if self.nests.points and not callable(getattr(tracker, "select_nest", None)):
            if not (callable(getattr(tracker, "reacquire", None)) and getattr(tracker, "can_reacquire", True)):
                raise DriverError(f"{getattr(tracker, 'url', 'tracker')}: the plan has reference nests but this "
                                  "tracker driver cannot aim at a fixed point (no select_nest or reacquire)")
            blind = [n.id for n in self.nests.points if n.p_tracker_mm is None]
            if blind:
                raise DriverError(f"{getattr(tracker, 'url', 'tracker')}: this tracker driver aims by position only "
                                  f"(reacquire): give plan.nests p_tracker_mm for nest {blind[0]}")
        self.nest_first: dict[str, np.ndarray] = {}     # first reading of each nest (tracker frame, mm)
        self.nest_last: dict[str, np.ndarray] = {}

    def _remember_nests(self, contents) -> None:
        """First/last nest readings of earlier sessions (resume), so the bound refers to the run's start."""
        for rec in getattr(contents, "records", lambda: [])():
            p = np.asarray(rec.p_tracker_mm, float)
            if isinstance(rec, NestRecord):
                self.nest_first.setdefault(rec.nest_id, p)
                self.nest_last[rec.nest_id] = p
            else:
                self.p_last = p

    def _nest_guess(self, nest_id: str) -> np.ndarray | None:
        """Where to aim (tracker frame, mm): the nest's last reading, else its configured ``p_tracker_mm``."""
        if nest_id in self.nest_last:
            return self.nest_last[nest_id]
        given = next((n.p_tracker_mm for n in self.nests.points if n.id == nest_id), None)
        return None if given is None else np.asarray(given, float)

    def _aim_at_nest(self, nest_id: str) -> None:
        """Aim the tracker at the nest; a failed search pauses the run (PointFailed) with the reason."""
        guess = self._nest_guess(nest_id)
        try:
            if callable(getattr(self.tracker, "select_nest", None)):
                self.tracker.select_nest(nest_id, None if guess is None else tuple(float(v) for v in guess))
            else:
                self.tracker.reacquire(tuple(float(v) for v in guess))
        except TrackerError as exc:
            raise PointFailed(f"nest {nest_id}: tracker cannot find it ({' '.join(str(exc).split())})") from None

    def _aim_back(self) -> None:
        """Back to the robot's SMR 1 after a nest reading (its predicted position, else its last reading)."""
        self._smr = 1
        if callable(getattr(self.tracker, "select_smr", None)):
            self.tracker.select_smr(1)
            return
        p = self.p_last
        if self.predict_p_tracker_mm is not None and self.q_read is not None:
            p = np.asarray(self.predict_p_tracker_mm(self.q_read), float)
        if p is not None and callable(getattr(self.tracker, "reacquire", None)):
            self.tracker.reacquire(tuple(float(v) for v in p))

    def measure_nest(self, point: PlanPoint, log: RunLog) -> NestRecord:
        """One reading of a reference nest (the robot stays where it is); returns the log record."""
        nest_id = point.point_id.rsplit("@", 1)[0]
        t_start = self.clock.now()
        self._aim_at_nest(nest_id)
        self._smr = 0                                   # a beam break now must not search at the robot's SMR
        try:
            mean, spread, readings, retries = self._measure_with_retries(point, log)
        finally:
            self._aim_back()
        try:
            env = dict(self.tracker.environment() or {})
        except DriverError as exc:
            env = {}
            log.append_event({"type": "environment_fault", "point_id": point.point_id,
                              "reason": " ".join(str(exc).split()), "t_s": self.clock.now()})
        cov = self.covariance(mean)
        rec = NestRecord(point.point_id, nest_id, tuple(mean), tuple(map(tuple, cov)), spread, len(readings),
                         t_start, self.clock.now(), retries, tuple(point.p_base_mm), env or None)
        return rec

    def read_nest(self, point: PlanPoint, log: RunLog) -> NestRecord:
        """A nest reading; one more when it is more than ``max_move_mm`` from the nest's first reading (a misread:
        the first reading is kept in a ``nest_reread`` event of the log, the second one is returned)."""
        record = self.measure_nest(point, log)
        moved = self._nest_move_mm(record)
        if moved > self.nests.max_move_mm:
            log.append_event({"type": "nest_reread", "reason": f"nest {record.nest_id} read {moved:.3f} mm from its "
                              "first reading", "first_reading": record.to_dict(), "t_s": self.clock.now()})
            record = self.measure_nest(point, log)
        return record

    def _nest_move_mm(self, record: NestRecord) -> float:
        """Distance (mm) of a nest reading from the nest's first reading of the run (0 for the first one)."""
        first = self.nest_first.get(record.nest_id)
        return 0.0 if first is None else float(np.linalg.norm(np.asarray(record.p_tracker_mm, float) - first))

    def _check_nest(self, record: NestRecord) -> None:
        """Pause when the nest (read twice, ``read_nest``) reads more than ``max_move_mm`` from its first reading."""
        nest_id, p = record.nest_id, np.asarray(record.p_tracker_mm, float)
        first = self.nest_first.setdefault(nest_id, p)
        self.nest_last[nest_id] = p
        moved = float(np.linalg.norm(p - first))
        if moved > self.nests.max_move_mm:
            raise PointFailed(f"nest {nest_id} moved {moved:.3f} mm since its first reading (bound "
                              f"{self.nests.max_move_mm:g} mm, plan.nests.max_move_mm; read twice): tracker stand "
                              "or nest disturbed; check them before resuming")
