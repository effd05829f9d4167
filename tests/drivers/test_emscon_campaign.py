"""The emScon tracker in a campaign: a whole ``campaign run`` against the emulator (robot mock) compared with the
mock tracker, and every tracker fault through the runner, each ending measured or paused with the reason, bounded
in time, losing no point.

The emulator measures the same simulated cell the mock robot moves (``campaign.run.devices.mock_world`` is pointed at
one shared world), so its readings are the cell's SMR + the cell's per-point tracker error + the emulator's own noise.
"""
from __future__ import annotations

import dataclasses
import time

import numpy as np
import pytest

from campaign.run import devices
from campaign.cli import main
from campaign.config.load import load_cell
from campaign.data.log_dataset import dataset_from_log
from campaign.plan.build import build_plan
from campaign.run.log_writer import RunLog
from campaign.run.log_reader import read_log
from campaign.run.runner import Runner
from campaign.run.tracker_quality import SmrPredictor
from drivers.emscon import open_tracker
from drivers.emulators.emscon_server import EmsconEmulator
from drivers.mock import MockRobot
from tests.campaign.helpers import read_report, small_config

SMALL = {"plan.grid.step_mm": 600, "plan.test.count": 8, "plan.check_poses": {"count": 0, "every_n_points": 50},
         "tracker.measurement.samples": 2, "tracker.measurement.settle_s": 0.0, "calibration.residual": "none"}
FAST = {"timeout_s": 0.3, "meas_time_ms": 10}


def _world(cell):
    world = devices.mock_world(cell)
    world.faults = {}
    return world


def _smr(world):
    return lambda: world.p_smr_tracker_mm + world.point_error_mm


@pytest.mark.system
def test_campaign_run_with_emscon_matches_the_mock_tracker(tmp_path, monkeypatch):
    cfg_mock = small_config(tmp_path, **SMALL)
    assert main(["run", str(cfg_mock), "--out", str(tmp_path / "mock")]) == 0
    world = _world(load_cell(cfg_mock))
    monkeypatch.setattr(devices, "mock_world", lambda cell: world)
    with EmsconEmulator(_smr(world), seed=5) as emu:
        cfg = small_config(tmp_path, **SMALL, **{"tracker.url": emu.url, "tracker.options": {"meas_time_ms": 10}})
        assert main(["run", str(cfg), "--out", str(tmp_path / "emscon")]) == 0
    mock, emscon = read_log(tmp_path / "mock"), read_log(tmp_path / "emscon")
    assert emscon.stops[-1]["exit_status"] == "success" and len(emscon.points) >= 20
    assert [p["point_id"] for p in emscon.points] == [p["point_id"] for p in mock.points]
    p_mock = np.array([p["p_tracker_mm"] for p in mock.points])
    p_emscon = np.array([p["p_tracker_mm"] for p in emscon.points])
    diff = np.linalg.norm(p_emscon - p_mock, axis=1)
    r_mock, r_emscon = read_report(tmp_path / "mock"), read_report(tmp_path / "emscon")
    floor = r_mock.noise_floor_mm
    rms_mock = r_mock.stages["kinematic"].test.rms_mm
    rms_emscon = r_emscon.stages["kinematic"].test.rms_mm
    print(f"\nper-point |emscon - mock| median {np.median(diff):.4f} max {diff.max():.4f} mm; test RMS kinematic "
          f"mock {rms_mock:.4f} emscon {rms_emscon:.4f} mm; noise floor {floor:.4f} mm")
    assert diff.max() < 3 * floor                     # same cell, independent noise draws
    assert abs(rms_emscon - rms_mock) < floor and rms_emscon < 3 * floor
    assert r_emscon.method.measurement_covariance == "device"
    assert r_mock.method.measurement_covariance == "spec"
    for record in emscon.points:                       # device statistics and environment in every point record
        assert record["cov_source"] == "device" and all(0 < s < 0.05 for s in record["device_std_mm"])
        assert record["temperatures"] == {"temp_c": 20.5, "pressure_hpa": 1008.0, "humidity_pct": 42.0}
    assert dataset_from_log(emscon).cov_mm2 is not None and dataset_from_log(mock).cov_mm2 is None


# --------------------------------------------------------------------------------------- faults through the runner

class FaultAt:
    """A mock robot that injects emulator faults when it reaches the ``at``-th point (1-based)."""

    def __init__(self, robot: MockRobot, emulator: EmsconEmulator, at: int, faults: tuple[str, ...]) -> None:
        self.robot, self.emulator, self.at, self.faults, self.moves = robot, emulator, at, faults, 0
        self.n_joints = robot.n_joints

    def move_joints(self, q_deg):
        self.robot.move_joints(q_deg)
        self.moves += 1
        if self.moves == self.at:
            self.emulator.inject(*self.faults)

    def __getattr__(self, name):
        return getattr(self.robot, name)


@pytest.fixture(scope="module")
def cell(tmp_path_factory):
    """The small config's cell model and the first 7 points of its plan (built once: planning solves IK)."""
    model = load_cell(small_config(tmp_path_factory.mktemp("cell"), **SMALL))
    return model, build_plan(model).points[:7]


def _run(tmp_path, cell, faults, *, at=4, retries=3, predictor=True, late_s=1.0):
    model, points = cell
    cfg = model.config
    world = _world(model)
    measurement = dataclasses.replace(cfg.tracker.measurement, retries=retries)
    with EmsconEmulator(_smr(world), seed=2, late_s=late_s) as emu:
        robot = FaultAt(MockRobot(world), emu, at, faults)
        tracker = open_tracker(emu.url, FAST)
        tracker.connect()
        log = RunLog.create(tmp_path / "run", {"config_sha256": "test", "plan_sha256": "test"})
        predict = SmrPredictor(model.kinematics, cfg.tracker.position_in_base_mm) if predictor else None
        runner = Runner(robot, tracker, measurement, world.clock, lambda p: model.covariance(p[None])[0],
                        predict_p_tracker_mm=predict, covariance_from_device=model.device_covariance)
        if predict is not None:
            runner.on_point = lambda point, record: predict.observe(record.q_read_deg, record.p_tracker_mm)
        t0 = time.monotonic()
        outcome = runner.execute(points, log)
        elapsed = time.monotonic() - t0
        tracker.close()
        stale = tracker.stale_discarded
    contents = read_log(tmp_path / "run")
    truth_ok = all(np.isfinite(r["p_tracker_mm"]).all() for r in contents.points)
    return outcome, contents, elapsed, points, stale, truth_ok


def _steps(contents, point_id):
    return [(e.get("type"), e.get("step") or e.get("kind")) for e in contents.events if e.get("point_id") == point_id]


@pytest.mark.system
def test_beam_break_mid_point_is_reacquired_and_measured(tmp_path, cell):
    outcome, contents, elapsed, points, _, _ = _run(tmp_path, cell, ("beam_break",))
    assert outcome.exit_status == "success" and elapsed < 10.0
    assert [r["point_id"] for r in contents.points] == [p.point_id for p in points]
    pid = points[3].point_id
    assert _steps(contents, pid) == [("tracker_fault", "beam_broken"), ("reacquire", "predicted"),
                                     ("tracker_step", "go_position"), ("tracker_step", "find_reflector"),
                                     ("tracker_step", "reacquired"), ("reacquire", "found")]
    record = next(r for r in contents.points if r["point_id"] == pid)
    assert record["retries"] == 1 and record["cov_source"] == "device"


@pytest.mark.system
def test_beam_break_without_a_prediction_is_not_recovered(tmp_path, cell):
    """Control: the tracker stays pointed at the previous point (> search radius away), so only aiming recovers."""
    outcome, contents, elapsed, points, _, _ = _run(tmp_path, cell, ("beam_break",), predictor=False)
    assert outcome.exit_status == "paused" and "beam_broken" in outcome.reason and elapsed < 10.0
    assert len(contents.points) == 3


@pytest.mark.system
def test_reflector_lost_for_good_pauses_with_the_reason(tmp_path, cell):
    outcome, contents, elapsed, points, _, _ = _run(tmp_path, cell, ("lost_reflector",), retries=2)
    assert outcome.exit_status == "paused" and elapsed < 10.0
    assert f"point {points[3].point_id}" in outcome.reason and "not_found" in outcome.reason
    assert "reflector not found near the predicted position" in outcome.reason
    assert contents.stops[-1]["exit_status"] == "paused" and contents.stops[-1]["reason"] == outcome.reason
    assert [r["point_id"] for r in contents.points] == [p.point_id for p in points[:3]]     # nothing lost


@pytest.mark.system
@pytest.mark.parametrize("faults, step", [(("garbage",), "reconnect"), (("disconnect",), "reconnect"),
                                          (("not_initialised",), "initialize"), (("late",), None),
                                          (("garbage", "disconnect", "not_initialised", "warm_up"), "reconnect")])
def test_recoverable_faults_lose_no_point(tmp_path, cell, faults, step):
    outcome, contents, elapsed, points, stale, truth_ok = _run(tmp_path, cell, faults, late_s=0.45)
    assert outcome.exit_status == "success" and elapsed < 15.0 and truth_ok
    assert [r["point_id"] for r in contents.points] == [p.point_id for p in points]
    kinds = [k for t, k in _steps(contents, points[3].point_id)]
    if step is not None:
        assert step in kinds
    if faults == ("late",):
        assert "timeout" in kinds and stale == 1
