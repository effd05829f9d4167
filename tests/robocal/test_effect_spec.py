"""``EffectChoice.to_spec``: a choice written as a config's ``calibration.effects`` item reads back as the same
choice (the YAML text in between), and the effect factory accepts its parameters."""
from __future__ import annotations

import numpy as np
import pytest
import yaml

from robocal.effects.bases import by_name
from robocal.effects.model import EffectChoice

CHOICES = [
    EffectChoice("joint_compliance", (("joints", (2, 3)), ("form", "links"), ("payload_cog_flange_mm", (0.0, 0.0, 12.5)),
                                      ("gravity_base", (0.0, 0.0, -1.0)))),
    EffectChoice("gear_cyclic", (("joint", 4), ("harmonics", (2, 3)))),
    EffectChoice("registration_drift", (("clock", "t_s"), ("degree", 2), ("span", np.float64(7206.0)))),
    EffectChoice("readback_lag", (("joints", (1, 2)), ("memory_joints", (2,)))),
    EffectChoice("thermal_drift", (("tau_s", 3600.0), ("joints", (1, 2, 3)))),
    EffectChoice("axis_coupling", ()),
]


def _read_back(item: dict) -> EffectChoice:
    """The choice a config item gives, as ``campaign.calibrate.effects_stage.effect_choices`` reads it."""
    return EffectChoice.of_dict({"name": item["name"], "options": item["params"]})


@pytest.mark.unit
@pytest.mark.parametrize("choice", CHOICES, ids=lambda c: c.label)
def test_a_choice_reads_back_from_its_config_item(choice):
    text = yaml.safe_dump({"effects": [choice.to_spec()]}, sort_keys=False)      # as effects.yaml is written
    item = yaml.safe_load(text)["effects"][0]
    assert "!!" not in text                                 # plain YAML: no numpy or tuple tags
    assert _read_back(item) == choice and _read_back(item).label == choice.label
    assert by_name(item["name"], 6, **item["params"]).k == choice.build(6).k
