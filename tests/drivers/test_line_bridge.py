"""The reference bridge (drivers/bridge/line_bridge.py) with its CSV replay back end against the line-protocol driver.

The driver-vs-emulator tests of tests/drivers/test_line_tracker.py are run here unchanged, with the emulator replaced by
the bridge replaying a CSV of the readings the emulator would have produced (same points, std devs, environment,
same fault hooks). Only the spherical-mode test is left out: the bridge contract is Cartesian xyz.
"""
from __future__ import annotations

import csv
import random
import shutil

import numpy as np
import pytest

from drivers.base import TargetNotFound, TrackerError
from drivers.bridge.line_bridge import (BackendError, FaroSdkBackend, LineBridge, Measurement, ReplayBackend,
                                        SpatialAnalyzerBackend)
from drivers.emulators.line_tracker_server import DEFAULT_POINT_MM
from drivers.line_tracker import open_tracker
from tests.drivers import test_line_tracker as contract
from tests.drivers.helpers import REPO, served_port
from tests.drivers.test_line_tracker import (no_leftover_threads, test_connection_refused_is_connection_lost,
                                             test_emulator_disconnect_is_connection_lost_and_reconnect_works,
                                             test_emulator_dropped_reply_is_retried,
                                             test_emulator_dropped_reply_times_out_within_the_timeout,
                                             test_emulator_faults_map_to_errors_and_recover,
                                             test_emulator_late_reply_already_arrived_is_flushed,
                                             test_emulator_late_reply_in_flight_is_dropped_by_seq,
                                             test_emulator_late_reply_without_flush_is_dropped_by_seq,
                                             test_emulator_position_source_and_environment,
                                             test_emulator_random_faults_are_seeded,
                                             test_emulator_readings_with_default_options)

pytestmark = pytest.mark.system
CONTRACT_TESTS = (test_connection_refused_is_connection_lost,
                  test_emulator_disconnect_is_connection_lost_and_reconnect_works,
                  test_emulator_dropped_reply_is_retried, test_emulator_dropped_reply_times_out_within_the_timeout,
                  test_emulator_faults_map_to_errors_and_recover, test_emulator_late_reply_already_arrived_is_flushed,
                  test_emulator_late_reply_in_flight_is_dropped_by_seq,
                  test_emulator_late_reply_without_flush_is_dropped_by_seq,
                  test_emulator_position_source_and_environment,
                  test_emulator_random_faults_are_seeded, test_emulator_readings_with_default_options)


def replay_rows(position_source=None, *, seed=0, noise_mm=0.002, std_mm=0.005, environment=(20.0, 1013.25, 45.0),
                n=200) -> list[dict[str, str]]:
    """CSV rows of the readings the sample emulator would produce (its defaults), as a recorded session."""
    rng = random.Random(seed)
    source = position_source or (lambda: tuple(c + rng.gauss(0.0, noise_mm) for c in DEFAULT_POINT_MM))
    rows = []
    for _ in range(n):
        x, y, z = source()
        rows.append({"x": repr(float(x)), "y": repr(float(y)), "z": repr(float(z)), "sx": str(std_mm),
                     "sy": str(std_mm), "sz": str(std_mm), "temp_c": str(environment[0]),
                     "pressure_hpa": str(environment[1]), "humidity_pct": str(environment[2])})
    return rows


class ReplayBridge(LineBridge):
    """The bridge + ReplayBackend, constructed like ``TrackerEmulator`` (the contract tests build it that way)."""

    def __init__(self, position_source=None, faults=None, port: int = 0, *, seed: int = 0, mode: str = "cartesian",
                 **recording) -> None:
        assert mode == "cartesian", "the bridge contract is Cartesian"
        probabilities = dict(faults or {})
        delay_s = probabilities.pop("delay_s", 0.5)
        super().__init__(ReplayBackend(replay_rows(position_source, seed=seed, **recording)), port, seed=seed,
                         probabilities=probabilities, delay_s=delay_s)
        self.device = self                 # the contract tests read emulator.device.requests


@pytest.fixture(autouse=True)
def bridge_instead_of_emulator(monkeypatch):
    monkeypatch.setattr(contract, "TrackerEmulator", ReplayBridge)


@pytest.fixture
def emulator():
    with ReplayBridge(seed=0) as bridge:
        yield bridge


def test_all_driver_facing_contract_tests_are_included():
    left_out = {name for name in dir(contract) if name.startswith("test_emulator_")} - {
        t.__name__ for t in CONTRACT_TESTS}
    assert left_out == {"test_emulator_spherical_mode", "test_emulator_fault_settings_are_validated",
                        "test_emulator_command_line_prints_port_and_stops_on_stdin_eof"}


# ------------------------------------------------------------------------------------------- bridge specifics

def test_replayed_errors_and_goto_find_through_the_driver(tmp_path):
    path = tmp_path / "session.csv"
    with path.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["x", "y", "z", "sx", "sy", "sz", "error"])
        w.writerow([1000.0, 0.0, 0.0, 0.004, 0.004, 0.004, ""])
        w.writerow(["", "", "", "", "", "", "beam_broken"])
        w.writerow([1000.5, 0.0, 0.0, 0.004, 0.004, 0.004, ""])
    backend = ReplayBackend.from_csv(str(path))
    options = {"timeout_s": 0.5, "environment": None, "goto": "GOTO {seq} {x:.4f} {y:.4f} {z:.4f}",
               "find": "FIND {seq}",
               "length_unit": "m", "measure_regex": r"^OK (?P<seq>\d+) (?P<x>{num}) (?P<y>{num}) (?P<z>{num})"
                                                    r"(?: (?P<sx>{num}) (?P<sy>{num}) (?P<sz>{num}))?$"}
    with LineBridge(backend) as bridge:
        with open_tracker(bridge.url, options) as tracker:
            assert tracker.can_reacquire
            assert tracker.measure().xyz_mm == pytest.approx((1e6, 0.0, 0.0))       # the bridge speaks m here
            with pytest.raises(TrackerError, match="beam_broken"):
                tracker.measure()
            tracker.reacquire((1500.0, -250.0, 20.0))                              # mm -> m on the wire
            assert backend.aim_mm == pytest.approx((1.5, -0.25, 0.02))
            assert [r.split()[0] for r in bridge.requests][-2:] == ["GOTO", "FIND"]


def test_find_failure_is_target_not_found():
    class Lost(ReplayBackend):
        def find(self):
            raise BackendError("no_target", "searched, nothing")
    with LineBridge(Lost([{"x": "1", "y": "2", "z": "3"}])) as bridge:
        with open_tracker(bridge.url, {"timeout_s": 0.5, "find": "FIND {seq}"}) as tracker:
            with pytest.raises(TargetNotFound, match="NO_TARGET"):
                tracker.reacquire((1.0, 2.0, 3.0))


def test_without_goto_find_the_driver_does_not_claim_reacquisition():
    with ReplayBridge() as bridge:
        with open_tracker(bridge.url, {"timeout_s": 0.5}) as tracker:
            assert not tracker.can_reacquire
            with pytest.raises(TrackerError, match="no goto/find"):
                tracker.reacquire((0.0, 0.0, 0.0))


def test_bad_replay_csv_is_a_one_line_error(tmp_path):
    path = tmp_path / "bad.csv"
    path.write_text("x,y,z\n1,2,3\n1,two,3\n")
    with pytest.raises(ValueError, match=r"bad.csv line 3 column 'y': not a number: 'two'"):
        ReplayBackend.from_csv(str(path))
    with pytest.raises(ValueError, match="no rows"):
        ReplayBackend([])


def test_untested_skeletons_refuse_to_run():
    for backend in (FaroSdkBackend("10.0.0.9"), SpatialAnalyzerBackend()):
        with pytest.raises(BackendError, match="untested skeleton"):
            backend.open()


def test_command_line_replays_a_csv(tmp_path):
    path = tmp_path / "session.csv"
    path.write_text("x,y,z\n1200.0,-300.0,150.0\n")
    with served_port("drivers.bridge.line_bridge", "--csv", str(path)) as (proc, port):
        with open_tracker(f"tracker+socket://127.0.0.1:{port}", {"timeout_s": 1.0, "environment": None}) as tracker:
            assert tracker.measure().xyz_mm == (1200.0, -300.0, 150.0)
        proc.stdin.close()
        assert proc.wait(5) == 0


def test_a_copied_drivers_folder_runs_without_site_packages(tmp_path):
    """The documented deployment: only the ``drivers/`` folder, copied to a PC, run with the standard library
    alone (``-S``: no site-packages, so neither numpy nor this installed project; ``-E``: no PYTHONPATH)."""
    shutil.copytree(REPO / "drivers", tmp_path / "drivers", ignore=shutil.ignore_patterns("__pycache__"))
    (tmp_path / "session.csv").write_text("x,y,z\n1200.0,-300.0,150.0\n")
    with served_port("drivers.bridge.line_bridge", "--csv", "session.csv", python_flags=("-S", "-E"),
                     cwd=tmp_path) as (proc, port):
        with open_tracker(f"tracker+socket://127.0.0.1:{port}", {"timeout_s": 1.0, "environment": None}) as tracker:
            assert tracker.measure().xyz_mm == (1200.0, -300.0, 150.0)
        proc.stdin.close()
        assert proc.wait(5) == 0


def test_measurement_record():
    assert Measurement((1.0, 2.0, 3.0)).std_mm is None


def test_runner_reacquires_through_the_line_protocol_after_a_beam_break(tmp_path):
    """Same reacquisition as emScon where the protocol allows: beam break -> GOTO predicted position -> FIND."""
    from campaign.config.load import load_cell
    from campaign.run.devices import mock_world
    from campaign.plan.build import build_plan
    from campaign.run.log_writer import RunLog
    from campaign.run.log_reader import read_log
    from campaign.run.runner import Runner
    from campaign.run.tracker_quality import SmrPredictor
    from drivers.mock import MockRobot
    from tests.campaign.helpers import small_config

    cell = load_cell(small_config(tmp_path, **{"plan.grid.step_mm": 600, "tracker.measurement.samples": 1}))
    cfg = cell.config
    world = mock_world(cell)
    world.faults = {}

    class CellBackend(ReplayBackend):
        def measure(self):
            return Measurement(tuple(world.p_smr_tracker_mm + world.point_error_mm))

    points = build_plan(cell).points[:5]
    backend = CellBackend([{"x": "0", "y": "0", "z": "0"}])
    with LineBridge(backend) as bridge:
        tracker = open_tracker(bridge.url, {"timeout_s": 0.5, "environment": None,
                                            "goto": "GOTO {seq} {x:.3f} {y:.3f} {z:.3f}", "find": "FIND {seq}"})
        tracker.connect()
        predict = SmrPredictor(cell.kinematics, cfg.tracker.position_in_base_mm)
        runner = Runner(MockRobot(world), tracker, cfg.tracker.measurement, world.clock,
                        lambda p: cell.covariance(p[None])[0], predict_p_tracker_mm=predict)
        runner.on_point = lambda point, record: (predict.observe(record.q_read_deg, record.p_tracker_mm),
                                                 bridge.inject("beam_break") if point is points[2] else None)
        outcome = runner.execute(points, RunLog.create(tmp_path / "run", {"config_sha256": "t", "plan_sha256": "t"}))
        tracker.close()
    assert outcome.exit_status == "success"
    contents = read_log(tmp_path / "run")
    pid = points[3].point_id
    steps = [(e["type"], e.get("step") or e.get("kind")) for e in contents.events if e.get("point_id") == pid]
    assert steps == [("tracker_fault", "beam_broken"), ("reacquire", "predicted"), ("reacquire", "found")]
    predicted = next(e["p_tracker_mm"] for e in contents.events if e.get("step") == "predicted")
    measured = next(r["p_tracker_mm"] for r in contents.points if r["point_id"] == points[3].point_id)
    assert backend.aim_mm == pytest.approx(predicted, abs=1e-3)                   # GOTO carried the prediction
    assert np.linalg.norm(np.subtract(predicted, measured)) < 10.0                # and it was close to the SMR
