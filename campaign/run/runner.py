"""The runner: executes a Plan on a Robot and a Tracker and appends every measurement to the RunLog.

Per point: move (fine) -> settle -> read back joints -> N tracker samples -> stability test -> append +
fsync -> only then the next move. Tracker faults are retried within limits; when retries are exhausted
the run *pauses* (log closed with exit_status "paused" and the reason) instead of losing or faking the
point, and ``campaign run CONFIG --resume RUN_DIR`` continues it. Ctrl-C stops the robot and closes the
log cleanly ("abort"). One ``finally`` in ``execute`` commands the robot to stop exactly once and closes the
log with the exit status and reason whatever happened (driver, log, I/O or programming errors alike; the
last are re-raised after the log is closed).
Before the first move the robot driver receives the motion caps (``set_motion_limits``; a driver that cannot
enforce them is refused) and the payload, and the speed override is read; all are logged in a ``devices``
event with the robot and tracker identification. With a ``PathGuard`` every move, via poses included, is
checked along its swept path first, and the first move is routed from wherever the robot stands.
With a multi-SMR tool (``n_smrs`` 2 or 3, seed 003) the tracker is aimed at each further SMR in turn
(``tracker.select_smr(k)``) at the same stop, and the record gains ``p2_tracker_mm`` / ``p3_tracker_mm``
(+ ``cov2_mm2`` / ``cov3_mm2``); the tracker is aimed back at SMR 1 before the next move.
Reference nests (plan points of set ``nest``, :mod:`campaign.run.runner_nests`): the robot does not move, the tracker
reads the nest; a reading off its first one is read again, then the run pauses.
"""
from __future__ import annotations

import logging
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Callable, Iterable, Iterator, Mapping, Protocol, Sequence

import numpy as np

from robocal.measure.approach import next_approach

from drivers.base import (BeamBroken, Clock, DrainsEvents, DriverError, EnforcesMotionLimits, MotionLimits, Payload,
                          ReadsJointTemperatures, ReadsSpeedOverride, Robot, SelectsSmr, TakesPayload, Tracker,
                          TrackerError, Unstable, average_samples, backoff_s, can_reacquire, device_url)

from campaign.config.plan_schema import NestsConfig
from campaign.config.schema import MeasurementConfig
from campaign.errors import one_line
from campaign.plan.motion_safety import PathGuard, UnsafeMotion
from campaign.plan.points import PlanPoint
from .log_events import (DevicesEvent, EnvironmentFault, ExitStatus, FaultEvent, FirstPassEvent,
                         JointTemperatureFault, LogEvent, PauseEvent, ReacquireEvent, TrackerFault, TrackerStep)
from .log_records import NestRecord, PointRecord, SmrReading
from .runner_nests import NestReader, PointFailed, Readings
from .log_writer import RunLog
from .log_reader import RunLogError
from .tracker_quality import check_device_stability, device_covariance
from .traceability import device_identity, environment_from_readings


logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class RunOutcome:
    """How a run ended: its exit status, a one-line reason, points measured now."""
    exit_status: ExitStatus
    reason: str
    n_measured: int


class Runner:
    """Executes plan points; ``covariance(p_tracker_mm (3,)) -> (3, 3)`` gives the logged uncertainty;
    ``on_point(point, record)`` is called after each record is on disk (a :class:`PointRecord`, or a
    :class:`NestRecord` for a nest point). ``limits`` (caps sent to the driver before the first move),
    ``payload``, ``guard`` (swept-path checks and routes) and ``first_pass_limits`` (a reduced-speed traverse of
    the plan before measuring): None = none. Reference nests are read by its :class:`NestReader` (``nests``)."""

    def __init__(self, robot: Robot, tracker: Tracker, measurement: MeasurementConfig, clock: Clock,
                 covariance: Callable[[np.ndarray], np.ndarray], payload_kg: float = 0.0,
                 on_point: Callable[[PlanPoint, PointRecord | NestRecord], None] | None = None,
                 n_smrs: int = 1,
                 predict_p_tracker_mm: Callable[[np.ndarray], np.ndarray] | None = None,
                 covariance_from_device: Callable[[np.ndarray], np.ndarray] | None = None,
                 nests: NestsConfig | None = None, *, limits: MotionLimits | None = None,
                 payload: Payload | None = None, guard: PathGuard | None = None,
                 first_pass_limits: MotionLimits | None = None) -> None:
        self.robot, self.tracker, self.m, self.clock = robot, tracker, measurement, clock
        self.covariance, self.payload_kg, self.on_point = covariance, payload_kg, on_point
        if n_smrs > 1 and not isinstance(tracker, SelectsSmr):
            raise DriverError(f"{device_url(tracker, 'tracker')}: the tool has {n_smrs} SMRs but this tracker "
                              "driver cannot aim at another SMR (no select_smr)")
        self.n_smrs = n_smrs
        # after a beam break: aim the tracker at predict_p_tracker_mm(q_read_deg) (mm, tracker frame) and search;
        # covariance_from_device(device cov (3, 3)) -> the logged covariance when the tracker reports its own
        self.predict_p_tracker_mm, self.covariance_from_device = predict_p_tracker_mm, covariance_from_device
        self.q_read: np.ndarray | None = None
        self._smr = 1                                     # the SMR the tracker aims at (0: a reference nest)
        self.nests = NestReader(tracker, nests, self)
        self.p_last: np.ndarray | None = None             # last robot SMR reading (to aim back after a nest)
        self.q_prev: np.ndarray | None = None
        self.approach: np.ndarray | None = None
        self.limits, self.payload, self.guard, self.first_pass_limits = limits, payload, guard, first_pass_limits
        self.q_at: np.ndarray | None = None               # last commanded pose (deg)
        self._poses: np.ndarray | None = None
        self._stopped = False

    def execute(self, points: Iterable[PlanPoint], log: RunLog) -> RunOutcome:
        """Measure ``points`` in order; return how the run ended. The log is closed with the exit status and
        reason whatever happens."""
        return self.execute_passes(_OnePass(points), log)

    def execute_passes(self, plan: "PassPlan", log: RunLog) -> RunOutcome:
        """Measure the passes of ``plan`` in turn (each pass's measurements decide the next), then close the log
        with the exit status and reason whatever happens; the robot is stopped once at the end."""
        n = 0
        status, reason, self._stopped = ExitStatus.FAIL, "internal error", False
        self._remember(getattr(log, "contents", None))
        try:
            points = plan.first()
            while points is not None:
                p_tracker_mm, n_pass = self._measure_pass(list(points), log)
                n += n_pass
                points = plan.next(p_tracker_mm)
            status, reason = ExitStatus.SUCCESS, "all planned points measured"
        except PointFailed as exc:
            self._safe_stop()
            status, reason = ExitStatus.PAUSED, str(exc)
            self._event(log, lambda t_s: PauseEvent(reason, t_s))
        except KeyboardInterrupt as exc:                     # Ctrl-C, or a signal raised as a subclass with a reason
            self._safe_stop()
            status = ExitStatus.ABORT
            reason = one_line(exc) if type(exc) is not KeyboardInterrupt and str(exc) else \
                "interrupted by the operator (Ctrl-C)"
        except (DriverError, UnsafeMotion) as exc:
            self._safe_stop()
            status, reason = ExitStatus.FAIL, one_line(exc)
            self._event(log, lambda t_s: FaultEvent("robot", reason, t_s))
        except (OSError, RunLogError) as exc:               # the log or the disk failed: stop, keep what is on disk
            self._safe_stop()
            status, reason = ExitStatus.FAIL, f"{type(exc).__name__}: {one_line(exc)}"
        except BaseException as exc:                         # a bug or a signal: stop, close, then re-raise
            self._safe_stop()
            status = ExitStatus.FAIL if isinstance(exc, Exception) else ExitStatus.ABORT
            reason = f"{type(exc).__name__}: {one_line(exc)}"
            raise
        finally:
            self._safe_stop()
            (logger.info if status == ExitStatus.SUCCESS else logger.warning)(
                "run %s: %s (%d points measured now)", status, reason, n)
            close_log(log, status, reason)
        return RunOutcome(status, reason, n)

    def _measure_pass(self, points: list[PlanPoint], log: RunLog) -> tuple[np.ndarray, int]:
        """One pass over ``points`` (caps, payload and devices event first); returns the robot points' readings
        (M, 3) mm in order and the number of points measured."""
        n, got = 0, []
        self._poses = np.array([p.q_deg for p in points], float) if points else None
        self._prepare(log)
        if self.first_pass_limits is not None and points:
            self._first_pass(points, log)
        for point in points:
            if point.set == "nest":
                record = self.nests.read(point, log)          # read twice when the first reading is off
                log.append_point(record)                  # durable before the bound check can pause
                n += 1
                if self.on_point:
                    self.on_point(point, record)
                self.nests.check(record)
                continue
            record = self.measure_point(point, log)
            log.append_point(record)                      # flushed + fsynced before the next move
            self.p_last = np.asarray(record.p_tracker_mm, float)
            got.append(self.p_last)
            n += 1
            if self.on_point:
                self.on_point(point, record)
        return np.array(got, float).reshape(-1, 3), n

    def _safe_stop(self) -> None:
        """Command the robot to stop, once per ``execute``; best effort on an already failing device."""
        if self._stopped:
            return
        self._stopped = True
        try:
            self.robot.stop()
        except Exception:  # stop is best effort on an already failing device
            pass

    def _event(self, log: RunLog, event: Callable[[float], LogEvent]) -> None:
        """Append ``event(t_s)`` on a failure path (never masks the failure being handled, a failing clock
        included)."""
        try:
            log.append_event(event(self.clock.now()))
        except Exception:
            pass

    def _remember(self, contents) -> None:
        """The last robot SMR reading and the nests' first/last readings of earlier sessions (resume)."""
        for rec in contents.records() if contents is not None else ():
            if isinstance(rec, NestRecord):
                self.nests.remember(rec)
            else:
                self.p_last = np.asarray(rec.p_tracker_mm, float)

    def _prepare(self, log: RunLog) -> None:
        """Caps and payload to the driver before the first move; speed override and identities logged."""
        robot, url = self.robot, device_url(self.robot, "robot")
        limits = payload = None
        if self.limits is not None:
            if not isinstance(robot, EnforcesMotionLimits):
                raise UnsafeMotion(f"{url}: this robot driver cannot enforce the speed caps (no set_motion_limits); "
                                   "refusing to move")
            robot.set_motion_limits(self.limits)
            limits = {"max_tcp_speed_mm_s": self.limits.max_tcp_speed_mm_s,
                      "max_joint_speed_pct": self.limits.max_joint_speed_pct}
        if self.payload is not None:
            if isinstance(robot, TakesPayload):
                robot.set_payload(self.payload)
            elif self.payload.mass_kg > 0:
                raise UnsafeMotion(f"{url}: this robot driver cannot send the payload "
                                   f"({self.payload.mass_kg:g} kg) to the controller; refusing to move")
            payload = {"mass_kg": self.payload.mass_kg, "cog_flange_mm": list(self.payload.cog_flange_mm)}
        override = robot.speed_override_pct() if isinstance(robot, ReadsSpeedOverride) else None
        event = DevicesEvent(**device_identity(robot, self.tracker), speed_override_pct=override,
                             t_s=self.clock.now(), motion_limits=limits, payload=payload)
        log.append_event(event)
        rid = event.robot_identity
        logger.info("robot %s %s serial %s software %s; caps %s; payload %s; speed override %s %%", rid["vendor"],
                    rid["model"], rid["serial"], rid["software_version"], limits, payload, override)

    def _first_pass(self, points: list[PlanPoint], log: RunLog) -> None:
        """Traverse every planned move (vias included) at the reduced caps without measuring, then restore."""
        lim = self.first_pass_limits
        self.robot.set_motion_limits(lim)
        log.append_event(FirstPassEvent("start", self.clock.now(), lim.max_tcp_speed_mm_s, lim.max_joint_speed_pct))
        for point in points:
            self._move_to(point)
        log.append_event(FirstPassEvent("done", self.clock.now()))
        self.robot.set_motion_limits(self.limits if self.limits is not None else MotionLimits())

    def _move_to(self, point: PlanPoint) -> None:
        """Move through the point's via poses to it; with a guard every leg is checked (and routed) first."""
        targets = [tuple(v) for v in point.via_deg] + [tuple(point.q_deg)]
        if self.guard is not None:
            prev = self.q_at if self.q_at is not None else np.asarray(self.robot.read_joints(), float)
            legs = []
            for q in targets:
                legs += self.guard.route(prev, q, self._poses) + [q]
                prev = np.asarray(q, float)
            targets = legs
        for q in targets:
            self.robot.move_joints(q)
            self.q_at = np.asarray(q, float)

    def measure_point(self, point: PlanPoint, log: RunLog) -> PointRecord:
        """Move, settle and measure one point; returns the log record."""
        q_cmd = np.asarray(point.q_deg, float)
        t_start = self.clock.now()
        self._move_to(point)
        self.clock.sleep(self.m.settle_s)
        q_read = np.asarray(self.robot.read_joints(), float)
        self.q_read = q_read
        approach = self._approach(q_cmd)
        t_measure = self.clock.now()                        # in position and settled: the readings start
        mean, spread, readings, retries = self.measure_readings(point, log)
        env = {**environment_from_readings(readings), **self.tracker_environment(point, log)}
        joint_temp = self._joint_temperatures(point, log)
        dev_cov = device_covariance(readings)
        use_dev = dev_cov is not None and self.covariance_from_device is not None
        cov = self.covariance_from_device(dev_cov) if use_dev else self.covariance(mean)
        payload = self.payload
        return PointRecord(                                 # t_end_s is taken before SMRs 2 and 3 are measured
            point_id=point.point_id, set=point.set, q_cmd_deg=tuple(q_cmd), q_read_deg=tuple(q_read),
            p_tracker_mm=tuple(mean), cov_mm2=tuple(map(tuple, cov)), cov_source="device" if use_dev else "spec",
            spread_mm=spread, n_samples=len(readings), t_start_s=t_start, t_measure_s=t_measure,
            t_end_s=self.clock.now(), approach=tuple(approach),
            payload_kg=payload.mass_kg if payload is not None else self.payload_kg, retries=retries,
            p_target_base_mm=tuple(point.p_base_mm), temperatures=env or None,
            joint_temp_c=None if joint_temp is None else tuple(joint_temp),
            payload_cog_flange_mm=None if payload is None else tuple(payload.cog_flange_mm),
            device_std_mm=None if dev_cov is None else tuple(np.sqrt(np.diag(dev_cov))),
            device_cov_mm2=None if dev_cov is None else tuple(map(tuple, dev_cov)),
            smrs=tuple(self._measure_smr(k, point, log) for k in range(2, self.n_smrs + 1)))

    def tracker_environment(self, point: PlanPoint, log: RunLog) -> dict:
        """The tracker's environment readings now; a failed weather read never costs the point (empty, logged)."""
        try:
            return dict(self.tracker.environment() or {})
        except DriverError as exc:
            log.append_event(EnvironmentFault(point.point_id, one_line(exc), self.clock.now()))
            return {}

    def _joint_temperatures(self, point: PlanPoint, log: RunLog) -> list[float] | None:
        """Joint (motor) temperatures in deg C where the driver reads them (:class:`ReadsJointTemperatures`)."""
        if not isinstance(self.robot, ReadsJointTemperatures):
            return None
        try:
            values = self.robot.joint_temperatures_c()
        except DriverError as exc:                          # never costs the point
            log.append_event(JointTemperatureFault(point.point_id, one_line(exc), self.clock.now()))
            return None
        return None if values is None else [float(v) for v in values]

    def _measure_smr(self, k: int, point: PlanPoint, log: RunLog) -> SmrReading:
        """SMR k at the current stop; the tracker is aimed back at SMR 1 afterwards, also on failure."""
        self.tracker.select_smr(k)
        try:
            mean, spread, _, retries = self.measure_readings(point, log, smr=k)
        finally:
            self.tracker.select_smr(1)
        return SmrReading(k, tuple(mean), tuple(map(tuple, self.covariance(mean))), spread, retries)

    def _approach(self, q_cmd: np.ndarray) -> np.ndarray:
        """Sign of the last motion of each joint before this stop (a joint that did not move keeps its sign)."""
        self.approach = next_approach(self.approach, self.q_prev, q_cmd)
        self.q_prev = q_cmd
        return self.approach

    def measure_readings(self, point: PlanPoint, log: RunLog, smr: int = 1) -> Readings:
        """Collect ``samples`` good readings of the SMR the tracker aims at (``smr`` k of the tool, 0 a reference
        nest: a beam break searches only at SMR 1); every failed reading (or an unstable set, which is discarded)
        uses one of the point's ``retries`` and is followed by a short back-off. Returns (mean (3,) mm, spread mm,
        readings, faults)."""
        self._smr = smr
        try:
            return self._measure_with_retries(point, log)
        finally:
            self._smr = 1

    def _measure_with_retries(self, point: PlanPoint, log: RunLog) -> Readings:
        faults, readings = 0, []
        while True:
            try:
                while len(readings) < self.m.samples:
                    readings.append(self.tracker.measure())
                mean, spread = average_samples(readings, self.m.stability_mm)
                check_device_stability(readings, self.m.stability_mm)
                self._log_tracker_steps(point, log)
                return mean, spread, readings, faults
            except TrackerError as exc:
                faults += 1
                if isinstance(exc, Unstable):
                    readings = []
                self._fault(point, log, exc, faults)
                if isinstance(exc, BeamBroken):
                    faults = self._reacquire(point, log, faults)
                else:
                    self.clock.sleep(backoff_s(faults))

    def _fault(self, point: PlanPoint, log: RunLog, exc: TrackerError, faults: int) -> None:
        """Log a failed reading (and the driver's recovery steps); PointFailed once the retry limit is spent."""
        self._log_tracker_steps(point, log)
        log.append_event(TrackerFault(point.point_id, exc.kind, faults, one_line(exc), self.clock.now()))
        if faults > self.m.retries:
            raise PointFailed(f"point {point.point_id}: tracker {exc.kind} ({one_line(exc)}); "
                              f"{faults} failed readings, retry limit {self.m.retries}") from None

    def _reacquire(self, point: PlanPoint, log: RunLog, faults: int) -> int:
        """After a beam break: aim at the predicted SMR position and search (each step logged); every failed
        search uses one of the point's retries (then PointFailed names it). Returns the updated fault count."""
        if not can_reacquire(self.tracker) or self.predict_p_tracker_mm is None or self.q_read is None \
                or self._smr != 1:
            self.clock.sleep(backoff_s(faults))
            return faults
        p = np.asarray(self.predict_p_tracker_mm(self.q_read), float)
        log.append_event(ReacquireEvent(point.point_id, "predicted", self.clock.now(),
                                        [round(float(v), 3) for v in p]))
        while True:                                 # search again until found or the point's retries are spent
            try:
                self.tracker.reacquire(p.tolist())
                break
            except TrackerError as exc:
                faults += 1
                self._fault(point, log, exc, faults)
                self.clock.sleep(backoff_s(faults))
        self._log_tracker_steps(point, log)
        log.append_event(ReacquireEvent(point.point_id, "found", self.clock.now()))
        return faults

    def aim_at_robot_smr(self) -> None:
        """Aim the tracker back at the robot's SMR 1 (after a nest reading): SMR selection, else a search at its
        predicted position (else its last reading)."""
        if isinstance(self.tracker, SelectsSmr):
            self.tracker.select_smr(1)
            return
        p = self.p_last
        if self.predict_p_tracker_mm is not None and self.q_read is not None:
            p = np.asarray(self.predict_p_tracker_mm(self.q_read), float)
        if p is not None and can_reacquire(self.tracker):
            self.tracker.reacquire(tuple(float(v) for v in p))

    def _log_tracker_steps(self, point: PlanPoint, log: RunLog) -> None:
        """The driver's own recovery steps (reconnect, initialise, aim, search), if it reports them."""
        for step in self.tracker.drain_events() if isinstance(self.tracker, DrainsEvents) else ():
            log.append_event(TrackerStep(point.point_id, dict(step), self.clock.now()))


class PassPlan(Protocol):
    """Passes the runner measures in turn: ``first()`` the points of the first pass, ``next(p_tracker_mm)``
    those of the following one from the robot points' readings (M, 3) mm of the previous, None when done."""

    def first(self) -> Sequence[PlanPoint] | None: ...

    def next(self, p_tracker_mm: np.ndarray) -> Sequence[PlanPoint] | None: ...


class _OnePass:
    """A plan of one pass over given points."""

    def __init__(self, points: Iterable[PlanPoint]) -> None:
        self.points = points

    def first(self):
        return list(self.points)

    def next(self, p_tracker_mm):
        return None


def close_log(log: RunLog, status: ExitStatus, reason: str) -> None:
    """Close ``log`` with its stop record (status, one-line reason) unless already closed; a broken log stays as
    it is (a resume drops its torn tail)."""
    try:
        if not getattr(log, "closed", False):
            log.close(status, reason)
    except Exception:
        pass


@contextmanager
def closing_on_error(log: RunLog) -> Iterator[RunLog]:
    """Close ``log`` with the reason when an exception leaves the block before the runner took it over."""
    try:
        yield log
    except BaseException as exc:
        close_log(log, ExitStatus.FAIL if isinstance(exc, Exception) else ExitStatus.ABORT,
                  f"{type(exc).__name__}: {one_line(exc)}")
        raise


def pending(points: Iterable[PlanPoint], done_ids: set[str]) -> list[PlanPoint]:
    """Plan points not yet in the log."""
    return [p for p in points if p.point_id not in done_ids]


def start_record(config: Mapping, config_sha256: str, plan_sha256: str, software_version: str,
                 created_utc: str) -> dict:
    return {"config_sha256": config_sha256, "plan_sha256": plan_sha256, "config": dict(config),
            "created_utc": created_utc, "software_version": software_version,
            "units": {"q": "deg (controller)", "p_tracker": "mm, tracker frame", "cov": "mm^2", "t": "s"}}
