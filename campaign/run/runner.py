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

from drivers.base import (BeamBroken, Clock, DriverError, MotionLimits, Payload, Robot, Tracker, TrackerError,
                          Unstable, average_samples)

from campaign.config.plan_schema import NestsConfig
from campaign.config.schema import MeasurementConfig
from campaign.plan.motion_safety import PathGuard, UnsafeMotion
from campaign.plan.points import PlanPoint
from .log_records import NestRecord, PointRecord, SmrReading
from .runner_nests import NestReadings, PointFailed
from .log_writer import RunLog
from .log_reader import RunLogError
from .tracker_quality import check_device_stability, device_covariance
from .traceability import device_identity, environment_from_readings


logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class RunOutcome:
    """How a run ended: exit_status success | paused | abort | fail, a one-line reason, points measured now."""
    exit_status: str
    reason: str
    n_measured: int


class Runner(NestReadings):
    """Executes plan points; ``covariance(p_tracker_mm (3,)) -> (3, 3)`` gives the logged uncertainty;
    ``on_point(point, record)`` is called after each record is on disk (a :class:`PointRecord`, or a
    :class:`NestRecord` for a nest point). ``limits`` (caps sent to the driver before the first move),
    ``payload``, ``guard`` (swept-path checks and routes) and ``first_pass_limits`` (a reduced-speed traverse of
    the plan before measuring): None = none."""

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
        if n_smrs > 1 and not callable(getattr(tracker, "select_smr", None)):
            raise DriverError(f"{getattr(tracker, 'url', 'tracker')}: the tool has {n_smrs} SMRs but this tracker "
                              "driver cannot aim at another SMR (no select_smr)")
        self.n_smrs = n_smrs
        # after a beam break: aim the tracker at predict_p_tracker_mm(q_read_deg) (mm, tracker frame) and search;
        # covariance_from_device(device cov (3, 3)) -> the logged covariance when the tracker reports its own
        self.predict_p_tracker_mm, self.covariance_from_device = predict_p_tracker_mm, covariance_from_device
        self.q_read: np.ndarray | None = None
        self._smr = 1
        self._init_nests(tracker, nests)
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
        status, reason, self._stopped = "fail", "internal error", False
        self._remember_nests(getattr(log, "contents", None))
        try:
            points = plan.first()
            while points is not None:
                p_tracker_mm, n_pass = self._measure_pass(list(points), log)
                n += n_pass
                points = plan.next(p_tracker_mm)
            status, reason = "success", "all planned points measured"
        except PointFailed as exc:
            self._safe_stop()
            status, reason = "paused", str(exc)
            self._event(log, {"type": "pause", "reason": reason})
        except KeyboardInterrupt as exc:                     # Ctrl-C, or a signal raised as a subclass with a reason
            self._safe_stop()
            status = "abort"
            reason = _one_line(exc) if type(exc) is not KeyboardInterrupt and str(exc) else \
                "interrupted by the operator (Ctrl-C)"
        except (DriverError, UnsafeMotion) as exc:
            self._safe_stop()
            status, reason = "fail", _one_line(exc)
            self._event(log, {"type": "fault", "device": "robot", "reason": reason})
        except (OSError, RunLogError) as exc:               # the log or the disk failed: stop, keep what is on disk
            self._safe_stop()
            status, reason = "fail", f"{type(exc).__name__}: {_one_line(exc)}"
        except BaseException as exc:                         # a bug or a signal: stop, close, then re-raise
            self._safe_stop()
            status = "fail" if isinstance(exc, Exception) else "abort"
            reason = f"{type(exc).__name__}: {_one_line(exc)}"
            raise
        finally:
            self._safe_stop()
            (logger.info if status == "success" else logger.warning)("run %s: %s (%d points measured now)",
                                                                      status, reason, n)
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
                record = self.read_nest(point, log)           # read twice when the first reading is off
                log.append_point(record)                  # durable before the bound check can pause
                n += 1
                if self.on_point:
                    self.on_point(point, record)
                self._check_nest(record)
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

    def _event(self, log: RunLog, data: dict) -> None:
        """Append an event on a failure path (never masks the failure being handled)."""
        try:
            log.append_event({**data, "t_s": self.clock.now()})
        except Exception:
            pass

    def _prepare(self, log: RunLog) -> None:
        """Caps and payload to the driver before the first move; speed override and identities logged."""
        robot, url = self.robot, getattr(self.robot, "url", "robot")
        info: dict = {"type": "devices", **device_identity(robot, self.tracker)}
        if self.limits is not None:
            if not callable(getattr(robot, "set_motion_limits", None)):
                raise UnsafeMotion(f"{url}: this robot driver cannot enforce the speed caps (no set_motion_limits); "
                                   "refusing to move")
            robot.set_motion_limits(self.limits)
            info["motion_limits"] = {"max_tcp_speed_mm_s": self.limits.max_tcp_speed_mm_s,
                                     "max_joint_speed_pct": self.limits.max_joint_speed_pct}
        if self.payload is not None:
            if callable(getattr(robot, "set_payload", None)):
                robot.set_payload(self.payload)
            elif self.payload.mass_kg > 0:
                raise UnsafeMotion(f"{url}: this robot driver cannot send the payload "
                                   f"({self.payload.mass_kg:g} kg) to the controller; refusing to move")
            info["payload"] = {"mass_kg": self.payload.mass_kg, "cog_flange_mm": list(self.payload.cog_flange_mm)}
        override = robot.speed_override_pct() if callable(getattr(robot, "speed_override_pct", None)) else None
        info["speed_override_pct"] = override
        log.append_event({**info, "t_s": self.clock.now()})
        rid = info["robot_identity"]
        logger.info("robot %s %s serial %s software %s; caps %s; payload %s; speed override %s %%", rid["vendor"],
                    rid["model"], rid["serial"], rid["software_version"], info.get("motion_limits"),
                    info.get("payload"), override)

    def _first_pass(self, points: list[PlanPoint], log: RunLog) -> None:
        """Traverse every planned move (vias included) at the reduced caps without measuring, then restore."""
        lim = self.first_pass_limits
        self.robot.set_motion_limits(lim)
        log.append_event({"type": "first_pass", "state": "start", "max_tcp_speed_mm_s": lim.max_tcp_speed_mm_s,
                          "max_joint_speed_pct": lim.max_joint_speed_pct, "t_s": self.clock.now()})
        for point in points:
            self._move_to(point)
        log.append_event({"type": "first_pass", "state": "done", "t_s": self.clock.now()})
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
        mean, spread, readings, retries = self._measure_with_retries(point, log)
        try:
            env = dict(self.tracker.environment() or {})
        except DriverError as exc:                          # a failed weather read never costs the point
            env = {}
            log.append_event({"type": "environment_fault", "point_id": point.point_id,
                              "reason": " ".join(str(exc).split()), "t_s": self.clock.now()})
        env = {**environment_from_readings(readings), **env}
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

    def _joint_temperatures(self, point: PlanPoint, log: RunLog) -> list[float] | None:
        """Joint (motor) temperatures in deg C where the driver offers ``joint_temperatures_c()``."""
        read = getattr(self.robot, "joint_temperatures_c", None)
        if not callable(read):
            return None
        try:
            values = read()
        except DriverError as exc:                          # never costs the point
            log.append_event({"type": "joint_temperature_fault", "point_id": point.point_id,
                              "reason": _one_line(exc), "t_s": self.clock.now()})
            return None
        return None if values is None else [float(v) for v in values]

    def _measure_smr(self, k: int, point: PlanPoint, log: RunLog) -> SmrReading:
        """SMR k at the current stop; the tracker is aimed back at SMR 1 afterwards, also on failure."""
        self.tracker.select_smr(k)
        self._smr = k
        try:
            mean, spread, _, retries = self._measure_with_retries(point, log)
        finally:
            self._smr = 1
            self.tracker.select_smr(1)
        return SmrReading(k, tuple(mean), tuple(map(tuple, self.covariance(mean))), spread, retries)

    def _approach(self, q_cmd: np.ndarray) -> np.ndarray:
        """Sign of the last motion of each joint before this stop (a joint that did not move keeps its sign)."""
        self.approach = next_approach(self.approach, self.q_prev, q_cmd)
        self.q_prev = q_cmd
        return self.approach

    def _measure_with_retries(self, point: PlanPoint, log: RunLog):
        """Collect ``samples`` good readings; every failed reading (or an unstable set, which is discarded)
        uses one of the point's ``retries`` and is followed by a short back-off. Returns (mean, spread,
        readings, faults)."""
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
                    self.clock.sleep(min(2.0, 0.2 * 2 ** (faults - 1)))

    def _fault(self, point: PlanPoint, log: RunLog, exc: TrackerError, faults: int) -> None:
        """Log a failed reading (and the driver's recovery steps); PointFailed once the retry limit is spent."""
        self._log_tracker_steps(point, log)
        log.append_event({"type": "tracker_fault", "point_id": point.point_id, "kind": exc.kind,
                          "attempt": faults, "reason": " ".join(str(exc).split()), "t_s": self.clock.now()})
        if faults > self.m.retries:
            raise PointFailed(f"point {point.point_id}: tracker {exc.kind} ({' '.join(str(exc).split())}); "
                              f"{faults} failed readings, retry limit {self.m.retries}") from None

    def _reacquire(self, point: PlanPoint, log: RunLog, faults: int) -> int:
        """After a beam break: aim at the predicted SMR position and search (each step logged); every failed
        search uses one of the point's retries (then PointFailed names it). Returns the updated fault count."""
        reacquire = getattr(self.tracker, "reacquire", None)
        if not callable(reacquire) or not getattr(self.tracker, "can_reacquire", True) \
                or self.predict_p_tracker_mm is None or self.q_read is None or self._smr != 1:
            self.clock.sleep(min(2.0, 0.2 * 2 ** (faults - 1)))
            return faults
        p = np.asarray(self.predict_p_tracker_mm(self.q_read), float)
        log.append_event({"type": "reacquire", "point_id": point.point_id, "step": "predicted",
                          "p_tracker_mm": [round(float(v), 3) for v in p], "t_s": self.clock.now()})
        while True:                                 # search again until found or the point's retries are spent
            try:
                reacquire(p.tolist())
                break
            except TrackerError as exc:
                faults += 1
                self._fault(point, log, exc, faults)
                self.clock.sleep(min(2.0, 0.2 * 2 ** (faults - 1)))
        self._log_tracker_steps(point, log)
        log.append_event({"type": "reacquire", "point_id": point.point_id, "step": "found", "t_s": self.clock.now()})
        return faults

    def _log_tracker_steps(self, point: PlanPoint, log: RunLog) -> None:
        """The driver's own recovery steps (reconnect, initialise, aim, search), if it reports them."""
        drain = getattr(self.tracker, "drain_events", None)
        for step in (drain() if callable(drain) else ()):
            log.append_event({"type": "tracker_step", "point_id": point.point_id, **step, "t_s": self.clock.now()})


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


def close_log(log: RunLog, status: str, reason: str) -> None:
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
        close_log(log, "fail" if isinstance(exc, Exception) else "abort", f"{type(exc).__name__}: {_one_line(exc)}")
        raise


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split())


def pending(points: Iterable[PlanPoint], done_ids: set[str]) -> list[PlanPoint]:
    """Plan points not yet in the log."""
    return [p for p in points if p.point_id not in done_ids]


def start_record(config: Mapping, config_sha256: str, plan_sha256: str, software_version: str,
                 created_utc: str) -> dict:
    return {"config_sha256": config_sha256, "plan_sha256": plan_sha256, "config": dict(config),
            "created_utc": created_utc, "software_version": software_version,
            "units": {"q": "deg (controller)", "p_tracker": "mm, tracker frame", "cov": "mm^2", "t": "s"}}
