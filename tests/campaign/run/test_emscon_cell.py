"""python -m campaign.run.emscon_cell: the emScon emulator measuring a config's simulated cell, at the plan's
q_ref or following a robot's read-back joints."""
from __future__ import annotations

import numpy as np
import pytest

from campaign.config.load import load_cell
from campaign.config.simulation import simulated_cell
from campaign.run.devices import mock_world
from drivers.emulators.rws_server import RwsEmulator
from drivers.registry import open_tracker
from robocal.kinematics.models import smr_tracker
from tests.campaign.helpers import small_config
from tests.drivers.helpers import served_port

FAST = {"timeout_s": 0.3, "meas_time_ms": 10}


@pytest.mark.system
def test_command_line_measures_the_simulated_smr(tmp_path):
    cfg_path = small_config(tmp_path)
    world = mock_world(load_cell(cfg_path))
    expected = world.p_smr_tracker_mm + world.point_error_mm
    with served_port("campaign.run.emscon_cell", str(cfg_path), wait_s=30) as (proc, port):
        with open_tracker(f"emscon://127.0.0.1:{port}", dict(FAST, timeout_s=2.0)) as tracker:
            r = tracker.measure()
        assert r.xyz_mm == pytest.approx(expected.tolist(), abs=0.05)
        proc.stdin.close()
        assert proc.wait(10) == 0


@pytest.mark.system
def test_command_line_follows_a_robot(tmp_path):
    """--robot-url: the emulator reads the robot's joints (here the RWS emulator) and measures the simulated
    SMR there."""
    with RwsEmulator(1) as rws:
        cfg_path = small_config(tmp_path, **{"robot.url": rws.url,
                                             "robot.options": {"credentials": {"use_default": True}}})
        truth = simulated_cell(load_cell(cfg_path)).truth
        with served_port("campaign.run.emscon_cell", str(cfg_path), "--robot-url", rws.url,
                         wait_s=30) as (proc, port):
            with open_tracker(f"emscon://127.0.0.1:{port}", dict(FAST, timeout_s=5.0)) as tracker:
                for q in ([10.0, 20.0, 10.0, 0.0, 30.0, 0.0], [-30.0, 5.0, -20.0, 40.0, -45.0, 90.0]):
                    rws.joints = list(q)
                    expected = smr_tracker(truth, np.radians(q)[None])[0]
                    assert np.linalg.norm(np.subtract(tracker.measure().xyz_mm, expected)) < 0.3
            proc.stdin.close()
            assert proc.wait(10) == 0
            assert rws.counts["logouts"] >= 1                        # the robot session was released
