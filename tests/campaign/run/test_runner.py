"""Runner behaviour with stub devices: retries, pause, Ctrl-C, stop on driver failure."""
import numpy as np

from campaign.config.schema import MeasurementConfig
from campaign.plan.points import PlanPoint
from campaign.run.log_writer import RunLog
from campaign.run.log_reader import read_log
from campaign.run.runner import Runner
from drivers.base import BeamBroken, MotionError, TrackerReading
from drivers.mock import VirtualClock

import pytest

pytestmark = pytest.mark.unit


class StubRobot:
    n_joints = 6

    def __init__(self, fail_at=None):
        self.q, self.moves, self.stops, self.fail_at = (0.0,) * 6, 0, 0, fail_at

    def connect(self): pass

    def move_joints(self, q):
        self.moves += 1
        if self.fail_at == self.moves:
            raise MotionError("stub: motors off")
        self.q = tuple(q)

    def read_joints(self): return self.q

    def stop(self): self.stops += 1

    def close(self): pass


class StubTracker:
    def __init__(self, script=()):
        self.script, self.calls = list(script), 0

    def connect(self): pass

    def measure(self):
        self.calls += 1
        action = self.script.pop(0) if self.script else "ok"
        if action == "beam":
            raise BeamBroken("stub: beam broken")
        if action == "ctrl-c":
            raise KeyboardInterrupt
        return TrackerReading((1000.0 + 0.001 * self.calls, 0.0, 0.0), 0.0)

    def environment(self): return {}

    def close(self): pass


M = MeasurementConfig(samples=2, stability_mm=0.05, settle_s=0.0, timeout_s=1.0, retries=2)
POINTS = [PlanPoint(f"P{i}", "calib", (float(i),) * 6, (0.0, 0.0, 0.0)) for i in range(6)]


def run(tmp_path, robot, tracker):
    log = RunLog.create(tmp_path / "run", {"config_sha256": "x", "plan_sha256": "y"})
    outcome = Runner(robot, tracker, M, VirtualClock(), lambda p: np.eye(3) * 1e-4).execute(POINTS, log)
    return outcome, read_log(tmp_path / "run")


def test_transient_beam_break_is_retried(tmp_path):
    outcome, log = run(tmp_path, StubRobot(), StubTracker(["ok", "ok", "beam", "ok"]))
    assert outcome.exit_status == "success" and len(log.points) == 6
    assert log.points[1]["retries"] == 1
    assert [e["kind"] for e in log.events if e["type"] == "tracker_fault"] == ["beam_broken"]


def test_persistent_fault_pauses_without_losing_or_faking_points(tmp_path):
    outcome, log = run(tmp_path, StubRobot(), StubTracker(["ok"] * 4 + ["beam"] * 3))
    assert outcome.exit_status == "paused" and "P2" in outcome.reason and "beam_broken" in outcome.reason
    assert [p["point_id"] for p in log.points] == ["P0", "P1"]
    assert log.stops[-1]["exit_status"] == "paused"
    # resume on the same log with a healthy tracker finishes the remaining points
    resumed = RunLog.open_for_resume(tmp_path / "run")
    done = {p["point_id"] for p in resumed.contents.points}
    rest = [p for p in POINTS if p.point_id not in done]
    out2 = Runner(StubRobot(), StubTracker(), M, VirtualClock(), lambda p: np.eye(3)).execute(rest, resumed)
    assert out2.exit_status == "success"
    assert sorted(p["point_id"] for p in read_log(tmp_path / "run").points) == [p.point_id for p in POINTS]


def test_ctrl_c_stops_the_robot_and_closes_the_log(tmp_path):
    robot = StubRobot()
    outcome, log = run(tmp_path, robot, StubTracker(["ok"] * 6 + ["ctrl-c"]))
    assert outcome.exit_status == "abort" and robot.stops == 1
    assert len(log.points) == 3 and log.stops[-1]["exit_status"] == "abort" and not log.torn_tail


def test_robot_failure_stops_and_records_the_reason(tmp_path):
    robot = StubRobot(fail_at=4)
    outcome, log = run(tmp_path, robot, StubTracker())
    assert outcome.exit_status == "fail" and "motors off" in outcome.reason and robot.stops == 1
    assert len(log.points) == 3


def test_unstable_readings_are_rejected(tmp_path):
    class Drifting(StubTracker):
        def measure(self):
            self.calls += 1
            return TrackerReading((1000.0 + 0.1 * self.calls, 0.0, 0.0), 0.0)
    outcome, log = run(tmp_path, StubRobot(), Drifting())
    assert outcome.exit_status == "paused" and "unstable" in outcome.reason and not log.points
