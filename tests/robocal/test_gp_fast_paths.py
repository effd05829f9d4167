"""The GP's fast paths compute what the plain formulas compute: potri inverse, shared-output likelihood with
negligible kernel entries set to 0, one kernel matrix for the predictions of all outputs."""
import numpy as np
import pytest
from scipy.linalg import cho_factor

from robocal.layers.gp import MultiOutputGP, cholesky_inverse, nlml_shared, se_ard, unpack

pytestmark = pytest.mark.unit


def plain_nlml_shared(log_theta, X, Y, jitter):
    """Eq. 9 summed over the columns of Y and its gradient, with the explicit inverse and an (m, m, d) tensor."""
    sf, sn, lam = unpack(log_theta)
    m, k = Y.shape
    d2 = np.sum(((X[:, None, :] - X[None, :, :]) / lam) ** 2, axis=2)
    K = sf**2 * np.exp(-0.5 * d2)
    H = K + (sn**2 + jitter) * np.eye(m)
    Hinv = np.linalg.inv(H)
    A = Hinv @ Y
    L = 0.5 * np.sum(Y * A) + 0.5 * k * np.linalg.slogdet(H)[1] + 0.5 * m * k * np.log(2 * np.pi)
    W = A @ A.T - k * Hinv
    dK = [2 * K, 2 * sn**2 * np.eye(m)] + [K * (X[:, None, i] - X[None, :, i]) ** 2 / lam[i] ** 2
                                          for i in range(len(lam))]
    return L, np.array([-0.5 * np.sum(W * D) for D in dK])


def test_cholesky_inverse_is_the_inverse():
    rng = np.random.default_rng(0)
    B = rng.normal(size=(60, 60))
    H = B @ B.T + 60 * np.eye(60)
    np.testing.assert_allclose(cholesky_inverse(cho_factor(H, lower=True)), np.linalg.inv(H), rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize("length", [0.8, 0.02])          # 0.02: most kernel entries far below 1e-50
def test_shared_likelihood_matches_the_plain_formulas(length):
    rng = np.random.default_rng(1)
    X = rng.uniform(-1, 1, (80, 4))
    X -= X.mean(0)
    Y = rng.normal(size=(80, 3))
    theta = np.log(np.r_[1.2, 0.3, np.full(4, length)])
    L, g = nlml_shared(theta, X, Y, 1e-10)
    L_ref, g_ref = plain_nlml_shared(theta, X, Y, 1e-10)
    assert L == pytest.approx(L_ref, rel=1e-10)
    np.testing.assert_allclose(g, g_ref, rtol=1e-8, atol=1e-8 * np.abs(g_ref).max())
    if length < 0.1:
        K = se_ard(X, X, np.full(4, length), 1.2)
        assert np.mean(K == 0) > 0.5 and np.all((K == 0) | (K > 1e-50))


def test_one_kernel_for_all_outputs_predicts_like_each_output_alone():
    rng = np.random.default_rng(2)
    X = rng.uniform(-1, 1, (150, 3))
    Y = np.column_stack([np.sin(2 * X[:, 0]), 3 * np.cos(X[:, 1]) + X[:, 2], 0.1 * X[:, 0] * X[:, 2]])
    gp = MultiOutputGP.fit_subset(X, Y + rng.normal(0, 0.01, Y.shape), hyper_points=100, max_iter=30)
    Xs = rng.uniform(-1, 1, (40, 3))
    each = np.stack([g.predict(Xs) for g in gp.models], axis=1)
    np.testing.assert_allclose(gp.predict(Xs), each, rtol=1e-10, atol=1e-12)
