"""The joint-error GP layer (robocal.layers.joint_gp): per-joint angle-error curves through the Jacobian, reduced-rank GP,
hyperparameters by marginal likelihood, CV from Gram differences. Independent references: finite differences of
the likelihood, a direct fit on the training rows, a brute-force exact GP with the same kernel."""
import numpy as np
import pytest

import robocal.layers.joint_gp as jg
from robocal.effects.cv import kfold
from robocal.layers.choice import choose_layer
from robocal.layers.calibrated_model import CalibratedModel
from tests.cells import irb2600

LO, HI = np.radians([-60, -40, -60, -90, -60, -90]), np.radians([60, 60, 30, 90, 60, 90])
NOISE_AXIS_MM = 0.02


def _poses(n, seed):
    return np.random.default_rng(seed).uniform(LO, HI, (n, 6))


def _truth_rad(q):
    """Angle errors (N, 6) rad: J1 order 14 (20"), J3 order 9 (15"), the others none."""
    f = np.zeros_like(q)
    f[:, 0] = 1.0e-4 * np.sin(14 * q[:, 0] + 0.3)
    f[:, 2] = 0.75e-4 * np.cos(9 * q[:, 2])
    return f


def _residuals(kin, q, rng):
    A = jg.joint_directions(kin, q, np.arange(6))
    return np.einsum("nij,nj->ni", A, _truth_rad(q)) + rng.normal(0, NOISE_AXIS_MM, (len(q), 3))


@pytest.mark.unit
def test_likelihood_gradient_matches_finite_differences():
    rng = np.random.default_rng(0)
    basis = jg.Basis(np.zeros(2), np.array([1.0, 0.7]), (12, 8))
    P, y = rng.normal(size=(60, 20)), rng.normal(size=60)
    g = jg.Gram(P.T @ P, P.T @ y, float(y @ y), 60)
    th = np.log([0.3, 0.5, 0.2, 0.4, 0.3])
    args = (g, basis.omega(), basis.owner(), 2, 0.04)
    f, grad = jg._nll(th, *args)
    num = [(jg._nll(th + h, *args)[0] - jg._nll(th - h, *args)[0]) / 2e-6 for h in np.eye(5) * 1e-6]
    np.testing.assert_allclose(grad, num, rtol=1e-5, atol=1e-6)


@pytest.mark.unit
def test_reduced_rank_kernel_approaches_the_exact_kernel():
    """Inside the domain, Phi diag(S) Phi^T is the SE kernel (the reduced-rank approximation's claim)."""
    basis = jg.Basis(np.zeros(1), np.array([1.5]), (64,))
    x = np.linspace(-0.8, 0.8, 41)[:, None]
    P = basis.phi(x)
    lam = jg._prior(np.log([2.0, 0.2, 1.0]), basis.omega(), basis.owner(), 1)[0]
    exact = 4.0 * np.exp(-0.5 * (x - x.T) ** 2 / 0.2**2)
    np.testing.assert_allclose(P @ np.diag(lam) @ P.T, exact, atol=2e-3 * 4.0)


@pytest.mark.system
def test_recovers_per_joint_cyclic_errors_and_predicts_new_poses():
    kin = irb2600()
    rng = np.random.default_rng(1)
    q, qt = _poses(300, 1), _poses(200, 2)
    layer, _ = jg.fit_joint_gp(kin, q, _residuals(kin, q, rng), noise_floor_mm=np.sqrt(3) * NOISE_AXIS_MM)
    A_t = jg.joint_directions(kin, qt, np.arange(6))
    truth_t = np.einsum("nij,nj->ni", A_t, _truth_rad(qt))
    err = truth_t - layer.predict(qt)
    rms_truth = np.sqrt(np.mean(np.sum(truth_t**2, 1)))
    rms_err = np.sqrt(np.mean(np.sum(err**2, 1)))
    print(f"structure {rms_truth:.4f} mm, left after the layer {rms_err:.4f} mm on 200 new poses")
    assert rms_err < 0.35 * rms_truth
    curves = layer.curves_rad(qt)
    j1 = list(layer.joints).index(0)
    assert np.corrcoef(curves[:, j1], _truth_rad(qt)[:, 0])[0, 1] > 0.9
    assert layer.noise_mm >= NOISE_AXIS_MM * (1 - 1e-9)


@pytest.mark.system
def test_cv_from_gram_differences_equals_a_fit_on_the_training_rows():
    kin = irb2600()
    rng = np.random.default_rng(3)
    q = _poses(120, 3)
    e = _residuals(kin, q, rng)
    fold = kfold(len(q), 4, 0)
    _, err = jg.fit_joint_gp(kin, q, e, 0.03, fold)
    joints = jg.used_joints(q)
    basis = jg.Basis.of(q[:, joints])
    for k in range(4):
        tr = fold != k
        g, _ = jg._grams(kin, q[tr], e[tr], joints, basis, None)
        direct = jg._layer(kin, joints, basis, g, 0.03**2 / 3, 0.03)
        np.testing.assert_allclose(err[~tr], e[~tr] - direct.predict(q[~tr]), atol=1e-6)


@pytest.mark.unit
def test_gram_in_row_blocks_equals_one_block(monkeypatch):
    kin = irb2600()
    q = _poses(50, 4)
    e = _residuals(kin, q, np.random.default_rng(4))
    joints = jg.used_joints(q)
    basis = jg.Basis.of(q[:, joints])
    whole, _ = jg._grams(kin, q, e, joints, basis, None)
    monkeypatch.setattr(jg, "BLOCK_ROWS", 7)
    blocks, _ = jg._grams(kin, q, e, joints, basis, None)
    np.testing.assert_allclose(blocks.PtP, whole.PtP, rtol=1e-10, atol=1e-9)
    np.testing.assert_allclose(blocks.Pty, whole.Pty, rtol=1e-10, atol=1e-9)


@pytest.mark.unit
def test_round_trip_and_zero_outside_the_calibrated_range():
    kin = irb2600()
    q = _poses(80, 5)
    layer, _ = jg.fit_joint_gp(kin, q, _residuals(kin, q, np.random.default_rng(5)), 0.03)
    model = CalibratedModel(kin, layer)
    again = CalibratedModel.from_dict(model.to_dict())
    qt = _poses(20, 6)
    np.testing.assert_allclose(again.residual.predict(qt), layer.predict(qt), atol=1e-12)
    np.testing.assert_allclose(again.residual.predict_std(qt), layer.predict_std(qt), atol=1e-12)
    far = qt.copy()
    far[:, :] = 3.0                                 # every joint far outside its calibrated range
    np.testing.assert_allclose(layer.predict(far), 0.0, atol=1e-12)


@pytest.mark.system
def test_not_kept_on_pure_noise():
    """Residuals that are noise at the floor (10 seeds, 150 poses): the one-SE rule never keeps the layer."""
    kin = irb2600()
    model = CalibratedModel(kin)
    kept = 0
    for seed in range(10):
        rng = np.random.default_rng(100 + seed)
        q = _poses(150, 100 + seed)
        p_tracker = model.smr_tracker(q) + rng.normal(0, NOISE_AXIS_MM, (150, 3)) @ kin.T_tracker_base[:3, :3].T
        choice = choose_layer(model, q, p_tracker, candidates=("joint_gp",), noise_floor_mm=np.sqrt(3) * NOISE_AXIS_MM)
        kept += choice.kind == "joint_gp"
    assert kept == 0


@pytest.mark.system
def test_diagnosis_names_the_joint_whose_curve_is_left_over():
    """Residuals from a J3 angle error of 9 periods per revolution only (plus noise): the diagnosis' joint curves put
    J3 first, with about the simulated amplitude (RMS of 0.75e-4 rad sin: 10.9 arcsec)."""
    from robocal.diagnose.leftover import joint_curves
    from robocal.diagnose.records import DiagnosisOptions
    kin = irb2600()
    rng = np.random.default_rng(7)
    q = _poses(250, 7)
    f = np.zeros_like(q)
    f[:, 2] = 0.75e-4 * np.sin(9 * q[:, 2])
    e_base = np.einsum("nij,nj->ni", jg.joint_directions(kin, q, np.arange(6)), f)
    e_base += rng.normal(0, NOISE_AXIS_MM, e_base.shape)
    model = CalibratedModel(kin)
    p_tracker = model.smr_tracker(q) + e_base @ kin.T_tracker_base[:3, :3].T
    curves, _ = joint_curves(DiagnosisOptions(), model, q, p_tracker, np.arange(len(q)), {}, np.sqrt(3) * NOISE_AXIS_MM)
    assert curves[0]["joint"] == 3
    assert curves[0]["rms_arcsec"] == pytest.approx(0.75e-4 / np.sqrt(2) * 206264.8, rel=0.25)
    assert curves[1]["rms_mm"] < 0.3 * curves[0]["rms_mm"]
