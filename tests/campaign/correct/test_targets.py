"""Target correction end to end on the mock cell: correct CLI, write-back bounds, closed-loop verify."""
import json

import pytest

from campaign.cli import main
from drivers.rapid import check_rapid_syntax, parse_rapid_module
from tests.campaign.helpers import ROOT, read_verify

pytestmark = pytest.mark.system

CONFIG = str(ROOT / "configs/irb2600.yaml")


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("corr") / "run"
    assert main(["run", CONFIG, "--out", str(out)]) == 0
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
    from tests.campaign.helpers import small_config
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
