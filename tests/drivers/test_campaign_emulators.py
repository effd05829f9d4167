"""`campaign run` end to end through the real protocols: a small plan (>= 20 points) against each emulator.

RWS 1.0 and 2.0 (the driver over HTTP Digest / Basic to the in-process RWS emulator), UR through the real
ur_rtde library to the RTDE emulator process, and the generic tracker over socket:// to the tracker emulator.
Where the tracker is mock://, it follows the emulated robot's read-back joints (simulated measurements).
"""

import numpy as np
import pytest

from campaign.cli import main
from campaign.config.load import load_cell
from campaign.run.devices import mock_world
from campaign.run.log_reader import read_log
from drivers.emulators.rtde_launch import start_emulator
from drivers.emulators.rws_server import RwsEmulator
from drivers.emulators.line_tracker_server import TrackerEmulator
from tests.campaign.helpers import read_report, small_config

pytestmark = pytest.mark.system

SMALL = {"plan.grid.step_mm": 600, "plan.test.count": 8, "plan.check_poses": {"count": 0, "every_n_points": 50},
         "tracker.measurement.samples": 2, "tracker.measurement.settle_s": 0.0, "calibration.residual": "none"}
RWS_OPTIONS = {"credentials": {"use_default": True}, "settle_s": 0.01, "poll_s": 0.005, "max_poll_rate_hz": 500}


def _finished(run, min_points=20):
    contents = read_log(run)
    assert contents.stops[-1]["exit_status"] == "success", contents.stops
    assert len(contents.points) >= min_points
    report = read_report(run)
    assert report.stages["kinematic"].test.rms_mm < report.stages["nominal"].test.rms_mm
    return contents, report


@pytest.mark.parametrize("version", [1, 2])
def test_campaign_against_rws_emulator(tmp_path, version):
    with RwsEmulator(version, joint_speed_deg_s=5000.0) as emu:
        cfg = small_config(tmp_path, **SMALL, **{"robot.url": emu.url, "robot.options": RWS_OPTIONS})
        run = tmp_path / "run"
        assert main(["run", str(cfg), "--out", str(run)]) == 0
        contents, _ = _finished(run)
        assert len(emu.moves) >= len(contents.points)
    assert emu.counts["logouts"] >= 1                 # the session was closed in finally


def test_campaign_against_ur_emulator_with_the_real_library(tmp_path, monkeypatch):
    from drivers.base import MotionLimits
    from drivers.ur import URRobot
    monkeypatch.setattr(URRobot, "DEFAULT_LIMITS", MotionLimits(5000.0, 100.0))   # caps that do not bind here
    # nor does the config's TCP cap (250 mm/s would make this a minute of emulated motion)
    emu = start_emulator()
    try:
        cfg = small_config(tmp_path, "ur10", **dict(SMALL, **{"plan.grid.step_mm": 300}), **{
            "robot.url": f"ur-rtde://{emu.host}", "robot.max_tcp_speed_mm_s": 3000,   # the datasheet maximum
            "robot.options": {"speed_rad_s": 3.0, "acceleration_rad_s2": 20.0, "settle_hold_s": 0.02}})
        run = tmp_path / "run"
        assert main(["run", str(cfg), "--out", str(run)]) == 0
        _finished(run)
    finally:
        emu.stop()


def test_campaign_with_tracker_over_socket(tmp_path):
    """Robot: the RWS emulator moving a simulated robot; tracker: the line-protocol emulator measuring it."""
    cfg_path = small_config(tmp_path, **SMALL)
    world = mock_world(load_cell(cfg_path))
    world.faults = {}

    def move(q_deg):
        world.move(np.asarray(q_deg, float))
        return None

    def position():
        return world.p_smr_tracker_mm + world.point_error_mm

    with RwsEmulator(1, joint_speed_deg_s=5000.0, move_hook=move) as rws, \
            TrackerEmulator(position_source=position, noise_mm=0.0) as tracker:
        cfg = small_config(tmp_path, **SMALL, **{"robot.url": rws.url, "robot.options": RWS_OPTIONS,
                                                 "tracker.url": tracker.url})
        run = tmp_path / "run"
        assert main(["run", str(cfg), "--out", str(run)]) == 0
        contents, report = _finished(run)
    assert report.stages["kinematic"].test.rms_mm < 3 * report.noise_floor_mm


def test_motors_off_mid_run_stops_cleanly_and_resume_completes(tmp_path, capsys):
    """A fault during the campaign: one-line reason, robot commanded to stop, nothing lost, resume finishes."""
    with RwsEmulator(1, joint_speed_deg_s=5000.0) as emu:
        cfg = small_config(tmp_path, **SMALL, **{"robot.url": emu.url, "robot.options": RWS_OPTIONS})
        run = tmp_path / "run"
        moves = []

        def hook(q_deg):
            moves.append(q_deg)
            if len(moves) == 8:
                emu.fail_next_move("motors_off")
            return None
        emu.move_hook = hook
        assert main(["run", str(cfg), "--out", str(run)]) == 1
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and "run fail" in err and "--resume" in err
        before = read_log(run)
        assert before.stops[-1]["exit_status"] == "fail" and 5 <= len(before.points) <= 9
        prefix = (run / "log.jsonl").read_bytes()
        emu.move_hook = None
        emu.set_ctrlstate("motoron")
        emu.set_execution(True)
        assert main(["run", str(cfg), "--resume", str(run)]) == 0
        contents, _ = _finished(run)
        ids = [p["point_id"] for p in contents.points]
        assert len(ids) == len(set(ids)) and (run / "log.jsonl").read_bytes().startswith(prefix)


def test_controller_of_another_model_stops_before_the_first_move(tmp_path, capsys):
    """The config is an IRB 2600's; the controller reports an IRB 6700: exit 2 with the reason, nothing moved, no
    run directory. With --force the run goes ahead and the override is recorded in the log and the report."""
    with RwsEmulator(1, joint_speed_deg_s=5000.0, robot_type="IRB 6700-150/3.20", serial="6700-104512") as emu:
        cfg = small_config(tmp_path, **SMALL, **{"robot.url": emu.url, "robot.options": RWS_OPTIONS})
        run = tmp_path / "run"
        assert main(["run", str(cfg), "--out", str(run)]) == 2
        err = capsys.readouterr().err.strip()
        print(err)
        assert len(err.splitlines()) == 1 and "IRB 6700-150/3.20" in err and "6700-104512" in err
        assert "robot.model" in err and "--force" in err
        assert emu.moves == [] and not run.exists()
        assert main(["run", str(cfg), "--out", str(run), "--force"]) == 0
        contents, report = _finished(run)
    for doc in (contents.start, dict(report.identification)):
        check = doc["identity_check"]
        assert check["robot"]["result"] == "mismatch" and "IRB 6700-150/3.20" in check["overridden"][0]
