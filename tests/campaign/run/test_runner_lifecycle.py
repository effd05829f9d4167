"""Runner lifecycle under fault injection: every exception type at every step stops the robot exactly once and
leaves the log ending with a stop record (15 exception types x 5 steps); caps, payload and override reach the driver before the first move."""
import json

import numpy as np
import pytest

from campaign.config.schema import MeasurementConfig
from campaign.plan.motion_safety import UnsafeMotion
from campaign.plan.points import PlanPoint
from campaign.run.log_writer import RunLog
from campaign.run.log_reader import RunLogError, read_log
from campaign.run.runner import Runner
from drivers.base import (BeamBroken, ConnectionLost, DriverError, MotionError, MotionLimits, Payload, RobotError,
                          RobotNotReady, TrackerReading, TrackerTimeout)
from drivers.mock import VirtualClock

M = MeasurementConfig(samples=2, stability_mm=0.05, settle_s=0.1, timeout_s=1.0, retries=2)
POINTS = [PlanPoint(f"P{i}", "calib", (float(i),) * 6, (0.0, 0.0, 0.0)) for i in range(4)]


class Boom:
    """Raise ``exc`` on call number ``at`` of the wrapped step."""

    def __init__(self, exc, at):
        self.exc, self.at, self.calls = exc, at, 0

    def tick(self):
        self.calls += 1
        if self.calls == self.at:
            raise self.exc


class Robot:
    n_joints = 6

    def __init__(self, boom=None):
        self.q, self.calls, self.boom = (0.0,) * 6, [], boom

    def connect(self): pass

    def set_motion_limits(self, limits): self.calls.append(("limits", limits))

    def set_payload(self, payload): self.calls.append(("payload", payload))

    def speed_override_pct(self): return 75.0

    def identity(self):
        return {"vendor": "stub", "model": "R", "controller_type": "C", "serial": "S1", "software_version": "7.1"}

    def joint_temperatures_c(self): return [30.0 + i for i in range(6)]

    def move_joints(self, q):
        self.calls.append(("move", tuple(q)))
        if self.boom:
            self.boom.tick()
        self.q = tuple(q)

    def read_joints(self): return self.q

    def stop(self): self.calls.append(("stop",))

    def close(self): pass

    @property
    def stops(self):
        return sum(c[0] == "stop" for c in self.calls)


class Tracker:
    def __init__(self, boom=None):
        self.boom, self.n = boom, 0

    def connect(self): pass

    def measure(self):
        self.n += 1
        if self.boom:
            self.boom.tick()
        return TrackerReading((1000.0 + 1e-4 * self.n, 0.0, 0.0), 0.0,
                              {"temp_c": 20.5, "pressure_hpa": 1012.0, "humidity_pct": 40.0})

    def environment(self): return {}

    def identity(self): return {"vendor": "stub", "model": "T", "serial": "T9", "firmware": "3.2"}

    def close(self): pass


class Clock(VirtualClock):
    def __init__(self, boom=None):
        super().__init__()
        self.boom = boom

    def sleep(self, seconds):
        if self.boom:
            self.boom.tick()
        super().sleep(seconds)


class Terminated(KeyboardInterrupt):
    """A signal turned into an exception with its reason (as the CLI does for SIGTERM / SIGHUP)."""


EXCEPTIONS = [Terminated("terminated by SIGTERM"), Exception("bug"), RuntimeError("bug"), OSError(28, "No space left on device"), KeyboardInterrupt(),
              SystemExit(3), DriverError("drv"), ConnectionLost("link down"), RobotError("refused"),
              RobotNotReady("motors off"), MotionError("limit"), BeamBroken("beam"), TrackerTimeout("no reply"),
              RunLogError("log.jsonl", "record not storable"), UnsafeMotion("would enter keep-out box")]
STEPS = ["move", "settle", "measure", "log_append", "progress"]


def _runner(step, exc, tmp_path):
    boom = Boom(exc, at=3)
    robot = Robot(boom if step == "move" else None)
    tracker = Tracker(boom if step == "measure" else None)
    clock = Clock(boom if step == "settle" else None)
    log = RunLog.create(tmp_path / "run", {"config_sha256": "x", "plan_sha256": "y"})
    if step == "log_append":
        real = log.append_point

        def append_point(record):
            boom.tick()
            return real(record)
        log.append_point = append_point
    runner = Runner(robot, tracker, M, clock, lambda p: np.eye(3) * 1e-4)
    runner.limits, runner.payload = MotionLimits(200.0, 50.0), Payload(2.5, (0.0, 0.0, 60.0))
    if step == "progress":
        runner.on_point = lambda point, record: boom.tick()
    return runner, robot, log


@pytest.mark.unit
@pytest.mark.parametrize("step", STEPS)
@pytest.mark.parametrize("exc", EXCEPTIONS, ids=lambda e: type(e).__name__)
def test_every_fault_at_every_step_stops_once_and_closes_the_log(tmp_path, step, exc):
    runner, robot, log = _runner(step, exc, tmp_path)
    reraised = (isinstance(exc, (Exception, SystemExit))
                and not isinstance(exc, (OSError, DriverError, RunLogError, UnsafeMotion))
                and not isinstance(exc, KeyboardInterrupt))
    if reraised:
        with pytest.raises(type(exc)):
            runner.execute(POINTS, log)
        status = "fail" if isinstance(exc, Exception) else "abort"
    else:
        outcome = runner.execute(POINTS, log)
        status = outcome.exit_status
    assert robot.stops == 1, robot.calls
    assert robot.calls[-1] == ("stop",)                      # nothing commanded after the stop
    last = json.loads((tmp_path / "run" / "log.jsonl").read_text().splitlines()[-1])
    assert last["kind"] == "stop" and last["data"]["exit_status"] == status and log.closed
    if isinstance(exc, Terminated):
        assert last["data"]["reason"] == "terminated by SIGTERM"
    contents = read_log(tmp_path / "run")
    tracker_retry = step == "measure" and isinstance(exc, (BeamBroken, TrackerTimeout))
    if tracker_retry:                                        # retried within limits: the run completes
        assert status == "success" and len(contents.points) == len(POINTS)
    else:
        assert status != "success" and last["data"]["reason"]
        assert len(contents.points) < len(POINTS)


@pytest.mark.unit
def test_caps_payload_and_override_precede_the_first_move_and_are_logged(tmp_path):
    runner, robot, log = _runner("none", None, tmp_path)
    assert runner.execute(POINTS, log).exit_status == "success"
    kinds = [c[0] for c in robot.calls]
    assert kinds.index("limits") < kinds.index("move") and kinds.index("payload") < kinds.index("move")
    assert robot.calls[0] == ("limits", MotionLimits(200.0, 50.0))
    contents = read_log(tmp_path / "run")
    dev = [e for e in contents.events if e["type"] == "devices"][0]
    assert dev["speed_override_pct"] == 75.0 and dev["motion_limits"]["max_tcp_speed_mm_s"] == 200.0
    assert dev["robot_identity"]["serial"] == "S1" and dev["tracker_identity"]["firmware"] == "3.2"
    p = contents.points[0]
    assert p["payload_kg"] == 2.5 and p["payload_cog_flange_mm"] == [0.0, 0.0, 60.0]
    assert p["temperatures"] == {"temp_c": 20.5, "pressure_hpa": 1012.0, "humidity_pct": 40.0}
    assert p["joint_temp_c"] == [30.0, 31.0, 32.0, 33.0, 34.0, 35.0]


@pytest.mark.unit
def test_a_driver_that_cannot_enforce_the_caps_is_refused_before_moving(tmp_path):
    class NoCaps(Robot):
        set_motion_limits = None
    robot = NoCaps()
    log = RunLog.create(tmp_path / "run", {"config_sha256": "x", "plan_sha256": "y"})
    runner = Runner(robot, Tracker(), M, VirtualClock(), lambda p: np.eye(3) * 1e-4)
    runner.limits = MotionLimits()
    outcome = runner.execute(POINTS, log)
    assert outcome.exit_status == "fail" and "cannot enforce the speed caps" in outcome.reason
    assert not [c for c in robot.calls if c[0] == "move"] and robot.stops == 1
    assert read_log(tmp_path / "run").stops[-1]["exit_status"] == "fail"
