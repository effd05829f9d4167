"""Controller overhead per point with instant devices, durable logging (write + fsync) included.

Two figures: with trivial instant stub devices (the controller alone: runner, averaging, covariance, log),
and with the simulator-backed mock drivers. Target: <= 2 ms per point for the controller.
"""
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from campaign.config.load import load_cell  # noqa: E402
from campaign.run.devices import mock_world  # noqa: E402
from campaign.plan.build import build_plan  # noqa: E402
from campaign.run.log_writer import RunLog  # noqa: E402
from campaign.run.runner import Runner  # noqa: E402
from drivers.base import TrackerReading  # noqa: E402
from drivers.mock import MockRobot, MockTracker, VirtualClock  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


class InstantRobot:
    n_joints = 6

    def __init__(self):
        self.q = (0.0,) * 6

    def connect(self): pass

    def move_joints(self, q): self.q = tuple(q)

    def read_joints(self): return self.q

    def stop(self): pass

    def close(self): pass


class InstantTracker:
    def connect(self): pass

    def measure(self): return TrackerReading((2000.0, 100.0, -300.0), 0.0)

    def environment(self): return {}

    def close(self): pass


def time_run(cell, plan, robot, tracker, clock) -> float:
    with tempfile.TemporaryDirectory() as tmp:
        cfg = cell.config
        log = RunLog.create(Path(tmp) / "run", {"config_sha256": cfg.sha256, "plan_sha256": plan.sha256})
        runner = Runner(robot, tracker, cfg.tracker.measurement, clock, lambda p: cell.covariance(p[None])[0])
        t0 = time.perf_counter()
        outcome = runner.execute(plan.points, log)
        dt = time.perf_counter() - t0
    assert outcome.exit_status == "success"
    return dt / len(plan.points)


def main(repeats: int = 5) -> None:
    cell = load_cell(ROOT / "configs/irb2600.yaml")
    plan = build_plan(cell)
    m = cell.config.tracker.measurement
    stub = [time_run(cell, plan, InstantRobot(), InstantTracker(), VirtualClock()) for _ in range(repeats)]
    mocks = []
    for _ in range(repeats):
        world = mock_world(cell)
        mocks.append(time_run(cell, plan, MockRobot(world), MockTracker(world), world.clock))
    print(f"{len(plan.points)} points, {m.samples} samples per point, fsync per record")
    print(f"controller overhead per point (instant stub devices): median {1e3 * np.median(stub):.3f} ms "
          f"(min {1e3 * np.min(stub):.3f}, max {1e3 * np.max(stub):.3f}); target <= 2 ms")
    print(f"per point with the simulator-backed mock drivers: median {1e3 * np.median(mocks):.3f} ms")


if __name__ == "__main__":
    main()
