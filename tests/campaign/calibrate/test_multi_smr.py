"""Three SMRs end to end: the SMR triangle screens calib and test rows (model-free), a non-rigid SMR group is bad
input, and ``verify`` reports the tool orientation (seed 003: SMR 1 measured, SMRs 2-3 predicted, adjusted)."""
import csv
import json
from dataclasses import replace

import numpy as np
import pytest

from campaign.config.simulation import simulated_cell
from campaign.cli import main
from campaign.config.cell_model import CellModel
from campaign.config.load import load_cell
from campaign.data.dataset import Dataset
from campaign.data.interchange_csv import write_csv
from campaign.calibrate.stages import calibrate_dataset
from robocal.multi_smr.calibration import predict_multi
from tests.campaign.helpers import ROOT, read_verify, small_config
from tests.campaign.config.test_multi_smr_section import SMR1, SMR2, SMR3

CELL = load_cell(ROOT / "configs/irb2600.yaml")
CFG = CELL.config
OFFSETS = np.array([[0.36, 0.28, 39.43], [90.0, 0.0, 50.0], [0.0, 90.0, 50.0]])


def three_smr_dataset(seed=7, n_cal=120, n_test=40):
    rng = np.random.default_rng(seed)
    truth = simulated_cell(CELL).truth
    q = rng.uniform(np.radians([-60, -40, -60, -120, -100, -180]), np.radians([60, 70, 40, 120, 100, 180]),
                    (n_cal + n_test, 6))
    P = predict_multi(truth, OFFSETS, q) + rng.normal(0, 0.01, (3, len(q), 3))
    return rng, q, P, tuple(["calib"] * n_cal + ["test"] * n_test)


def dataset(q, P, sets, source="sim3"):
    return Dataset(tuple(f"P{i}" for i in range(len(q))), sets, np.degrees(q), P[0], p2_tracker_mm=P[1],
                   p3_tracker_mm=P[2], source=source)


@pytest.mark.system
def test_corrupted_smr_readings_are_set_aside_on_calib_and_test_rows():
    cfg = replace(CFG, tool=replace(CFG.tool, p_flange_smr2_mm=tuple(OFFSETS[1]), p_flange_smr3_mm=tuple(OFFSETS[2])))
    _, q, P, sets = three_smr_dataset()
    P[1, [3, 130]] += [1.5, 0.0, 0.0]                     # SMR 2 misread on a calib and a test row
    P[2, 50] += [0.0, -2.0, 0.5]                          # SMR 3 on a calib row
    rep = calibrate_dataset(dataset(q, P, sets), CellModel.from_config(cfg)).report
    listed = {e.point_id: e for e in rep.excluded_points}
    print({k: v.reason for k, v in listed.items()})
    assert set(listed) == {"P3", "P50", "P130"} and listed["P130"].set == "test"
    assert "(SMR 2)" in listed["P3"].reason and "(SMR 3)" in listed["P50"].reason
    assert rep.stages["kinematic"].test.n == 39 and rep.n.calib == 118


@pytest.mark.unit
def test_smr_columns_of_no_rigid_tool_are_bad_input(tmp_path, capsys):
    rng, q, P, sets = three_smr_dataset()
    P[2] = P[2][rng.permutation(len(q))]                  # SMR 3 readings of other poses
    write_csv(tmp_path / "d.csv", dataset(q, P, sets))
    cfg = small_config(tmp_path, **{"tool.p_flange_smr2_mm": OFFSETS[1].tolist(),
                                    "tool.p_flange_smr3_mm": OFFSETS[2].tolist()})
    assert main(["reprocess", str(tmp_path / "d.csv"), "--config", str(cfg), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "not on one rigid tool" in err
    assert not (tmp_path / "o").exists()


@pytest.mark.system
def test_verify_with_three_smrs_reports_the_tool_orientation(tmp_path, capsys):
    cfg = small_config(tmp_path, "irb4600", **{"tool.p_flange_smr_mm": SMR1, "tool.p_flange_smr2_mm": SMR2,
                                                "tool.p_flange_smr3_mm": SMR3, "simulation.p_flange_smr_mm": SMR1,
                                                "plan.test.count": 12, "calibration.residual": "none"})
    run = tmp_path / "run"
    assert main(["run", str(cfg), "--out", str(run)]) == 0
    model = json.loads((run / "model.json").read_text())
    assert len(model["meta"]["p_flange_smrs_mm"]) == 3
    capsys.readouterr()
    assert main(["verify", str(run)]) == 0
    out = capsys.readouterr().out
    report = read_verify(next(run.glob("verify-*/verify.json")))
    a = {p.stage: p.orientation_error_arcsec for p in report.passes if p.orientation_error_arcsec is not None}
    print({k: (round(v.rms, 1), v.source) for k, v in a.items()})
    assert "measured" in a["uncorrected (planned joints)"].source
    assert "seed 003" in a["model-corrected"].source and a["model-corrected"].n == report.n
    assert "tool orientation error" in out
    # the position-only correction leaves the orientation error (the simulated robot's geometry) as it was
    assert abs(a["model-corrected"].rms / a["uncorrected (planned joints)"].rms - 1) < 0.05
    # ... and `correct` predicts it at the same points: the model's orientation at the corrected joints with the
    # three-SMR calibration's held-out orientation RMS
    with open(run / "plan.csv", newline="") as fh:
        tests = [r for r in csv.DictReader(fh) if r["set"] == "test"]
    (tmp_path / "t.csv").write_text("target_id,x,y,z\n" + "".join(
        f"{r['point_id']},{r['x_base_mm']},{r['y_base_mm']},{r['z_base_mm']}\n" for r in tests))
    assert main(["correct", "--config", str(cfg), "--model", str(run / "model.json"), "--targets",
                 str(tmp_path / "t.csv"), "--out", str(tmp_path / "c"), "--format", "csv"]) == 0
    assert "held-out RMS" in capsys.readouterr().out
    with open(tmp_path / "c" / "targets.csv", newline="") as fh:
        rot = np.array([float(r["predicted_rot_err_deg"]) for r in csv.DictReader(fh)]) * 3600
    rms = np.sqrt(np.mean(rot**2))
    print(f"predicted orientation error {rms:.1f} arcsec RMS on {len(rot)} targets; measured after correction "
          f"{a['model-corrected'].rms:.1f}")
    assert len(rot) == len(tests) and abs(rms / a["model-corrected"].rms - 1) < 0.05
    # the estimate from SMR 1 + two predicted SMRs agrees with the orientation measured from all three (itself
    # ~30 arcsec noisy: 0.02 mm over a 150-210 mm triangle), far below the robot's own orientation error
    from campaign.calibrate.multi_smr import measured_flange_poses, pose_estimator
    from campaign.calibrate.outputs import load_model
    from campaign.run.log_reader import read_log
    from robocal.kinematics.frames import matrix_to_rotvec
    records = read_log(run).records()
    est = pose_estimator(load_cell(cfg), load_model(run / "model.json"), records)
    tests = [r for r in records if r.set == "test"]
    T_meas = measured_flange_poses(est.tool.p_flange_mm, tests)
    T_est = est.estimate(np.radians([r.q_cmd_deg for r in tests]), np.array([r.p_tracker_mm for r in tests]))
    d = np.degrees(np.linalg.norm(matrix_to_rotvec(T_est.T_tracker_flange[:, :3, :3]
                                                   @ np.swapaxes(T_meas[:, :3, :3], 1, 2)), axis=1)) * 3600
    print(f"estimated vs measured flange orientation on {len(d)} test stops: {np.sqrt(np.mean(d**2)):.1f} arcsec RMS")
    assert np.sqrt(np.mean(d**2)) < 60.0 < 0.2 * a["uncorrected (planned joints)"].rms
