"""The joint-error GP layer in the calibration report: its summary (approximation, training size, noise against the
floor, each joint's curve) survives report.json, and the terminal line names the curves."""
from __future__ import annotations

import numpy as np
import pytest

import robocal.layers.joint_gp as jg
from campaign.calibrate.report_sections import LayerSummary
from campaign.report.terminal import layer_line
from robocal.layers.choice import LayerChoice, layer_summary
from tests.cells import irb2600


@pytest.mark.unit
def test_joint_gp_summary_round_trips_and_prints_its_curves():
    kin = irb2600()
    rng = np.random.default_rng(0)
    q = rng.uniform(np.radians([-60, -40, -60, -90, -60, -90]), np.radians([60, 60, 30, 90, 60, 90]), (120, 6))
    f = np.zeros_like(q)
    f[:, 1] = 1e-4 * np.sin(12 * q[:, 1])
    e = np.einsum("nij,nj->ni", jg.joint_directions(kin, q, np.arange(6)), f) + rng.normal(0, 0.02, (120, 3))
    layer, _ = jg.fit_joint_gp(kin, q, e, noise_floor_mm=0.035)
    stage = {"calib": {"rms_mm": 0.03}, "test": {"rms_mm": 0.04}}
    d = layer_summary(LayerChoice("joint_gp", layer, {"joint_gp": {"cv_rms_mm": 0.041}}, 5), stage)
    lay = LayerSummary.from_dict(d)
    assert lay.to_dict() == d
    assert lay.approximation == "reduced-rank joint curves" and lay.n_train == 120 and lay.n_inducing is None
    assert lay.noise_mm >= lay.noise_floor_mm == 0.035
    curves = lay.joint_curve_rms_arcsec
    assert max(curves, key=curves.get) == "J2"
    assert curves["J2"] == pytest.approx(1e-4 / np.sqrt(2) * 206264.8, rel=0.3)
    line = layer_line(lay)
    assert line.startswith("residual layer joint_gp (reduced-rank joint curves (J1 ") and "on 120 points" in line


@pytest.mark.system
def test_residual_joint_gp_in_the_config_forces_the_layer_and_the_model_reloads(tmp_path):
    """``calibration.residual: joint_gp`` on a simulated UR10 campaign: the final model carries the layer, model.json
    reloads it with the same predictions, and the report's layer summary lists one curve per moving joint."""
    import yaml

    from campaign.calibrate.stages import calibrate_dataset
    from campaign.config.load import load_cell
    from robocal.layers.calibrated_model import CalibratedModel
    from tests.campaign.helpers import ROOT, simulated_campaign

    d = yaml.safe_load((ROOT / "configs" / "ur10.yaml").read_text())
    d.setdefault("calibration", {})["residual"] = "joint_gp"
    (tmp_path / "c.yaml").write_text(yaml.safe_dump(d, sort_keys=False))
    cell = load_cell(tmp_path / "c.yaml")
    ds = simulated_campaign(cell, 1)
    res = calibrate_dataset(ds, cell)
    assert res.report.residual_choice.chosen == "joint_gp"
    assert isinstance(res.model.residual, jg.JointGPResidual)
    again = CalibratedModel.from_dict(res.model.to_dict())
    q = np.radians(ds.q_deg[ds.mask("test")])
    np.testing.assert_allclose(again.smr_tracker(q), res.model.smr_tracker(q), atol=1e-9)
    lay = res.report.final.layer
    assert set(lay.joint_curve_rms_arcsec) == {f"J{j + 1}" for j in res.model.residual.joints}
