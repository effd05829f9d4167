import numpy as np
import pytest

from robocal.kinematics import gravity
from robocal.effects.bases import apply_effects, effect_regressor, every_effect
from robocal.kinematics.gravity import gravity_torques
from robocal.kinematics.ik import branch_signature, solve_ik, solve_on_branch
from robocal.kinematics.models import fk, smr_base
from robocal.measure.noise import (TrackerUncertainty, cartesian_to_spherical, noise_floor_mm, repeatability_sigma_mm,
                           spherical_to_cartesian)
from robocal.measure.stats import error_stats
from tests.cells import T_SEED000, irb2600, tool_frame

pytestmark = pytest.mark.unit


def test_spherical_covariance_matches_jacobian_form_and_monte_carlo():
    unc = TrackerUncertainty()
    p = spherical_to_cartesian(3000.0, np.radians(30), np.radians(70))
    cov = unc.covariance(p[None])[0]
    r, az, zen = cartesian_to_spherical(p)
    u_r, u_t = unc.sigmas_mm(r)
    J = np.array([[np.sin(zen) * np.cos(az), -r * np.sin(zen) * np.sin(az), r * np.cos(zen) * np.cos(az)],
                  [np.sin(zen) * np.sin(az), r * np.sin(zen) * np.cos(az), r * np.cos(zen) * np.sin(az)],
                  [np.cos(zen), 0, -r * np.sin(zen)]])
    np.testing.assert_allclose(cov, J @ np.diag([u_r**2, (u_t / (r * np.sin(zen)))**2, (u_t / r)**2]) @ J.T,
                               rtol=1e-9, atol=1e-15)
    rng = np.random.default_rng(0)
    n = 200_000
    samples = spherical_to_cartesian(r + rng.normal(0, u_r, n), az + rng.normal(0, u_t / (r * np.sin(zen)), n),
                                     zen + rng.normal(0, u_t / r, n))
    np.testing.assert_allclose(np.cov(samples.T).diagonal(), cov.diagonal(), rtol=0.02)


def test_noise_floor_is_the_rms_of_simulated_noise():
    unc = TrackerUncertainty()
    rng = np.random.default_rng(1)
    p = rng.uniform([3000, -500, -500], [5000, 500, 500], (2000, 3))
    L = np.linalg.cholesky(unc.covariance(p))
    s = repeatability_sigma_mm(0.04)
    noise = np.einsum("nij,nj->ni", L, rng.standard_normal(p.shape)) + rng.normal(0, s, p.shape)
    assert error_stats(noise).rms_mm == pytest.approx(noise_floor_mm(p, unc, 0.04), rel=0.03)


def test_repeatability_conversion_against_monte_carlo():
    rng = np.random.default_rng(2)
    x = rng.normal(0, 1.0, (200_000, 3))
    l = np.linalg.norm(x, axis=1)
    assert repeatability_sigma_mm(l.mean() + 3 * l.std()) == pytest.approx(1.0, rel=0.01)


@pytest.mark.parametrize("effect", every_effect(6), ids=lambda e: e.name + "".join(map(str, e.joints)))
def test_effect_regressor_is_the_linearisation_of_the_simulation(effect):
    kin = irb2600().with_(T_tracker_base=T_SEED000, p_flange_smr_mm=[40.0, 30.0, 60.0])
    rng = np.random.default_rng(3)
    q = rng.uniform(-1, 1, (20, 6))
    meta = {"t_s": np.linspace(0, 7200, 20), "payload_kg": rng.choice([0.0, 12.0], 20),
            "approach": rng.choice([-1.0, 1.0], (20, 6)), "temp_c": None, "order": np.arange(20.0) * 5.0,
            "move": rng.uniform(-1.0, 1.0, (20, 6)), "prev_move": rng.uniform(-1.0, 1.0, (20, 6))}
    params = np.array(effect.typical)
    base = apply_effects(kin, q, meta, [])
    exact = apply_effects(kin, q, meta, [(effect, params)]) - base
    linear = effect_regressor(kin, q, meta, effect) @ params
    assert np.max(np.abs(exact)) > 1e-3, "typical magnitude should be visible"
    np.testing.assert_allclose(linear, exact, atol=2e-3 * np.max(np.abs(exact)) + 1e-6)


def test_gravity_torques_signs():
    kin = irb2600()
    q = np.radians([[0, 0, 0, 0, 0, 0], [0, 30, 0, 0, 0, 0]])
    tau = gravity_torques(kin, q, [0, 35, 40, 12, 4, 1], np.array([0.0, 0.0]))
    assert abs(tau[0, 0]) < 1e-9                           # J1 axis is vertical
    assert abs(tau[1, 1]) > abs(tau[0, 1])                 # leaning forward loads J2 more


def _frames_reference(kin, qk):
    """4x4 frames of one pose, multiplied one by one: frames[i] turns with joint i - 1 (frames[0] the base), its z
    joint i's axis; the last one the flange."""
    T, frames = np.eye(4), []
    for i in range(kin.n):
        frames.append(T.copy())
        th, d, a, al = qk[i] + kin.theta_rad[i], kin.d_mm[i], kin.a_mm[i], kin.alpha_rad[i]
        Rz = np.array([[np.cos(th), -np.sin(th), 0, 0], [np.sin(th), np.cos(th), 0, 0], [0, 0, 1, d], [0, 0, 0, 1]])
        Tx = np.array([[1, 0, 0, a], [0, np.cos(al), -np.sin(al), 0], [0, np.sin(al), np.cos(al), 0], [0, 0, 0, 1]])
        b = kin.beta_rad[i]
        Ry = np.array([[np.cos(b), 0, np.sin(b), 0], [0, 1, 0, 0], [-np.sin(b), 0, np.cos(b), 0], [0, 0, 0, 1]])
        T = T @ Rz @ Tx @ Ry
    return frames + [T]


def _gravity_torques_reference(kin, q, link_masses_kg, payload_kg, cog_flange_mm, g_base):
    """Independent reference: per pose, joint and hanging body, the lever (body - joint origin) x weight about the
    joint axis, from 4x4 frames multiplied one by one (Python loops: small N only)."""
    out = np.zeros(q.shape)
    g = np.asarray(g_base, float) / np.linalg.norm(g_base) * 9.80665
    for k, qk in enumerate(q):
        frames = _frames_reference(kin, qk)
        origins = [f[:3, 3] for f in frames]
        T = frames[-1]
        p_pay = T[:3, :3] @ np.asarray(cog_flange_mm, float) + T[:3, 3]
        for j in range(kin.n):
            o_j, z_j = frames[j][:3, 3], frames[j][:3, 2]
            bodies = [(link_masses_kg[m], 0.5 * (origins[m] + origins[m + 1])) for m in range(j, kin.n)]
            bodies.append((payload_kg[k], p_pay))
            out[k, j] = sum(m * np.dot(np.cross(c - o_j, g), z_j) for m, c in bodies) / 1000.0
    return out


def test_link_mass_torques_span_any_mass_fixed_on_the_links_and_the_lever_points_do_not():
    """Point masses anywhere on links 2-6 (their centres off the roll axes, fixed in each link's 4x4 frame of the
    reference): their gravity torques about J2 and J3 are a combination of ``link_mass_torques``' columns (to
    rounding); the lever form's points (``lever_torques``) leave a visible part of them."""
    kin = irb2600()
    rng = np.random.default_rng(12)
    q = np.radians(rng.uniform(-90, 90, (60, 6)))
    g = np.array([0.0, 0.0, -9.80665])
    bodies = [(m, rng.uniform(0.5, 20.0), rng.uniform(-150.0, 150.0, 3)) for m in range(1, 6) for _ in range(2)]
    tau = np.zeros((len(q), 2))
    for k, qk in enumerate(q):
        frames = _frames_reference(kin, qk)
        for col, j in enumerate((1, 2)):
            o_j, z_j = frames[j][:3, 3], frames[j][:3, 2]
            for link, mass, p_link in bodies:
                if link >= j:
                    p = frames[link + 1][:3, :3] @ p_link + frames[link + 1][:3, 3]
                    tau[k, col] += mass * np.dot(np.cross(p - o_j, g), z_j) / 1000.0
    links = gravity.link_mass_torques(kin, q, (2, 3))
    levers = gravity.lever_torques(kin, q, (2, 3))

    def left(cols, t):
        return np.linalg.norm(t - cols @ np.linalg.lstsq(cols, t, rcond=None)[0]) / np.linalg.norm(t)
    for col, j in enumerate((2, 3)):
        assert left(links[j][0], tau[:, col]) < 1e-9
        assert left(levers[j][0], tau[:, col]) > 1e-3


@pytest.mark.parametrize("g_base", [(0.0, 0.0, -1.0), (0.3, -1.0, 0.2)])
def test_gravity_torques_equal_an_independent_reference_in_one_block_and_in_row_blocks(monkeypatch, g_base):
    """The vectorised torque (cumulative first moments) = lever x weight summed body by body, per pose; and the
    row-blocked path (``CHAIN_ROWS`` forced to 7) gives the same numbers as one block."""
    kin = irb2600()
    rng = np.random.default_rng(11)
    q = np.radians(rng.uniform(-90, 90, (30, 6)))
    masses, pay, cog = [0, 35, 40, 12, 4, 1], rng.uniform(0, 5, 30), [10.0, -5.0, 40.0]
    tau = gravity_torques(kin, q, masses, pay, cog, g_base)
    np.testing.assert_allclose(tau, _gravity_torques_reference(kin, q, masses, pay, cog, g_base), rtol=1e-10,
                               atol=1e-9)
    monkeypatch.setattr(gravity, "CHAIN_ROWS", 7)      # the torque model lives in robocal.kinematics.gravity
    np.testing.assert_array_equal(gravity_torques(kin, q, masses, pay, cog, g_base), tau)


def test_ik_reaches_targets_to_sub_micrometre():
    kin = irb2600()
    rng = np.random.default_rng(4)
    q_true = rng.uniform(np.radians([-60, -20, -40, -90, 20, -90]), np.radians([60, 60, 30, 90, 90, 90]), (200, 6))
    T = fk(kin, q_true)
    res = solve_ik(kin, smr_base(kin, q_true), T[:, :3, :3], q_true + rng.normal(0, 0.05, q_true.shape))
    assert res.converged.all()
    assert res.pos_err_mm.max() < 1e-5 and res.rot_err_rad.max() < 1e-8


def test_solve_on_branch_keeps_one_configuration():
    kin = irb2600()
    q_ref = np.radians([0, 0, 0, 0, 45, 0])
    targets = np.random.default_rng(5).uniform([600, -700, 500], [1200, 700, 1500], (200, 3))
    q, ok = solve_on_branch(kin, targets, tool_frame([1, 0, -0.7]), q_ref)
    assert ok.mean() > 0.8
    assert np.all(branch_signature(kin, q[ok]) == branch_signature(kin, q_ref[None]))
    np.testing.assert_allclose(smr_base(kin, q[ok]), targets[ok], atol=1e-5)
