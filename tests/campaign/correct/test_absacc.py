"""Absolute Accuracy robots: `correct` refuses (exit 2) to write Cartesian targets that the controller would correct
a second time, unless explicitly allowed (then it warns)."""
import json

import pytest

from campaign.cli import main
from campaign.config.load import load_cell
from campaign.correct.targets import AbsAccRobot, absacc_guard, recorded_identity
from campaign.errors import DataError
from campaign.run.log_writer import RunLog
from robocal.layers.calibrated_model import CalibratedModel
from tests.campaign.helpers import ROOT

CONFIG = str(ROOT / "configs/irb2600.yaml")
ABSACC = {"vendor": "ABB", "model": "IRB 2600-12/1.65", "serial": "2600-500123", "absacc": "yes"}


@pytest.mark.unit
def test_guard_refuses_or_warns_only_for_absacc():
    assert absacc_guard(None) is None and absacc_guard({"absacc": "no"}) is None
    assert absacc_guard({"vendor": "Universal Robots"}) is None
    with pytest.raises(AbsAccRobot, match="corrected twice") as info:
        absacc_guard(ABSACC)
    assert isinstance(info.value, DataError) and "2600-500123" in str(info.value)
    with pytest.warns(UserWarning, match="Absolute Accuracy"):
        assert "corrected twice" in absacc_guard(ABSACC, allow=True)


@pytest.mark.unit
def test_identity_from_model_meta_or_the_run_log(tmp_path):
    kin = load_cell(CONFIG).kinematics
    model = CalibratedModel(kin, None, {"robot_identity": ABSACC})
    assert recorded_identity(model) == ABSACC
    plain = CalibratedModel(kin, None, {})
    run = tmp_path / "run"
    RunLog.create(run, {"config_sha256": "x", "plan_sha256": "y", "robot_identity": ABSACC}).close()
    assert recorded_identity(plain, run / "model.json") == ABSACC            # the run's start record
    assert recorded_identity(plain) is None and recorded_identity(plain, tmp_path / "model.json") is None


@pytest.mark.system
def test_correct_cli_refuses_an_absacc_model(tmp_path, capsys):
    model = CalibratedModel(load_cell(CONFIG).kinematics, None, {"robot_identity": ABSACC})
    path = tmp_path / "model.json"
    path.write_text(json.dumps(model.to_dict()))
    targets = tmp_path / "targets.csv"
    targets.write_text("target_id,x,y,z\nA,900,0,1000\n")
    code = main(["correct", "--config", CONFIG, "--model", str(path), "--targets", str(targets),
                 "--out", str(tmp_path / "out")])
    assert code == 2 and not (tmp_path / "out" / "CalTargets.mod").exists()
    assert "Absolute Accuracy" in capsys.readouterr().err
