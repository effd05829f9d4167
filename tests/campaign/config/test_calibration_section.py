"""calibration.effects / outliers / residual / cv_folds keys, and an effect list reaching the model."""
import json

import pytest
import yaml

from campaign.cli import main
from campaign.config.load import load_config
from campaign.errors import ConfigError
from tests.campaign.helpers import ROOT, read_report, small_config


def _with(tmp_path, **calibration):
    doc = yaml.safe_load((ROOT / "configs/irb2600.yaml").read_text())
    doc["calibration"].update(calibration)
    path = tmp_path / "c.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


@pytest.mark.unit
def test_effect_list_is_parsed(tmp_path):
    cfg = load_config(_with(tmp_path, effects=[{"name": "joint_compliance", "params": {"joints": [2, 3]}},
                                               "axis_coupling"], outliers="none", cv_folds=4))
    assert [e.name for e in cfg.calibration.effects] == ["joint_compliance", "axis_coupling"]
    assert cfg.calibration.outliers == "none" and cfg.calibration.cv_folds == 4


@pytest.mark.unit
@pytest.mark.parametrize("key, value, path, words", [
    ("effects", "some", "calibration.effects", "auto, none"),
    ("effects", [{"name": "link_bending"}], "calibration.effects[0].name", "joint_compliance"),
    ("effects", [{"name": "gear_cyclic", "params": {"joint": 2, "order": 3}}], "calibration.effects[0].params.order",
     "unknown parameter of gear_cyclic (expected one of: harmonics, joint)"),
    ("effects", [{"name": "axis_coupling", "params": {"tau_s": 4}}], "calibration.effects[0].params.tau_s",
     "expected one of: joints"),
    ("effects", [{"name": "backlash", "scale": 2}], "calibration.effects[0].scale", "simulated effects only"),
    ("effects", [{"name": "joint_compliance", "params": {"form": "linkz"}}], "calibration.effects[0].params",
     "unknown compliance form 'linkz'"),
    ("outliers", "igg3", "calibration.outliers", "local, none"),
    ("residual", "krige", "calibration.residual", "auto"),
    ("cv_folds", 1, "calibration.cv_folds", "[2, 20]"),
])
def test_bad_calibration_keys_name_the_key(tmp_path, key, value, path, words):
    with pytest.raises(ConfigError) as err:
        load_config(_with(tmp_path, **{key: value}))
    msg = str(err.value)
    assert path in msg and words in msg and len(msg.splitlines()) == 1


@pytest.mark.system
def test_forced_effect_list_reaches_model_json(tmp_path):
    cfg = small_config(tmp_path, **{"calibration.effects": [{"name": "joint_compliance", "params": {"joints": [2, 3]}}],
                                    "calibration.residual": "none"})
    run = tmp_path / "r"
    assert main(["run", str(cfg), "--out", str(run)]) == 0
    model = json.loads((run / "model.json").read_text())
    report = read_report(run)
    assert model["effects"][0]["name"] == "joint_compliance" and set(model["effects"][0]["params"]) == {"c2", "c3"}
    assert report.effects.selection is None and "elastic" in report.stages
    assert model["residual"] is None


@pytest.mark.unit
def test_gravity_model_keys_of_the_robot(tmp_path):
    from campaign.config.load import load_cell

    g = load_cell(small_config(tmp_path, **{"robot.mass_kg": 272, "robot.gravity_direction_base": [1, 0, 0]})).gravity
    assert g.source == "mass class" and g.gravity_base == (1.0, 0.0, 0.0)
    assert sum(g.link_masses_kg) == pytest.approx(0.7 * 272)
    for key, value, words in (("robot.link_masses_kg", [1, 2], "a list of 6 numbers"),
                              ("robot.link_masses_kg", [0, -1, 0, 0, 0, 0], ">= 0 kg"),
                              ("robot.mass_kg", -5, "robot.mass_kg"),
                              ("robot.gravity_direction_base", [0, 0, 0], "non-zero")):
        with pytest.raises(ConfigError) as err:
            load_config(small_config(tmp_path, **{key: value}))
        assert key in str(err.value) and words in str(err.value) and len(str(err.value).splitlines()) == 1
