"""Target correction end to end on the mock cell: correct CLI, write-back bounds, closed-loop verify."""
import csv
import json
import re

import numpy as np
import pytest

from campaign.cli import main
from campaign.config.load import load_cell
from campaign.plan.poses import solve_targets, tool_rotation
from drivers.rapid import check_rapid_syntax, parse_rapid_module
from tests.campaign.helpers import ROOT, read_verify, small_config

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
