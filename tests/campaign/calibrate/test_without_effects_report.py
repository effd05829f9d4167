"""Effects left out of the final model (robocal.layers.choice ``GEOMETRIC_RIVAL``), through ``campaign reprocess``:
every output says the same model, the one ``model.json`` holds, and the held-out error is lower than with the
effects kept."""
from __future__ import annotations

import json
import re
from unittest import mock

import numpy as np
import pytest

import robocal.layers.choice as choice
from campaign.calibrate.stages import calibrate_dataset
from campaign.config.load import load_cell
from campaign.data.source import load_source
from robocal.simulation.truth_cell import TruthProtocol, simulate
from tests.campaign.helpers import read_report, truth_csv
from tests.campaign.hostile import cli
from tests.campaign.one_record import check_everything

SAG = ["reach_deflection"]          # issue 32's layer-only form: a reach sag that no effect of the library describes
SEED = 8                            # a development seed where the effect engine takes a proxy of the sag
FEW = TruthProtocol(n_calib=60, n_test=40, check_poses=4)      # 60 poses: where proxies are taken


@pytest.mark.system
def test_left_out_effects_are_said_once_and_the_same_everywhere(tmp_path, capsys):
    csv, cfg = truth_csv(tmp_path, simulate(SAG, SEED, FEW))
    out = tmp_path / "out"
    code, text, err = cli(capsys, "reprocess", csv, "--config", cfg, "--out", out)
    assert code == 0, err
    report, model = read_report(out), json.loads((out / "model.json").read_text())
    w = report.residual_choice.without_effects
    left_out = report.residual_choice.effects_left_out
    assert w["chosen"] and left_out and tuple(w["effects"]) == left_out
    assert report.method.residual == "trend_gpr" and model["residual"]["kind"] == "trend_gpr"
    assert not model.get("effects") and report.parameters_geometry_only is None
    assert not (out / "effects.yaml").exists() and "effects.yaml" not in text      # nothing to carry
    assert report.summary.model.effects == ()                     # the summary lists the final model's effects
    assert "then left out" in report.summary.reasons.effects
    assert any(n.startswith("not in the final model: " + ", ".join(left_out)) for n in report.effects.notes)
    # the elastic stage stays in the table (what the effects gave), and the final model beats it held out
    assert report.stages["compensated"].test.rms_mm < report.stages["elastic"].test.rms_mm
    assert re.search(r"without the effects \(.*\): geometry \+ trend_gpr CV RMS 0\.\d{4} mm against 0\.\d{4} mm "
                     r"with them .*: chosen", " ".join(text.split()))
    page = (out / "report.html").read_text()
    assert 'id="without-effects"' in page and "The final model leaves the effects out" in page
    checked = check_everything(text, out, cfg)
    assert checked["urdf chain max mm"] < 1e-9
    # the budget is the final model's: no effect share
    assert not {c.name for c in report.budget.components} & set(left_out), report.budget.components
    with capsys.disabled():
        print(f"\nleft out {left_out}: CV {w['cv_rms_with_effects_mm']:.4f} -> {w['cv_rms_mm']:.4f} mm (t {w['t']:.1f});"
              f" held out elastic {report.stages['elastic'].test.rms_mm:.4f}, final {report.final.test.rms_mm:.4f}")


@pytest.mark.system
def test_left_out_beats_the_effects_kept_held_out(tmp_path):
    csv, cfg = truth_csv(tmp_path, simulate(SAG, SEED, FEW))
    ds, cell = load_source(csv).dataset, load_cell(cfg)
    on = calibrate_dataset(ds, cell)
    with mock.patch.object(choice, "GEOMETRIC_RIVAL", False):
        off = calibrate_dataset(ds, cell)
    on_mm, off_mm = on.report.final.test.rms_mm, off.report.final.test.rms_mm
    print(f"held-out RMS with the rival {on_mm:.4f} mm, without {off_mm:.4f} mm")
    assert on.model.effects == () and off.model.effects != ()
    assert on_mm < 0.9 * off_mm
    q = np.radians(ds.q_deg[ds.mask("test")])
    np.testing.assert_allclose(on.model.smr_tracker(q), type(on.model).from_dict(on.model.to_dict()).smr_tracker(q),
                               atol=1e-9)
