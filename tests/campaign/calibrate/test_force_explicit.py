"""``--force`` travels as an argument (no context variable): a failed plausibility check raises without it and is
recorded as overridden with it, and the CLI hands it to the workflow."""
from dataclasses import replace

import numpy as np
import pytest

from campaign.calibrate import plausibility
from campaign.calibrate.plausibility import Plausibility, check_deltas
from campaign.config.load import load_cell
from campaign.errors import PlausibilityError
from tests.campaign.helpers import ROOT

pytestmark = pytest.mark.unit


@pytest.fixture(scope="module")
def cell():
    return load_cell(ROOT / "configs" / "irb2600.yaml")


def test_a_failed_check_raises_unless_forced_and_is_recorded_when_forced(cell):
    kin0 = cell.kinematics
    kin = replace(kin0, a_mm=np.asarray(kin0.a_mm) + np.r_[40.0, np.zeros(kin0.n - 1)])     # a1 40 mm off
    with pytest.raises(PlausibilityError, match="a1 \\+40.0 mm"):
        check_deltas(kin0, kin, "model.json", Plausibility())
    state = check_deltas(kin0, kin, "model.json", Plausibility(), force=True)
    assert state.forced and "a1 +40.0 mm" in state.overridden[0]
    assert not hasattr(plausibility, "forced") and not hasattr(plausibility, "is_forced")


def test_the_cli_passes_force_to_the_workflow(monkeypatch, tmp_path):
    import campaign.workflows as workflows
    from campaign.cli import main

    seen = {}

    def fake_correct(cell, model, targets, out, formats=(), *, overwrite=False, force=False, on_rejected=None):
        seen["force"] = force
        raise PlausibilityError(str(model), "stop here")
    monkeypatch.setattr(workflows, "correct", fake_correct)
    args = ["correct", "--config", str(ROOT / "configs" / "irb2600.yaml"), "--model", str(tmp_path / "m.json"),
            "--targets", str(tmp_path / "t.csv"), "--out", str(tmp_path / "out")]
    assert main(args) == 2 and seen == {"force": False}
    assert main(args + ["--force"]) == 2 and seen == {"force": True}
