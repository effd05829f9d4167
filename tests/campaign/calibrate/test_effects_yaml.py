"""``effects.yaml`` (``campaign.calibrate.outputs.effects_yaml``): ``reprocess`` writes the physical effects of the
model it wrote as a config's ``calibration.effects``, and a campaign configured with them fits the same effects."""
from __future__ import annotations

import json

import pytest
import yaml

from robocal.simulation.truth_cell import simulate
from tests.campaign.helpers import read_report, truth_csv
from tests.campaign.hostile import cli

EFFECTS = ["joint_compliance", "gear_cyclic", "registration_drift"]   # issue 32's compliance + gear + drift form
SEED = 49


def _effects(out) -> list:
    """(name, options) of the effects of OUT/model.json."""
    return [(e["name"], e["options"]) for e in json.loads((out / "model.json").read_text()).get("effects") or ()]


@pytest.mark.system
def test_a_config_carrying_effects_yaml_fits_the_effects_the_model_has(tmp_path, capsys):
    csv, cfg = truth_csv(tmp_path, simulate(EFFECTS, SEED))
    out = tmp_path / "full"
    code, text, err = cli(capsys, "reprocess", csv, "--config", cfg, "--out", out)
    assert code == 0, err
    taken = _effects(out)
    assert len(taken) >= 2 and "effects.yaml" in text
    section = yaml.safe_load((out / "effects.yaml").read_text())
    assert [(e["name"], e["params"]) for e in section["calibration"]["effects"]] == taken
    assert read_report(out).effects.selection is not None            # chosen by calibration.effects: auto

    doc = yaml.safe_load(cfg.read_text())
    doc.setdefault("calibration", {}).update(section["calibration"])
    carried = tmp_path / "carried.yaml"
    carried.write_text(yaml.safe_dump(doc, sort_keys=False))
    again = tmp_path / "carried"
    code, text, err = cli(capsys, "reprocess", csv, "--config", carried, "--out", again)
    assert code == 0, err
    assert _effects(again) == taken                                  # the same effects, configured ...
    assert read_report(again).effects.selection is None              # ... not chosen again
    assert (again / "effects.yaml").read_text() == (out / "effects.yaml").read_text()


@pytest.mark.system
def test_no_effects_yaml_without_effects(tmp_path, capsys):
    csv, cfg = truth_csv(tmp_path, simulate(EFFECTS, SEED), **{"calibration.effects": "none"})
    out = tmp_path / "out"
    code, text, err = cli(capsys, "reprocess", csv, "--config", cfg, "--out", out)
    assert code == 0, err
    assert not _effects(out) and not (out / "effects.yaml").exists() and "effects.yaml" not in text
