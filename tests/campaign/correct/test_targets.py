"""Target correction end to end on the mock cell: correct CLI, write-back bounds, the predicted error of every
target, closed-loop verify."""
import csv
import json
import math
import re
import shutil

import numpy as np
import pytest

from campaign.cli import main
from campaign.config.load import load_cell
from campaign.correct.accuracy import held_out_of
from campaign.calibrate.outputs import load_model
from campaign.plan.poses import solve_targets, tool_rotation
from drivers.rapid import check_rapid_syntax, parse_rapid_module
from tests.campaign.helpers import ROOT, read_report, read_verify, small_config

pytestmark = pytest.mark.system

CONFIG = str(ROOT / "configs/irb2600.yaml")


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    """The shipped IRB 2600 plan on a geometric-only truth: correction and closed loop without tracker drift (verify
    on a drifting tracker with nests: test_verify_drift.py)."""
    tmp = tmp_path_factory.mktemp("corr")
    cfg = small_config(tmp, **{"plan.grid.step_mm": 200, "plan.test.count": 100,
                               "plan.check_poses": {"count": 3, "every_n_points": 50}})
    out = tmp / "run"
    assert main(["run", str(cfg), "--out", str(out)]) == 0
    return out


def test_correct_cli_writes_checked_files_and_rejects_unsafe_targets(run_dir, tmp_path, capsys):
    targets = tmp_path / "targets.csv"
    targets.write_text("target_id,x,y,z\nA,900,0,1000\nB,1100,300,800\nC,700,-500,1200\nFAR,3000,0,1000\n")
    out = tmp_path / "out"
    assert main(["correct", "--config", CONFIG, "--model", str(run_dir / "model.json"), "--targets", str(targets),
                 "--out", str(out), "--format", "rapid", "--format", "ur", "--format", "csv"]) == 0
    text = (out / "CalTargets.mod").read_text()
    assert check_rapid_syntax(text) == []
    values = parse_rapid_module(text)
    assert [v for v in values["id_cal"]] == ["A", "B", "C"]
    rejected = (out / "rejected.csv").read_text()
    assert "FAR" in rejected and "FAR" not in text and "FAR" not in (out / "targets_ur.script").read_text()
    ur = json.loads((out / "targets_ur.json").read_text())
    assert len(ur["targets"]) == 3


def test_correct_cli_bad_targets_file(run_dir, tmp_path, capsys):
    bad = tmp_path / "t.csv"
    bad.write_text("target_id,x,y,z\nA,900,zero,1000\n")
    assert main(["correct", "--config", CONFIG, "--model", str(run_dir / "model.json"), "--targets", str(bad),
                 "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "t.csv" in err and "line 2" in err and "'y'" in err


def test_closed_loop_verify_reaches_the_noise_floor(run_dir):
    assert main(["verify", str(run_dir)]) == 0
    report = read_verify(next(run_dir.glob("verify-*/verify.json")))
    floor, stages = report.noise_floor_mm, report.stages
    ratios = {k: v.rms_mm / floor for k, v in stages.items()}
    print("verify RMS / floor: " + ", ".join(f"{k} {r:.2f}" for k, r in ratios.items()))
    predicted = held_out_of(load_model(run_dir / "model.json"), run_dir / "model.json").rms_mm   # what correct states
    print(f"model-corrected RMS {stages['model-corrected'].rms_mm:.4f} mm vs predicted {predicted:.4f} mm")
    assert 0.8 < stages["model-corrected"].rms_mm / predicted < 1.25
    assert ratios["uncorrected (planned joints)"] > 10
    assert ratios["model-corrected"] <= 1.2
    assert ratios["after correction (all passes pooled)"] <= 1.2
    assert all(r <= 1.3 for k, r in ratios.items() if k.startswith("closed loop"))
    for p in report.passes[1:]:                     # every pass says what it measured
        assert p.n_corrected + p.n_held == (report.n if p.stage != "after correction (all passes pooled)"
                                            else p.n_corrected + p.n_held)
        assert p.n_held == sum(p.held.values()) or p.stage.startswith("after")


def test_gpr_model_reports_the_predictive_std_of_every_corrected_target(tmp_path):
    cfg = small_config(tmp_path, **{"calibration.residual": "gpr"})
    run = tmp_path / "run"
    assert main(["run", str(cfg), "--out", str(run)]) == 0
    targets = tmp_path / "targets.csv"
    targets.write_text("target_id,x,y,z\nA,900,0,1000\nB,1000,200,900\n")
    out = tmp_path / "out"
    assert main(["correct", "--config", str(cfg), "--model", str(run / "model.json"), "--targets", str(targets),
                 "--out", str(out), "--format", "ur", "--format", "csv"]) == 0
    rows = (out / "targets.csv").read_text().splitlines()
    assert rows[0].endswith("predicted_std_mm") and len(rows) == 3
    stds = [float(r.split(",")[-1]) for r in rows[1:]]
    assert all(0 < s < 1 for s in stds)
    ur = json.loads((out / "targets_ur.json").read_text())
    assert all(t["predicted_std_mm"] > 0 for t in ur["targets"])
    rms = read_report(run).final.test.rms_mm                  # the layer's std at each target enters the prediction
    for t in ur["targets"]:
        assert t["predicted_error_mm"] == pytest.approx(
            math.sqrt(rms**2 + t["predicted_std_mm"]**2 + t["solver_tolerance_mm"]**2), rel=1e-12)


def _correct(run_dir, tmp_path, rows, *formats, model=None):
    """``campaign correct`` of the targets ``rows`` (``id,x,y,z``) with the run's model (or ``model``); the exit code
    and the output directory."""
    targets = tmp_path / "targets.csv"
    targets.write_text("target_id,x,y,z\n" + "\n".join(rows) + "\n")
    out = tmp_path / "out"
    code = main(["correct", "--config", CONFIG, "--model", str(model or run_dir / "model.json"), "--targets",
                 str(targets), "--out", str(out)] + [a for f in formats for a in ("--format", f)])
    return code, out


def _csv_rows(path):
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def test_correct_states_the_predicted_error_from_the_held_out_figures_and_the_solver_tolerance_apart(
        run_dir, tmp_path, capsys):
    code, out = _correct(run_dir, tmp_path, ["A,900,0,1000", "B,1100,300,800"], "rapid", "ur", "csv")
    assert code == 0
    said = " ".join(capsys.readouterr().out.split())
    final = read_report(run_dir).final.test
    rows = _csv_rows(out / "targets.csv")
    for r in rows:
        tol = float(r["solver_tolerance_mm"])
        assert tol < 1e-4                                        # the config's threshold_mm: converged
        assert float(r["predicted_error_mm"]) == pytest.approx(math.hypot(final.rms_mm, tol), rel=1e-12)
        assert math.isnan(float(r["predicted_rot_err_deg"]))      # one SMR: the orientation was never measured
    print(said)
    assert (f"predicted position error (predicted_error_mm) {final.rms_mm:.3f} mm: held-out RMS {final.rms_mm:.3f} mm "
            f"of the final model on {final.n} test points ({run_dir / 'report.json'};") in said
    assert "solver tolerance (solver_tolerance_mm)" in said and "predicted_rot_err_deg is nan" in said
    assert "residual" not in said
    errors = [float(r["predicted_error_mm"]) for r in rows]
    assert parse_rapid_module((out / "CalTargets.mod").read_text())["err_cal_mm"] == [round(e, 4) for e in errors]
    assert [t["predicted_error_mm"] for t in json.loads((out / "targets_ur.json").read_text())["targets"]] == errors
    assert f"# A predicted_error_mm={errors[0]:.4f}".rstrip("0") in (out / "targets_ur.script").read_text()


def test_a_model_away_from_its_report_has_an_unknown_predicted_error(run_dir, tmp_path, capsys):
    lonely = tmp_path / "model"
    lonely.mkdir()
    shutil.copy(run_dir / "model.json", lonely)
    code, out = _correct(run_dir, tmp_path, ["A,900,0,1000", "B,1100,300,800"], "rapid", "ur", "csv",
                         model=lonely / "model.json")
    assert code == 0
    said = " ".join(capsys.readouterr().out.split())
    assert "predicted position error: unknown (no report.json beside model.json" in said
    assert all(math.isnan(float(r["predicted_error_mm"])) for r in _csv_rows(out / "targets.csv"))
    rapid = (out / "CalTargets.mod").read_text()
    assert "err_cal_mm" not in parse_rapid_module(rapid) and "predicted position error is unknown" in rapid
    assert all(t["predicted_error_mm"] is None for t in json.loads((out / "targets_ur.json").read_text())["targets"])
    assert (out / "targets_ur.script").read_text().count("predicted_error_mm=unknown") == 2


def test_held_out_figures_come_only_from_the_models_own_calibration_report(run_dir, tmp_path):
    model = load_model(run_dir / "model.json")
    report = read_report(run_dir)
    held = held_out_of(model, run_dir / "model.json")
    assert (held.rms_mm, held.n, held.noise_floor_mm) == (report.final.test.rms_mm, report.final.test.n,
                                                          report.noise_floor_mm)
    assert held.rot_rms_deg is None
    doc = json.loads((run_dir / "report.json").read_text())

    def beside(text):
        d = tmp_path / f"d{len(list(tmp_path.iterdir()))}"
        d.mkdir()
        (d / "report.json").write_text(text)
        return held_out_of(model, d / "model.json")

    no_test = json.loads(json.dumps(doc))
    no_test["stages"]["compensated"]["test"] = {"max_mm": None, "mean_mm": None, "rms_mm": None, "n": 0}
    for text, why in ((json.dumps({**doc, "source": "another/log.jsonl"}), "another calibration"),
                      (json.dumps({**doc, "format": "campaign-iso9283/1"}), "not a calibration report"),
                      ("{", "not readable"), (json.dumps(no_test), "no test points")):
        unknown = beside(text)
        assert unknown.rms_mm is None and why in unknown.source, (why, unknown.source)
    three = {"n_smr": 3, "p_flange_smr_mm": [[0, 0, 40]] * 3, "sigma0": 1.0, "converged": True, "test": {},
             "orientation_error_arcsec": {"mean": 30.0, "rms": 36.0, "max": 50.0, "n": 12}}
    held3 = beside(json.dumps({**doc, "multi_smr": three}))
    assert held3.rot_rms_deg == pytest.approx(0.01) and held3.rot_n == 12 and held3.rms_mm == held.rms_mm


def test_a_rejected_target_names_the_reason_as_the_plan_does(run_dir, tmp_path, capsys):
    code, out = _correct(run_dir, tmp_path, ["A,900,0,1000", "LOW,400,0,200", "FAR,3000,0,1000"], "csv")
    assert code == 0
    said = capsys.readouterr().out
    rejected = {r["target_id"]: r["reason"] for r in _csv_rows(out / "rejected.csv")}
    cell = load_cell(CONFIG)
    _, _, skipped = solve_targets(cell.config, cell.kinematics, np.array([[400.0, 0, 200], [3000.0, 0, 1000]]),
                                  ["LOW", "FAR"], ["test"] * 2, tool_rotation(cell.config.plan.tool_direction), None)
    planned = {s.point_id: s.reason for s in skipped}
    print(rejected, planned)
    assert re.fullmatch(r"joint 2 would be at -1\d\d\.\d deg, outside \[-95, 155\]", rejected["LOW"])
    assert rejected["LOW"] == planned["LOW"] and f"LOW: {rejected['LOW']}" in said
    assert (rejected["FAR"], planned["FAR"]) == ("unreachable with the plan's fixed SMR orientation",
                                                 "unreachable with the fixed SMR orientation")
