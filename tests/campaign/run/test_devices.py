"""open_devices / CellContext: mock drivers build and share their world; real factories get only what they use."""
import pytest

import drivers.registry as registry
from drivers.base import SystemClock
from drivers.mock import MockRobot, MockTracker, VirtualClock
from drivers.registry import CellContext, open_robot, open_tracker


def _world_builder(calls):
    from tests.cells import irb2600
    from drivers.mock import MockWorld
    from robocal.measure.noise import TrackerUncertainty
    from robocal.simulation.mock_cell import SimulatedCell

    def build():
        calls.append(1)
        return MockWorld(SimulatedCell(irb2600(), (), TrackerUncertainty(), 0.0))
    return build


@pytest.mark.unit
def test_mock_pair_shares_one_world_built_once():
    calls = []
    cell = CellContext(n_joints=6, simulation=_world_builder(calls))
    robot = open_robot("mock://", {}, cell)
    tracker = open_tracker("mock://", {}, cell, robot)
    assert isinstance(robot, MockRobot) and isinstance(tracker, MockTracker)
    assert tracker.world is robot.world and len(calls) == 1
    assert isinstance(robot.simulated_clock, VirtualClock) and tracker.simulated_clock is robot.simulated_clock


@pytest.mark.unit
def test_real_factories_receive_only_what_they_use(monkeypatch):
    got = {}

    def fake(url, options, **context):
        got[url] = context
        return object()
    monkeypatch.setattr(registry, "_factory", lambda table, url, what: fake)
    cell = CellContext(n_joints=6, simulation=lambda: pytest.fail("a real driver built the simulated world"))
    robot = open_robot("abb-rws://r", {}, cell)
    open_tracker("emscon://t", {}, cell, robot)
    assert got == {"abb-rws://r": {"n_joints": 6}, "emscon://t": {"clock": None}}


@pytest.mark.unit
def test_mock_without_simulation_is_a_driver_error():
    from drivers.base import DriverError
    with pytest.raises(DriverError, match="simulated cell"):
        open_robot("mock://", {}, CellContext(n_joints=6))


@pytest.mark.unit
def test_open_devices_closes_both_devices_on_error(monkeypatch):
    from campaign.run import devices
    closed = []

    class Dev:
        def __init__(self, name):
            self.name = name

        def connect(self):
            pass

        def close(self):
            closed.append(self.name)
    monkeypatch.setattr(devices, "open_robot", lambda url, opts, ctx: Dev("robot"))
    monkeypatch.setattr(devices, "open_tracker", lambda url, opts, ctx, robot: Dev("tracker"))

    class Cfg:                                              # the config fields open_devices reads
        class robot:
            joints, url, options, track = [None] * 6, "x://", {}, None

        class tracker:
            url, options = "y://", {}

            class measurement:
                timeout_s = 1.0

    class Cell:                                             # the cell model of that config
        config = Cfg
    with pytest.raises(RuntimeError):
        with devices.open_devices(Cell) as cell:
            assert isinstance(cell.clock, SystemClock)
            raise RuntimeError("boom")
    assert closed == ["tracker", "robot"]
