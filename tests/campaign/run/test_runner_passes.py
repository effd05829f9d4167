"""Runner.execute_passes: each pass decided by the previous pass's readings, one stop record, robot stopped once."""
import numpy as np
import pytest

from campaign.plan.points import PlanPoint
from campaign.run.log_writer import RunLog
from campaign.run.log_reader import read_log
from campaign.run.runner import Runner, closing_on_error
from drivers.mock import VirtualClock
from tests.campaign.run.test_runner import M, StubRobot, StubTracker

pytestmark = pytest.mark.unit


class TwoPasses:
    """Pass 2 commands joints derived from pass 1's readings (the plan sees what was measured)."""

    def __init__(self):
        self.seen = []

    def first(self):
        return [PlanPoint(f"T{i}.v0", "verify", (float(i),) * 6, (0.0, 0.0, 0.0)) for i in range(3)]

    def next(self, p_tracker_mm):
        self.seen.append(np.asarray(p_tracker_mm))
        if len(self.seen) == 2:
            return None
        return [PlanPoint(f"T{i}.v1", "verify", (float(i) + p[0] / 1000.0,) * 6, (0.0, 0.0, 0.0))
                for i, p in enumerate(p_tracker_mm)]


def _log(tmp_path):
    return RunLog.create(tmp_path / "v", {"config_sha256": "x", "plan_sha256": "verify"})


def test_passes_follow_the_readings_and_close_once(tmp_path):
    robot, plan = StubRobot(), TwoPasses()
    outcome = Runner(robot, StubTracker(), M, VirtualClock(), lambda p: np.eye(3) * 1e-4).execute_passes(
        plan, _log(tmp_path))
    contents = read_log(tmp_path / "v")
    assert (outcome.exit_status, outcome.n_measured) == ("success", 6)
    assert [p.shape for p in plan.seen] == [(3, 3), (3, 3)]
    assert np.allclose(contents.points[4]["q_cmd_deg"], 1.0 + plan.seen[0][1][0] / 1000.0)
    assert [s["exit_status"] for s in contents.stops] == ["success"] and robot.stops == 1


def test_failure_in_a_later_pass_closes_with_its_reason(tmp_path):
    robot = StubRobot(fail_at=5)                              # the second move of pass 2
    outcome = Runner(robot, StubTracker(), M, VirtualClock(), lambda p: np.eye(3)).execute_passes(
        TwoPasses(), _log(tmp_path))
    contents = read_log(tmp_path / "v")
    assert outcome.exit_status == "fail" and "motors off" in outcome.reason
    assert len(contents.points) == 4 and [s["reason"] for s in contents.stops] == [outcome.reason]


def test_closing_on_error_writes_the_stop_record_with_the_reason(tmp_path):
    log = _log(tmp_path)
    with pytest.raises(OSError):
        with closing_on_error(log):
            raise OSError("disk gone")
    assert log.closed
    assert read_log(tmp_path / "v").stops[-1]["reason"] == "OSError: disk gone"
