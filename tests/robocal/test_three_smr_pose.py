"""Three-SMR tool (seed 003 §2-3): spherical error propagation, measurement adjustment, 3-point pose, estimator."""
import numpy as np
import pytest

from robocal.kinematics.frames import make_T, rotvec_to_matrix, transform_points
from robocal.multi_smr.three_smr_pose import (MultiSMRPoseEstimator, adjust_points, conditions, euler_xyz_deg, fit_points_pose,
                                    measured_covariance, nominal_points, orientation_error_deg, pair_distances,
                                    seed003_tool, spherical_covariance, spherical_jacobian, tracker_spherical_sigmas,
                                    weight_matrix_inverse)
from robocal.measure.noise import TrackerUncertainty, cartesian_to_spherical, spherical_to_cartesian
from robocal.simulation.payload import HeavyPayloadCell, irb4600, random_configurations
from robocal.simulation.mock_cell import random_geometric_errors

pytestmark = pytest.mark.unit

TOOL = seed003_tool()


def noisy_triangles(n, rng, sigma=0.05):
    """n copies of the tool's triangle, rigidly moved into the tracker's working volume, with anisotropic
    per-point covariances and noise drawn from them."""
    T = make_T(rotvec_to_matrix(rng.normal(0, 1, (n, 3))), rng.uniform([2000, -1500, -500], [4000, 1500, 500], (n, 3)))
    true = transform_points(T[:, None], TOOL.p_flange_mm[None])
    A = rng.normal(0, sigma, (n, 3, 3, 3))
    cov = A @ np.swapaxes(A, -1, -2) + (0.2 * sigma) ** 2 * np.eye(3)
    noise = np.einsum("nkij,nkj->nki", np.linalg.cholesky(cov), rng.standard_normal((n, 3, 3)))
    return true, true + noise, cov


def test_spherical_propagation_matches_monte_carlo_and_the_beam_frame_form():
    rng = np.random.default_rng(0)
    p = np.array([[3000.0, 1000.0, -500.0], [-1500.0, 2500.0, 1200.0]])
    sH, sV, sr = 2.4e-5, 1.0e-5, 0.01                                  # ~5", 2", 10 um: strongly anisotropic
    D = spherical_covariance(p, sH, sV, sr)
    for i in range(len(p)):
        r, H, V = cartesian_to_spherical(p[i])
        n = 200_000
        s = spherical_to_cartesian(r + rng.normal(0, sr, n), H + rng.normal(0, sH, n), V + rng.normal(0, sV, n))
        mc = np.cov(s.T)
        assert np.linalg.norm(mc - D[i]) / np.linalg.norm(D[i]) < 0.05
        np.testing.assert_allclose(np.diag(mc), np.diag(D[i]), rtol=0.05)
        corr = D[i] / np.sqrt(np.outer(np.diag(D[i]), np.diag(D[i])))
        np.testing.assert_allclose(mc / np.sqrt(np.outer(np.diag(mc), np.diag(mc))), corr, atol=0.02)
    tracker = TrackerUncertainty()
    q = rng.uniform(-4000, 4000, (20, 3))
    np.testing.assert_allclose(measured_covariance(tracker, q), tracker.covariance(q), rtol=1e-9, atol=1e-18)
    sH2, sV2, _ = tracker_spherical_sigmas(tracker, q)
    assert np.all(sH2 >= sV2)                                           # azimuth angle = arc / (rho sinV)


def test_spherical_jacobian_matches_finite_differences():
    p = np.array([[2500.0, -800.0, 300.0]])
    r, H, V = cartesian_to_spherical(p[0])
    h = 1e-7
    fd = np.stack([(spherical_to_cartesian(r + dr, H + dH, V + dV) - spherical_to_cartesian(r - dr, H - dH, V - dV)) / (2 * h)
                   for dH, dV, dr in h * np.eye(3)], axis=1)
    np.testing.assert_allclose(spherical_jacobian(p)[0], fd, rtol=1e-6, atol=1e-6)


def test_adjusted_points_satisfy_the_distance_constraints():
    rng = np.random.default_rng(1)
    true, meas, cov = noisy_triangles(200, rng)
    adj = adjust_points(meas, cov, TOOL.d_mm, TOOL.sigma_d_mm())
    assert adj.converged.all() and adj.iterations <= 6
    assert np.max(np.abs(pair_distances(adj.points_mm) - adj.distances_mm)) < 1e-9
    np.testing.assert_allclose(adj.residual_mm, 0.0, atol=1e-9)
    assert np.max(np.abs(conditions(np.concatenate([adj.points_mm.reshape(-1, 9), adj.distances_mm], 1),
                                    with_jacobian=False))) < 1e-6   # mm^2
    # the CMM distances (sigma ~3 um) move far less than the points (sigma ~50 um)
    assert np.abs(adj.distances_mm - TOOL.d_mm).max() < 0.1 * np.abs(adj.corrections[:, :9]).max()
    # statistically: the adjustment brings the points closer to the truth, and sigma0_post ~ 1
    before = np.linalg.norm(meas - true, axis=2).mean()
    after = np.linalg.norm(adj.points_mm - true, axis=2).mean()
    assert after < before
    assert 0.8 < np.sqrt(np.mean(adj.sigma0_post**2)) < 1.2


def test_adjustment_is_the_weighted_least_squares_solution():
    """First step = the seed's closed form (eq. 24-25); at convergence Delta = P^-1 C^T lambda (first-order
    optimality); the unit-weight sigma0 cancels; the point with the larger variance takes the correction."""
    rng = np.random.default_rng(2)
    _, meas, cov = noisy_triangles(5, rng)
    Lm = np.concatenate([meas.reshape(-1, 9), np.broadcast_to(TOOL.d_mm, (5, 3))], 1)
    Q = weight_matrix_inverse(cov, TOOL.sigma_d_mm())
    G, C = conditions(Lm)
    lam = -np.linalg.solve(C @ Q @ np.swapaxes(C, 1, 2), G[..., None])
    one_step = (Q @ np.swapaxes(C, 1, 2) @ lam)[..., 0]
    np.testing.assert_allclose(adjust_points(meas, cov, TOOL.d_mm, TOOL.sigma_d_mm(), max_iter=1).corrections,
                               one_step, atol=1e-12)
    adj = adjust_points(meas, cov, TOOL.d_mm, TOOL.sigma_d_mm())
    _, C_a = conditions(np.concatenate([adj.points_mm.reshape(-1, 9), adj.distances_mm], 1))
    B = Q @ np.swapaxes(C_a, 1, 2)                                    # (N, 12, 3)
    lam_fit = np.linalg.lstsq(B[0], adj.corrections[0], rcond=None)[0]
    np.testing.assert_allclose(B[0] @ lam_fit, adj.corrections[0], atol=1e-12)
    again = adjust_points(meas, cov, TOOL.d_mm, TOOL.sigma_d_mm(), sigma0=3.7)
    np.testing.assert_allclose(again.points_mm, adj.points_mm, atol=1e-12)
    np.testing.assert_allclose(again.sigma0_post, adj.sigma0_post, rtol=1e-9)
    iso = np.broadcast_to(np.eye(3), (1, 3, 3, 3)).copy() * 1e-6
    iso[0, 2] *= 1e4                                                 # SMR 3 100x less precise
    pts = TOOL.p_flange_mm[None] + np.array([[[0, 0, 0], [0, 0, 0], [0.05, 0.02, 0]]])
    a = adjust_points(pts, iso, TOOL.d_mm, TOOL.sigma_d_mm())
    moved = np.linalg.norm(a.corrections[0, :9].reshape(3, 3), axis=1)
    assert moved[2] > 100 * max(moved[0], moved[1])


def test_three_point_pose_and_euler_angles():
    rng = np.random.default_rng(3)
    R = rotvec_to_matrix(rng.normal(0, 1, (10, 3)))
    T = make_T(R, rng.uniform(-3000, 3000, (10, 3)))
    pts = transform_points(T[:, None], TOOL.p_flange_mm[None])
    np.testing.assert_allclose(fit_points_pose(TOOL.p_flange_mm, pts), T, atol=1e-9)
    ex, ey, ez = np.radians([0.01, -0.02, 0.03])
    Rz = np.array([[np.cos(ez), -np.sin(ez), 0], [np.sin(ez), np.cos(ez), 0], [0, 0, 1]])
    Ry = np.array([[np.cos(ey), 0, np.sin(ey)], [0, 1, 0], [-np.sin(ey), 0, np.cos(ey)]])
    Rx = np.array([[1, 0, 0], [0, np.cos(ex), -np.sin(ex)], [0, np.sin(ex), np.cos(ex)]])
    np.testing.assert_allclose(euler_xyz_deg((Rz @ Ry @ Rx)[None])[0], [0.01, -0.02, 0.03], atol=1e-12)
    assert TOOL.d_mm == pytest.approx([144.833, 210.149, 210.684])
    np.testing.assert_allclose(pair_distances(TOOL.p_flange_mm[None])[0], TOOL.d_mm, atol=1e-9)


def test_estimator_predicts_the_two_smrs_and_the_pose():
    """Offline GPR models of SMRs 2, 3 on a heavy-payload cell, then online estimates at new configurations."""
    nominal = irb4600(p_flange_smr_mm=TOOL.p_flange_mm[0])
    cell = HeavyPayloadCell(random_geometric_errors(nominal, np.random.default_rng(4)))
    rng = np.random.default_rng(5)
    q_off, q_on = random_configurations(120, seed=6), random_configurations(30, seed=7)
    m_off, _ = cell.measure(q_off, 46.05, TOOL.p_flange_mm, rng)
    m_on, actual = cell.measure(q_on, 46.05, TOOL.p_flange_mm, rng)
    nominal_reg = nominal.with_(T_tracker_base=cell.truth.T_tracker_base)
    est = MultiSMRPoseEstimator.fit(nominal_reg, TOOL, q_off, m_off[:, 1], m_off[:, 2], n_restarts=0)
    pe = est.estimate(q_on, m_on[:, 0])
    pre = np.linalg.norm(pe.points_mm[:, 1:] - actual[:, 1:], axis=2).mean()
    adj = np.linalg.norm(pe.adjusted_mm[:, 1:] - actual[:, 1:], axis=2).mean()
    raw = np.linalg.norm(nominal_points(nominal_reg, TOOL, q_on)[:, 1:] - actual[:, 1:], axis=2).mean()
    print(f"SMRs 2, 3 on 30 new configurations: nominal model {raw:.3f} mm, GPR {pre:.4f} mm, adjusted {adj:.4f} mm")
    assert pre < 0.2 * raw and adj < 1.05 * pre
    np.testing.assert_allclose(pair_distances(pe.adjusted_mm), pe.adjustment.distances_mm, atol=1e-9)
    assert np.all(pe.gpr_std_mm > 0) and pe.gpr_std_mm.mean() < 3 * pre
    T_true = fit_points_pose(TOOL.p_flange_mm, actual)
    err = np.linalg.norm(orientation_error_deg(pe.T_tracker_flange, T_true), axis=1)
    T_nom = fit_points_pose(TOOL.p_flange_mm, nominal_points(nominal_reg, TOOL, q_on))
    err_nom = np.linalg.norm(orientation_error_deg(T_nom, T_true), axis=1)
    print(f"orientation error: nominal model {err_nom.mean():.3f} deg, estimated pose {err.mean():.4f} deg")
    assert err.mean() < 0.2 * err_nom.mean()
    no_adj = est.estimate(q_on, m_on[:, 0], adjust=False)
    assert no_adj.adjusted_mm is None and no_adj.adjustment is None
    np.testing.assert_allclose(no_adj.points_mm, pe.points_mm)
