"""Multi-SMR calibration against the simulator's truth: one robot, one flange offset per SMR."""
import numpy as np
import pytest

from robocal.kinematics.frames import make_T
from robocal.kinematics.models import Kinematics
from robocal.multi_smr.calibration import calibrate_multi_smr, orientation_errors_arcsec, predict_multi
from robocal.measure.noise import TrackerUncertainty
from robocal.simulation.mock_cell import random_geometric_errors
from tests.cells import T_SEED000, irb2600

OFFSETS_NOMINAL = np.array([[80.0, 0.0, 60.0], [-40.0, 70.0, 60.0], [-40.0, -70.0, 60.0]])


def last_joint_gauge(nominal: Kinematics, truth: Kinematics) -> np.ndarray:
    """G (4, 4): with the last joint's parameters held at nominal, the offsets that reproduce the truth are
    G @ p_true (DH: T_n = Rz(q + theta) M, M = Tz(d) Tx(a) Rx(alpha) Ry(beta); G = M_nom^-1 Rz(dtheta) M_true)."""
    def M(k):
        i = k.n - 1
        ca, sa, cb, sb = np.cos(k.alpha_rad[i]), np.sin(k.alpha_rad[i]), np.cos(k.beta_rad[i]), np.sin(k.beta_rad[i])
        Rx = np.array([[1, 0, 0], [0, ca, -sa], [0, sa, ca]])
        Ry = np.array([[cb, 0, sb], [0, 1, 0], [-sb, 0, cb]])
        return make_T(Rx @ Ry, [k.a_mm[i], 0.0, k.d_mm[i]])
    dt = truth.theta_rad[-1] - nominal.theta_rad[-1]
    Rz = make_T(np.array([[np.cos(dt), -np.sin(dt), 0], [np.sin(dt), np.cos(dt), 0], [0, 0, 1]]), np.zeros(3))
    return np.linalg.inv(M(nominal)) @ Rz @ M(truth)


@pytest.mark.unit
def test_three_smr_offsets_recovered_and_orientation_reported():
    rng = np.random.default_rng(11)
    nominal = irb2600()
    truth = random_geometric_errors(nominal, rng).with_(T_tracker_base=T_SEED000)
    off_true = OFFSETS_NOMINAL + rng.normal(0.0, 0.3, (3, 3))             # a tool known to ~0.3 mm
    lo, hi = np.radians([-60, -40, -60, -120, -100, -180]), np.radians([60, 70, 40, 120, 100, 180])
    q = rng.uniform(lo, hi, (200, 6))
    tracker = TrackerUncertainty()
    P = predict_multi(truth, off_true, q)
    cov = tracker.covariance(P.reshape(-1, 3)).reshape(3, len(q), 3, 3)
    P = P + np.einsum("snij,snj->sni", np.linalg.cholesky(cov), rng.standard_normal(P.shape))
    cal, test = slice(0, 150), slice(150, 200)
    res = calibrate_multi_smr(nominal, q[cal], P[:, cal], OFFSETS_NOMINAL, cov[:, cal])
    G = last_joint_gauge(nominal, truth)
    expected = off_true @ G[:3, :3].T + G[:3, 3]
    err = np.linalg.norm(res.p_flange_smr_mm - expected, axis=1)
    ang = orientation_errors_arcsec(res.kinematics, res.p_flange_smr_mm, q[test], P[:, test])
    ang_true = orientation_errors_arcsec(truth, off_true, q[test], predict_multi(truth, off_true, q[test]))
    ang_noise = orientation_errors_arcsec(truth, off_true, q[test], P[:, test])   # the truth seen through the noise
    rms = lambda a: float(np.sqrt(np.mean(a**2)))  # noqa: E731
    pos = np.linalg.norm(P[:, test] - res.predict_tracker(q[test]), axis=2)
    print(f"per-SMR offset error vs truth (mm): {np.round(err, 4)}; test orientation error mean "
          f"{ang.mean():.1f} / RMS {np.sqrt(np.mean(ang**2)):.1f} / max {ang.max():.1f} arcsec; "
          f"test position RMS {np.sqrt(np.mean(pos**2)):.4f} mm; the truth's own orientation error through the "
          f"measurement noise RMS {rms(ang_noise):.1f} arcsec")
    assert res.converged and np.all(err <= 0.02)
    assert np.all(ang_true < 1e-3)                                        # the measure itself is exact on truth
    assert rms(ang) <= 1.2 * rms(ang_noise)                                # only the noise remains
    # the same data without the truth's tool: a wrong offset set is detected as an orientation error
    ang_bad = orientation_errors_arcsec(res.kinematics, OFFSETS_NOMINAL, q[test], P[:, test])
    assert np.mean(ang_bad) > 3 * np.mean(ang)


@pytest.mark.unit
def test_two_smr_calibration_fits_both():
    rng = np.random.default_rng(12)
    nominal = irb2600()
    truth = random_geometric_errors(nominal, rng).with_(T_tracker_base=T_SEED000)
    off_true = OFFSETS_NOMINAL[:2] + rng.normal(0.0, 0.3, (2, 3))
    q = rng.uniform(np.radians([-60, -40, -60, -120, -100, -180]), np.radians([60, 70, 40, 120, 100, 180]), (150, 6))
    P = predict_multi(truth, off_true, q) + rng.normal(0, 0.01, (2, 150, 3))
    res = calibrate_multi_smr(nominal, q, P, OFFSETS_NOMINAL[:2])
    G = last_joint_gauge(nominal, truth)
    err = np.linalg.norm(res.p_flange_smr_mm - (off_true @ G[:3, :3].T + G[:3, 3]), axis=1)
    assert res.converged and np.all(err <= 0.02)
    assert np.sqrt(np.mean(res.residual_tracker_mm ** 2)) < 0.02
