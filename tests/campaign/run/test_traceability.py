"""Traceability and ETA: identification in the start record and report.json, campaign.log, a keep-out run whose
every executed move stays clear, and an ETA that converges during the run."""

from datetime import datetime

import numpy as np
import pytest

from campaign.cli import main
from campaign.config.load import load_cell, load_config
from campaign.run.eta import RunEta, estimate_duration_s, point_times_s
from campaign.workflows import run_campaign
from campaign.plan.build import build_plan
from campaign.run.log_reader import read_log
from campaign.run.traceability import simulated_devices
from drivers.mock import MockRobot
from robocal.kinematics.sweep import Boxes, flange_points_base, sample_segments
from tests.campaign.helpers import read_report, small_config

SMALL = {"plan.grid.step_mm": 600, "plan.test.count": 6, "plan.check_poses": {"count": 0, "every_n_points": 50},
         "tracker.measurement.samples": 2, "tracker.measurement.settle_s": 0.0, "calibration.residual": "none"}
KEEP_OUT = {"name": "fixture", "min_mm": [700, -250, 800], "max_mm": [1000, 250, 1100]}


@pytest.mark.system
def test_mock_run_carries_identification_and_writes_campaign_log(tmp_path):
    cfg = small_config(tmp_path, **SMALL)
    run = tmp_path / "run"
    assert main(["run", str(cfg), "--out", str(run)]) == 0
    start = read_log(run).start
    for doc in (start, dict(read_report(run).identification)):
        assert doc["robot_identity"]["serial"] == "MOCK-R-0001"
        assert set(doc["robot_identity"]) >= {"vendor", "model", "controller_type", "serial", "software_version"}
        assert doc["tracker_identity"]["serial"] == "MOCK-T-0001"
        assert set(doc["tracker_identity"]) >= {"vendor", "model", "serial", "firmware"}
        assert doc["driver_versions"]["robot_driver"] == "drivers.mock.MockRobot"
        assert doc["software_version"]
    ident = dict(read_report(run).identification)
    contents = read_log(run)
    assert (ident["config_sha256"], ident["plan_sha256"]) == (start["config_sha256"], start["plan_sha256"])
    assert ident["started_utc"] == start["created_utc"] and ident["finished_utc"] == contents.stops[-1]["closed_utc"]
    assert datetime.fromisoformat(ident["started_utc"]) <= datetime.fromisoformat(ident["finished_utc"])
    recs = contents.records()
    assert ident["measuring_s"] == max(r.t_end_s for r in recs) - min(r.t_start_s for r in recs) > 0
    assert ident["simulated_devices"] == ["robot", "tracker"]
    text = (run / "campaign.log").read_text()
    assert "MOCK-R-0001" in text and "run success" in text


@pytest.mark.unit
def test_simulated_devices_are_the_mock_urls():
    cfg = {"robot": {"url": "abb-rws://192.168.125.1"}, "tracker": {"url": "mock://tracker"}}
    assert simulated_devices(cfg) == ["tracker"]
    assert simulated_devices({"robot": {"url": "mock://robot"}, "tracker": {"url": "emscon://10.0.0.2"}}) == ["robot"]
    assert simulated_devices({}) == []


@pytest.mark.unit
def test_eta_on_a_mock_cell_is_labelled_simulated_time():
    assert RunEta(np.array([30.0, 30.0]), simulated=True).text() == "ETA 0:01:00 (simulated time)"
    assert RunEta(np.array([3600.0, 5.0])).text() == "ETA 1:00:05"


@pytest.mark.system
def test_keep_out_run_every_executed_move_stays_clear(tmp_path, monkeypatch):
    cell = load_cell(small_config(tmp_path, **SMALL, **{"plan.keep_out": [KEEP_OUT], "plan.clearance_mm": 30}))
    kin = cell.kinematics
    plan = build_plan(cell)
    assert any(p.via_deg for p in plan.points)                 # the box sits across the plan: vias were needed
    robots = []
    real_init = MockRobot.__init__

    def spy(self, *a, **k):
        real_init(self, *a, **k)
        robots.append(self)
    monkeypatch.setattr(MockRobot, "__init__", spy)
    result = run_campaign(cell, tmp_path / "run")
    assert result.outcome.exit_status == "success"
    cmds = robots[0].commands
    q_a = np.radians([c.q_from_deg for c in cmds])
    q_b = np.radians([c.q_to_deg for c in cmds])
    q, _ = sample_segments(q_a, q_b, np.full(len(cmds), 300))
    pts = flange_points_base(kin, q, np.array([[0.0, 0.0, 0.0], cell.config.tool.p_flange_smr_mm])).reshape(-1, 3)
    box = Boxes(np.array([KEEP_OUT["min_mm"]], float), np.array([KEEP_OUT["max_mm"]], float)).grown(30.0)
    inside = np.all((pts > box.lo[0]) & (pts < box.hi[0]), axis=1)
    assert not inside.any(), f"{inside.sum()} samples of executed moves inside the keep-out box"


@pytest.mark.system
def test_eta_uses_the_reading_time_and_converges_during_a_run(tmp_path):
    cell = load_cell(small_config(tmp_path, **SMALL))
    (tmp_path / "slow").mkdir()                           # its own file: the run copies cell's, unchanged
    slow = load_cell(small_config(tmp_path / "slow", **SMALL, **{"tracker.measurement.reading_time_s": 2.5}))
    plan = build_plan(cell)
    n = len(plan.points)
    d15, d25 = estimate_duration_s(plan.points, cell), estimate_duration_s(plan.points, slow)
    assert d25 - d15 == pytest.approx(n * 2 * 1.0, rel=1e-9)  # samples x (2.5 - 1.5) s per point
    result = run_campaign(cell, tmp_path / "run")
    recs = read_log(result.run_dir).records()
    actual = np.array([r.t_end_s - r.t_start_s for r in recs])
    eta = RunEta(*point_times_s(plan.points, cell))
    prior_error = abs(eta.remaining_s() - actual.sum()) / actual.sum()
    k = n // 4
    for r in recs[:k]:
        eta.observe(r)
    refined_error = abs(eta.remaining_s() - actual[k:].sum()) / actual[k:].sum()
    print(f"ETA error: prior {100 * prior_error:.0f} %, after {k}/{n} points {100 * refined_error:.0f} %")
    assert refined_error < 0.1 and refined_error < prior_error


@pytest.mark.unit
def test_identity_changes_name_what_differs():
    from campaign.run.traceability import identity_changes
    start = {"robot_identity": {"serial": "A1", "software_version": "7.1", "controller_type": "OmniCore"},
             "tracker_identity": {"serial": "T1", "firmware": "2.0", "model": "AT960"}}
    now = {"robot_identity": {"serial": "A2", "software_version": "7.1", "controller_type": "OmniCore"},
           "tracker_identity": {"serial": "T1", "firmware": "2.1", "model": "AT960"}}
    assert identity_changes(start, now) == ["robot serial was 'A1', now 'A2'", "tracker firmware was '2.0', now '2.1'"]
    assert identity_changes(start, start) == []


@pytest.mark.unit
def test_a_robot_standing_inside_the_clearance_is_told_to_jog_clear(tmp_path):
    from campaign.plan.motion_safety import PathGuard, UnsafeMotion
    cell = load_cell(small_config(tmp_path, **SMALL, **{"plan.keep_out": [KEEP_OUT]}))
    cfg, kin = cell.config, cell.kinematics
    guard = PathGuard.for_cell(cell)
    q_ref = np.asarray(cfg.plan.q_ref_deg, float)
    centre = (np.array(KEEP_OUT["min_mm"]) + np.array(KEEP_OUT["max_mm"])) / 2
    from robocal.kinematics.ik import solve_ik
    from campaign.plan.poses import tool_rotation
    res = solve_ik(kin, centre[None], tool_rotation(cfg.plan.tool_direction), np.radians(q_ref))
    inside_q = np.degrees(res.q_rad[0])
    assert guard.pose_reasons(inside_q)[0] is not None
    with pytest.raises(UnsafeMotion, match="jog it clear"):
        guard.route(inside_q, q_ref)


@pytest.mark.unit
def test_driver_warnings_reach_campaign_log_even_before_the_run_directory_exists(tmp_path):
    import io
    import logging

    from rich.console import Console

    from campaign.run.traceability import run_logging
    out = io.StringIO()
    with run_logging(Console(file=out, width=200)) as rl:
        logging.getLogger("drivers.some_driver").warning("controller said: motors off")
        logging.getLogger("campaign.run.runner").info("first point")
        path = rl.to_file(tmp_path)
        logging.getLogger("drivers.some_driver").warning("link slow")
    text = path.read_text()
    assert text.index("motors off") < text.index("first point") < text.index("link slow")
    assert "WARNING drivers.some_driver" in text
    assert "motors off" in out.getvalue() and "first point" not in out.getvalue()   # console: warnings only
    assert not logging.getLogger("drivers").handlers                                    # detached afterwards


@pytest.mark.unit
@pytest.mark.parametrize("configured, reported, same", [
    ("ABB IRB 2600-12/1.65", "IRB 2600-12/1.65", True), ("IRB 2600", "IRB2600-12/1.85", True),
    ("ABB IRB 2600-12/1.65", "IRB2600", True), ("Universal Robots UR10 (CB3)", "UR10", True),
    ("UR10e", "UR10", True), ("Leica AT960", "AT960-MR", True), ("API GTS3800", "GTS 3800", True),
    ("ABB IRB 2600-12/1.65", "IRB 6700-150/3.20", False), ("ABB IRB 2600-12/1.65", "IRB 2600-12/1.85", False),
    ("Universal Robots UR10 (CB3)", "UR5", False), ("Leica AT960", "Leica AT930", False),
    ("ABB IRB 2600-12/1.65", "simulated robot", None), ("Leica AT960", "emScon tracker", None),
    ("Leica AT960", "unknown", None)])
def test_model_names_match_across_vendor_formatting_but_not_across_models(configured, reported, same):
    from campaign.run.traceability import same_model
    assert same_model(configured, reported) is same


@pytest.mark.unit
def test_identity_check_names_the_mismatch_and_force_records_it(tmp_path):
    from campaign.errors import PlausibilityError
    from campaign.run.traceability import check_identity
    cfg = load_config(small_config(tmp_path))
    ident = {"robot_identity": {"model": "IRB 6700-150/3.20", "serial": "6700-1"},
             "tracker_identity": {"model": "emScon tracker", "serial": "7"}}
    with pytest.raises(PlausibilityError, match=r"robot.model is 'ABB IRB 2600-12/1.65' but .* 'IRB 6700-150/3.20'"):
        check_identity(cfg, ident)
    check = check_identity(cfg, ident, force=True)
    assert check["robot"]["result"] == "mismatch" and check["tracker"]["result"] == "not compared"
    assert len(check["overridden"]) == 1
    ident["robot_identity"]["model"] = "IRB2600"
    assert "overridden" not in check_identity(cfg, ident) and check_identity(cfg, ident)["robot"]["result"] == "match"
