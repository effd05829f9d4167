"""The trend + GPR residual layer (robocal.layers.trend): a quadratic field over the workspace fitted together with a
linearised change of the identified geometry, then the GPR over the joints on what is left. Independent references:
a field written term by term, a geometric fit that absorbed part of it (projection on the Jacobian's columns),
direct fits on the training rows, the model file round trip."""
import numpy as np
import pytest

import robocal.layers.choice as choice
from robocal.effects.cv import kfold
from robocal.kinematics.models import ParamLayout
from robocal.layers.calibrated_model import CalibratedModel
from robocal.layers.gp import MultiOutputGP
from robocal.layers.trend import (QuadraticTrend, TrendGPRResidual, _joint_solve, _priors, fit_trend_gpr,
                                  geometry_columns, trend_features)
from tests.cells import irb2600

LO, HI = np.radians([-60, -40, -60, -90, -60, -90]), np.radians([60, 60, 30, 90, 60, 90])
NOISE_AXIS_MM = 0.02
GEOMETRY = ("a2", "d4", "alpha2", "theta3", "a3", "base_tx", "base_ty", "base_tz", "base_rx", "base_ry", "base_rz")


def _poses(n, seed):
    return np.random.default_rng(seed).uniform(LO, HI, (n, 6))


def _arm(n, seed):
    """(kin, model without a layer, n poses (n, 6) rad, their model SMR positions (n, 3) mm, base frame)."""
    kin = irb2600()
    model = CalibratedModel(kin)
    q = _poses(n, seed)
    return kin, model, q, model.kinematic_smr_base(q)


def _sag_mm(p_base_mm, k_mm_per_m2=0.15):
    """A sag along base z growing with the square of the horizontal reach, plus a slow shear of x with z (N, 3) mm."""
    r_m = np.hypot(p_base_mm[:, 0], p_base_mm[:, 1]) / 1000.0
    out = np.zeros_like(p_base_mm)
    out[:, 2] = -k_mm_per_m2 * r_m**2
    out[:, 0] = 0.05 * p_base_mm[:, 2] / 1000.0
    return out


def _trend_only(p, e):
    """The trend of a field e (N, 3) at p (N, 3) without geometry, noise-free (a tiny noise floor)."""
    _, _, q, _ = _arm(len(p), 0)
    return fit_trend_gpr(q, p, e, noise_floor_mm=1e-6)[0].trend


@pytest.mark.unit
def test_trend_recovers_a_quadratic_field_and_predicts_new_points():
    rng = np.random.default_rng(0)
    p, pt = rng.uniform(-1200, 1200, (40, 3)), rng.uniform(-1300, 1300, (30, 3))
    trend = _trend_only(p, _sag_mm(p))
    assert np.all(trend.lo_mm <= pt.min(axis=0)) and np.all(trend.hi_mm >= pt.max(axis=0))    # inside the margin
    np.testing.assert_allclose(trend.predict(pt), _sag_mm(pt), atol=1e-6)


@pytest.mark.unit
def test_planar_poses_leave_the_normal_terms_small_and_finite():
    """Poses in one plane (z = 500 mm): the in-plane field is fitted, the terms in z stay at their prior's centre."""
    rng = np.random.default_rng(1)
    p = np.column_stack([rng.uniform(-1000, 1000, (60, 2)), np.full(60, 500.0)])
    trend = _trend_only(p, _sag_mm(p))
    pt = np.column_stack([rng.uniform(-1000, 1000, (20, 2)), np.full(20, 500.0)])
    np.testing.assert_allclose(trend.predict(pt), _sag_mm(pt), atol=1e-6)
    assert np.all(np.isfinite(trend.coef_mm)) and np.abs(trend.coef_mm).max() < 1.0


@pytest.mark.unit
def test_trend_is_held_at_the_box_face_beyond_its_data():
    """A quadratic grows without bound: 10 m out it is held at its value on the face of the widened box."""
    rng = np.random.default_rng(3)
    p = rng.uniform(-1000, 1000, (40, 3))
    trend = _trend_only(p, _sag_mm(p))
    far, face = np.array([[10000.0, 0.0, 0.0]]), np.array([[trend.hi_mm[0], 0.0, 0.0]])
    np.testing.assert_allclose(trend.predict(far), _sag_mm(face), atol=1e-6)
    assert abs(trend.predict(far)[0, 2]) < 0.15 * 1.3**2


@pytest.mark.unit
def test_the_share_a_geometric_fit_absorbed_goes_back_to_the_trend():
    """Residuals of a geometric fit that absorbed part of a sag (the sag less its projection on the identified
    parameters' columns): with the geometry's change, the layer predicts them at new poses; the trend alone cannot."""
    kin, model, q, p = _arm(150, 4)
    _, _, qt, pt = _arm(200, 5)
    A, At = geometry_columns(kin, GEOMETRY, q), geometry_columns(kin, GEOMETRY, qt)
    sag = _sag_mm(p, 0.5)
    absorbed = np.linalg.lstsq(A.reshape(-1, A.shape[2]), sag.reshape(-1), rcond=None)[0]
    rng = np.random.default_rng(4)
    e = sag - A @ absorbed + rng.normal(0, NOISE_AXIS_MM, sag.shape)
    truth = _sag_mm(pt, 0.5) - At @ absorbed
    kw = dict(noise_floor_mm=np.sqrt(3) * NOISE_AXIS_MM)
    joint = fit_trend_gpr(q, p, e, kinematics=kin, names=GEOMETRY, **kw)[0]
    alone = fit_trend_gpr(q, p, e, **kw)[0]
    left = lambda lay: np.sqrt(np.mean(np.sum((truth - lay.trend.predict(pt) - (0 if lay.shift is None else  # noqa
                                                 lay.shift.predict(qt))) ** 2, 1)))
    rms = np.sqrt(np.mean(np.sum(truth**2, 1)))
    print(f"residual {rms:.4f} mm; left by trend + geometry {left(joint):.4f}, by the trend alone {left(alone):.4f}")
    assert left(joint) < 0.15 * rms and left(joint) < 0.5 * left(alone)
    assert joint.shift.names == GEOMETRY and joint.shift.fit_rms_mm > 0
    together = joint.trend.predict(p) + joint.shift.predict(q)
    assert joint.together_rms_mm == pytest.approx(np.sqrt(np.mean(np.sum(together**2, 1))), rel=1e-9)


@pytest.mark.unit
def test_cv_errors_equal_a_fit_on_the_training_rows():
    kin, _, q, p = _arm(60, 2)
    e = _sag_mm(p) + np.random.default_rng(2).normal(0, NOISE_AXIS_MM, (60, 3))
    fold = kfold(60, 4, 0)
    layer, err = fit_trend_gpr(q, p, e, noise_floor_mm=0.03, fold=fold, kinematics=kin, names=GEOMETRY)
    A, F, centre = geometry_columns(kin, GEOMETRY, q), trend_features(p, p.mean(0)), p.mean(0)
    prior = _priors(kin, GEOMETRY)
    for k in range(4):                         # each fold's trend, geometry and GP fitted on its training rows alone
        tr, te = fold != k, fold == k
        d, c = _joint_solve(A[tr], F[tr], e[tr], prior, 0.03 / np.sqrt(3))
        t = QuadraticTrend.of(p[tr], centre, c)
        g = MultiOutputGP.fit_subset(q[tr], e[tr] - t.predict(p[tr]) - A[tr] @ d, n_restarts=0, max_iter=40,
                                     log_theta0=layer.gp.shared_log_theta, noise_floor_mm=0.03)
        np.testing.assert_allclose(err[te], e[te] - t.predict(p[te]) - A[te] @ d - g.predict(q[te]), atol=1e-9)
    assert isinstance(layer, TrendGPRResidual) and layer.gp.n_train == 60


@pytest.mark.unit
def test_round_trip_through_the_model_file_and_payload():
    kin, model, q, p = _arm(50, 3)
    pay = np.where(np.arange(50) < 25, 0.0, 12.0)
    layer, _ = fit_trend_gpr(q, p, _sag_mm(p), payload_kg=pay, noise_floor_mm=0.03, kinematics=kin, names=GEOMETRY)
    layer = layer.with_payload(12.0)
    again = CalibratedModel.from_dict(CalibratedModel(kin, layer).to_dict())
    qt = _poses(10, 4)
    pt = model.kinematic_smr_base(qt)
    assert type(again.residual) is TrendGPRResidual and again.residual.payload_kg == 12.0
    assert again.residual.shift.names == GEOMETRY and again.residual.together_rms_mm == layer.together_rms_mm
    np.testing.assert_allclose(again.residual.predict(qt, pt), layer.predict(qt, pt), atol=1e-12)
    np.testing.assert_allclose(again.smr_base(qt), model.kinematic_smr_base(qt) + layer.predict(qt, pt), atol=1e-9)
    with pytest.raises(ValueError, match="SMR positions"):
        layer.predict(qt)
    d = CalibratedModel(kin, layer).to_dict()
    d["residual"]["trend"]["terms"] = ["1", "x"]
    with pytest.raises(ValueError, match="trend terms"):
        CalibratedModel.from_dict(d)
    d = CalibratedModel(kin, layer).to_dict()
    d["residual"]["geometry_shift"]["parameters"][0] = "a9"
    with pytest.raises(ValueError, match="geometry shift"):
        CalibratedModel.from_dict(d)


@pytest.mark.system
def test_chosen_where_the_joint_layers_learn_little_from_few_poses():
    """60 poses with a reach sag: the CV keeps trend_gpr, and on 200 new poses it leaves much less of the sag than
    the GPR over the joints alone."""
    kin, model, q, _ = _arm(60, 5)
    rng = np.random.default_rng(5)
    qt = _poses(200, 6)
    p_tracker = model.smr_tracker(q) + (_sag_mm(model.kinematic_smr_base(q), 0.5)
                                        + rng.normal(0, NOISE_AXIS_MM, (60, 3))) @ kin.T_tracker_base[:3, :3].T
    got = choice.choose_layer(model, q, p_tracker, noise_floor_mm=np.sqrt(3) * NOISE_AXIS_MM)
    gpr = choice.fit_layer("gpr", model, q, p_tracker, noise_floor_mm=np.sqrt(3) * NOISE_AXIS_MM)
    pt = model.kinematic_smr_base(qt)
    truth = _sag_mm(pt, 0.5)
    left = lambda pred: np.sqrt(np.mean(np.sum((truth - pred) ** 2, 1)))  # noqa: E731
    print(f"sag {left(0 * truth):.4f} mm; left by trend_gpr {left(got.layer.predict(qt, pt)):.4f}, "
          f"by gpr {left(gpr.predict(qt, pt)):.4f}")
    assert got.kind == "trend_gpr"
    assert left(got.layer.predict(qt, pt)) < 0.5 * left(gpr.predict(qt, pt))


@pytest.mark.unit
def test_not_offered_beyond_its_row_cap(monkeypatch):
    _, model, q, _ = _arm(40, 7)
    monkeypatch.setattr(choice, "TREND_MAX_ROWS", 39)
    got = choice.choose_layer(model, q, model.smr_tracker(q), candidates=("gpr", "trend_gpr"), noise_floor_mm=0.03)
    assert "trend_gpr" not in got.cv and "gpr" in got.cv
    assert set(ParamLayout.of(model.kinematics).names) >= set(GEOMETRY)
