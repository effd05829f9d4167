"""The trend + GPR layer in the calibration: its summary (the trend's size, then the GP) survives report.json and the
terminal line names it; on a truth campaign whose sag is outside the effect library, the default process chooses it
(with the geometry change it fits), predicts the held-out poses better than without it, and model.json reloads it."""
from __future__ import annotations

from unittest import mock

import numpy as np
import pytest

import robocal.layers.choice as choice
from campaign.calibrate.report_sections import LayerSummary
from campaign.report.terminal import layer_line
from robocal.layers.calibrated_model import CalibratedModel
from robocal.layers.trend import TrendGPRResidual, fit_trend_gpr
from tests.cells import irb2600


@pytest.mark.unit
def test_trend_summary_round_trips_and_prints_the_trend_first():
    kin = irb2600()
    rng = np.random.default_rng(0)
    q = rng.uniform(np.radians([-60, -40, -60, -90, -60, -90]), np.radians([60, 60, 30, 90, 60, 90]), (80, 6))
    p = CalibratedModel(kin).kinematic_smr_base(q)
    e = np.zeros_like(p)
    e[:, 2] = -0.3 * (np.hypot(p[:, 0], p[:, 1]) / 1000.0) ** 2
    layer, _ = fit_trend_gpr(q, p, e + rng.normal(0, 0.02, e.shape), noise_floor_mm=0.035)
    stage = {"calib": {"rms_mm": 0.03}, "test": {"rms_mm": 0.04}}
    d = choice.layer_summary(choice.LayerChoice("trend_gpr", layer, {"trend_gpr": {"cv_rms_mm": 0.041}}, 5), stage)
    lay = LayerSummary.from_dict(d)
    assert lay.to_dict() == d
    assert lay.trend_rms_mm == pytest.approx(np.sqrt(np.mean(np.sum(e**2, 1))), rel=0.1)   # the sag it carries
    assert lay.approximation == "exact" and lay.n_train == 80
    assert layer_line(lay).startswith("residual layer trend_gpr (quadratic trend 0.")
    assert "then exact GP on 80 points" in layer_line(lay)


@pytest.mark.system
def test_chosen_on_a_sag_outside_the_library_and_better_held_out(tmp_path):
    """The truth simulator's reach sag (development seed 19 of issue 32's layer-only form, all rows): the default
    chooses trend_gpr; without it among the candidates, the held-out RMS is higher; model.json reloads the layer."""
    from campaign.calibrate.stages import calibrate_dataset
    from tests.campaign.adaptive_forms import ADAPTIVE_FORMS

    ds, cell = ADAPTIVE_FORMS["layer only (sag outside the library)"](tmp_path, 19)
    res = calibrate_dataset(ds, cell)
    with mock.patch.object(choice, "LAYER_KINDS", ("idw", "gpr", "joint_gp")):
        without = calibrate_dataset(ds, cell)
    with_mm, without_mm = res.report.final.test.rms_mm, without.report.final.test.rms_mm
    print(f"held-out RMS with trend_gpr offered {with_mm:.4f} mm, without {without_mm:.4f} mm")
    assert res.report.residual_choice.chosen == "trend_gpr" and isinstance(res.model.residual, TrendGPRResidual)
    assert with_mm < 0.95 * without_mm
    again = CalibratedModel.from_dict(res.model.to_dict())
    q = np.radians(ds.q_deg[ds.mask("test")])
    np.testing.assert_allclose(again.smr_tracker(q), res.model.smr_tracker(q), atol=1e-9)
    lay = res.report.final.layer
    assert lay.trend_rms_mm > 0.01 and lay.geometry_shift_rms_mm > 0.0 and lay.trend_and_shift_rms_mm > 0.01
    assert LayerSummary.from_dict(lay.to_dict()) == lay
    assert "with a geometry change of 0." in layer_line(lay) and ", together 0." in layer_line(lay)
