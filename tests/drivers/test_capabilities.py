"""The optional driver capabilities (``drivers.base`` Protocols): each is recognised on the real drivers, the
simulated ones and the test doubles that have it, and on none that lack it; the retry back-off."""
import pytest

from drivers.base import (DrainsEvents, EnforcesMotionLimits, Identifies, ReacquireSwitch, Reacquires,
                          ReadsJointTemperatures, ReadsSpeedOverride, SelectsNest, SelectsSmr, Simulated,
                          TakesPayload, backoff_s, can_reacquire)
from drivers.line_profile import LineProfile
from drivers.line_tracker import LineTracker
from drivers.registry import CellContext, open_robot, open_tracker
from tests.campaign.run.test_devices import _world_builder
from tests.campaign.run.test_runner_lifecycle import Robot as StubRobot, Tracker as StubTracker

pytestmark = pytest.mark.unit
CAPABILITIES = (EnforcesMotionLimits, TakesPayload, ReadsSpeedOverride, ReadsJointTemperatures, Identifies,
                Simulated, Reacquires, ReacquireSwitch, SelectsSmr, SelectsNest, DrainsEvents)


def _line_tracker(**options) -> LineTracker:
    return LineTracker("tracker+loop://", LineProfile.from_options({"init": [], "environment": None, "timeout_s": 0.2,
                                                                    **options}))


def _devices() -> dict:
    """Every driver (not connected) and test double, by name."""
    cell = CellContext(n_joints=6, simulation=_world_builder([]))
    mock_robot = open_robot("mock://", {}, cell)
    return {"abb-rws": open_robot("abb-rws://127.0.0.1:1", {"credentials": {"use_default": True}}),
            "ur-rtde": open_robot("ur-rtde://127.0.0.1", {}),
            "mock robot": mock_robot, "mock tracker": open_tracker("mock://", {}, cell, mock_robot),
            "emscon": open_tracker("emscon://127.0.0.1:1", {}), "line": _line_tracker(),
            "line goto/find": _line_tracker(goto="GOTO {x} {y} {z}", find="FIND"),
            "stub robot": StubRobot(), "stub tracker": StubTracker()}


HAS = {   # device -> the capabilities it offers (every other one it must not claim)
    "abb-rws": {EnforcesMotionLimits, TakesPayload, ReadsSpeedOverride, Identifies},
    "ur-rtde": {EnforcesMotionLimits, TakesPayload, ReadsSpeedOverride, Identifies},
    "mock robot": {EnforcesMotionLimits, TakesPayload, ReadsSpeedOverride, Identifies, Simulated},
    "mock tracker": {Identifies, Simulated, SelectsSmr, SelectsNest},
    "emscon": {Identifies, Reacquires, DrainsEvents},
    "line": {Reacquires, ReacquireSwitch},
    "line goto/find": {Reacquires, ReacquireSwitch},
    "stub robot": {EnforcesMotionLimits, TakesPayload, ReadsSpeedOverride, Identifies, ReadsJointTemperatures},
    "stub tracker": {Identifies},
}


def test_each_capability_is_recognised_exactly_where_the_driver_has_it():
    devices = _devices()
    try:
        got = {name: {c for c in CAPABILITIES if isinstance(dev, c)} for name, dev in devices.items()}
    finally:
        for dev in devices.values():
            dev.close()
    assert {name: {c.__name__ for c in caps} for name, caps in got.items()} == \
        {name: {c.__name__ for c in caps} for name, caps in HAS.items()}


def test_reacquisition_needs_the_method_and_a_device_that_can_aim():
    assert can_reacquire(_line_tracker(goto="GOTO {x} {y} {z}", find="FIND"))
    assert not can_reacquire(_line_tracker())                 # the method is there, the profile cannot aim
    assert not can_reacquire(StubTracker())

    class Emscon:                                             # reacquire without the switch: always can
        def reacquire(self, p): ...
    assert can_reacquire(Emscon())


def test_backoff_doubles_from_0_2_s_and_stops_at_2_s():
    assert [backoff_s(k) for k in (1, 2, 3, 4, 5, 6)] == pytest.approx([0.2, 0.4, 0.8, 1.6, 2.0, 2.0])
