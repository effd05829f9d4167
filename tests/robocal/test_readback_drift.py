"""Read-back statistics (commanded vs read-back joints) and the nest drift model, on seeded synthetic data."""
import numpy as np
import pytest

from robocal.measure.drift import fit_drift
from robocal.measure.readback import prefer_commanded, readback_statistics

NESTS_MM = np.array([[1000.0, -2000.0, -1000.0], [3000.0, 500.0, -1100.0], [-500.0, 1500.0, -1050.0]])


def _moves(rng, n=400, j=6):
    return rng.uniform(-90, 90, (n, j))


@pytest.mark.unit
@pytest.mark.parametrize("seed", range(5))
def test_lagging_readback_prefers_commanded_joints(seed):
    rng = np.random.default_rng(seed)
    q_cmd = _moves(rng)
    move = np.vstack([np.zeros((1, 6)), np.diff(q_cmd, axis=0)])
    q_read = q_cmd - 0.0005 * move + rng.normal(0, 0.002, q_cmd.shape)
    s = readback_statistics(q_read, q_cmd)
    commanded, why = prefer_commanded(s)
    assert commanded and "last move" in why
    np.testing.assert_allclose(s.lag_deg_per_deg, -0.0005, atol=3e-5)
    assert np.all(s.corr < -0.9)


@pytest.mark.unit
@pytest.mark.parametrize("seed", range(5))
def test_readback_at_encoder_noise_keeps_readback_joints(seed):
    rng = np.random.default_rng(seed)
    q_cmd = _moves(rng)
    q_read = q_cmd + rng.normal(0, 0.0002, q_cmd.shape)   # encoder noise only
    commanded, why = prefer_commanded(readback_statistics(q_read, q_cmd))
    assert not commanded and "encoder noise" in why
    assert not prefer_commanded(readback_statistics(q_cmd, q_cmd))[0]


@pytest.mark.unit
def test_noisy_uncorrelated_readback_prefers_commanded():
    rng = np.random.default_rng(11)
    q_cmd = _moves(rng)
    commanded, why = prefer_commanded(readback_statistics(q_cmd + rng.normal(0, 0.02, q_cmd.shape), q_cmd))
    assert commanded and "3 x the encoder noise" in why


def _nest_readings(rng, v_mm_h, w_rad_h, rounds=20, hours=1.0, noise_mm=0.01, curve=lambda u: u):
    t = np.repeat(np.linspace(0.0, hours * 3600.0, rounds), 3) + np.tile([0.0, 10.0, 20.0], rounds)
    k = np.tile(np.arange(3), rounds)
    u = curve(t / 3600.0)[:, None]
    p = NESTS_MM[k] + u * (np.asarray(v_mm_h) + np.cross(w_rad_h, NESTS_MM[k])) + rng.normal(0, noise_mm, (len(t), 3))
    return t, k, p


@pytest.mark.unit
@pytest.mark.parametrize("seed", range(4))
def test_drift_model_recovers_the_displacement_at_workspace_points(seed):
    rng = np.random.default_rng(seed)
    v, w = np.array([0.1, -0.06, 0.04]), np.array([16e-6, -10e-6, 20e-6])
    curve = (lambda u: u) if seed % 2 == 0 else (lambda u: 0.6 * (1 - np.exp(-u / 0.4)))   # linear and settling
    t, k, p = _nest_readings(rng, v, w, curve=curve)
    model = fit_drift(t, k, p)
    assert model.degree >= 1
    pts = rng.uniform([1000, 1000, -1500], [3000, 4000, -500], (50, 3))      # robot workspace, tracker frame
    tt = rng.uniform(0, 3600, 50)
    truth = curve(tt / 3600.0)[:, None] * (v + np.cross(w, pts))
    err = model.displacement_mm(pts, tt) - truth
    err, truth = err - err.mean(axis=0), truth - truth.mean(axis=0)      # a constant offset is the registration's
    rms_truth = np.sqrt(np.mean(np.sum(truth**2, axis=1)))
    rms_err = np.sqrt(np.mean(np.sum(err**2, axis=1)))
    print(f"seed {seed}: drift RMS {rms_truth:.4f} mm, model error RMS {rms_err:.4f} mm, degree {model.degree}")
    assert rms_err < (0.3 if seed % 2 == 0 else 0.5) * rms_truth   # a settling curve is harder to follow


@pytest.mark.unit
@pytest.mark.parametrize("seed", range(6))
def test_no_drift_gives_no_correction(seed):
    rng = np.random.default_rng(100 + seed)
    t, k, p = _nest_readings(rng, np.zeros(3), np.zeros(3))
    model = fit_drift(t, k, p)
    pts = rng.uniform([1000, 1000, -1500], [3000, 4000, -500], (50, 3))
    shift = np.linalg.norm(model.displacement_mm(pts, np.full(50, 3600.0)), axis=1)
    assert model.degree == 0 or shift.max() < 0.02     # at most noise-level, never a made-up drift


@pytest.mark.unit
def test_too_few_rounds_means_no_drift_model():
    rng = np.random.default_rng(5)
    t, k, p = _nest_readings(rng, [0.1, 0, 0], np.zeros(3), rounds=2)
    assert fit_drift(t, k, p).degree == 0


@pytest.mark.unit
def test_rotation_is_taken_when_the_nests_show_one():
    rng = np.random.default_rng(21)
    t, k, p = _nest_readings(rng, np.zeros(3), np.array([0.0, 0.0, 40e-6]))   # 40 urad/h about z
    model = fit_drift(t, k, p)
    assert model.degree >= 1 and model.rotation
    np.testing.assert_allclose(model.rotation_rad(np.array([3600.0]))[0], [0, 0, 40e-6], atol=6e-6)
    assert set(model.cv_rms_mm) >= {"0", "1", "1+rotation"}
