"""Inducing-point GP (robocal/layers/sparse_gp.py): equal to the exact GP when the inducing inputs are the training inputs,
close to it with few inducing inputs, bounded memory on many points, JSON round trip."""
import json
import tracemalloc

import numpy as np
import pytest

from robocal.effects.cv import kfold
from robocal.layers.gp_layer import GPRResidual
from robocal.layers.gp import MultiOutputGP
from robocal.layers.choice import fit_gp, gp_cv_errors
from robocal.layers.sparse_gp import EXACT_MAX_POINTS, INDUCING_POINTS, SparseGP

LO, HI = np.radians([-100, -60, -100, -150, -100, -150]), np.radians([100, 90, 40, 150, 100, 150])


def field(X):
    """A smooth residual (mm, 3 axes) of 6 joint angles (rad)."""
    return np.column_stack([0.05 * np.sin(1.5 * X[:, 1] + X[:, 2]), 0.04 * np.cos(X[:, 0]) * X[:, 3],
                            0.03 * X[:, 4] ** 2])


def data(n, seed, noise=0.01):
    rng = np.random.default_rng(seed)
    X = rng.uniform(LO, HI, (n, 6))
    return X, field(X) + rng.normal(0.0, noise, (n, 3))


def rms(e):
    return float(np.sqrt(np.mean(np.sum(np.square(e), axis=1))))


@pytest.mark.system
def test_inducing_inputs_at_the_training_inputs_give_the_exact_gp():
    X, Y = data(250, 0)
    Xt, _ = data(400, 1)
    exact = MultiOutputGP.fit_subset(X, Y, seed=3)
    sparse = SparseGP.fit(X, Y, seed=3, Z=X)               # same hyperparameters (all 250 points fit them)
    np.testing.assert_allclose(sparse.shared_log_theta, exact.shared_log_theta, rtol=1e-12)
    scale = rms(exact.predict(Xt))
    assert rms(sparse.predict(Xt) - exact.predict(Xt)) < 1e-4 * scale
    (_, s_sparse), (_, s_exact) = sparse.predict_std(Xt), exact.predict_std(Xt)
    np.testing.assert_allclose(s_sparse, s_exact, rtol=1e-3)


@pytest.mark.system
def test_few_inducing_inputs_agree_with_the_exact_gp_within_a_tenth_of_its_error():
    """1500 points, 300 inducing inputs: the two predictions differ by less than 10 % of the exact GP's own
    held-out error (stated tolerance of the approximation), and both learn the field."""
    X, Y = data(1500, 2)
    Xt, _ = data(2000, 3)
    exact = MultiOutputGP.fit_subset(X, Y, seed=0)
    sparse = SparseGP.fit(X, Y, n_inducing=300, seed=0)
    err_exact, err_sparse = rms(exact.predict(Xt) - field(Xt)), rms(sparse.predict(Xt) - field(Xt))
    diff = rms(sparse.predict(Xt) - exact.predict(Xt))
    print(f"exact held-out {err_exact:.5f} mm, sparse {err_sparse:.5f} mm, difference {diff:.5f} mm "
          f"(signal {rms(field(Xt)):.4f} mm)")
    assert err_exact < 0.3 * rms(field(Xt))
    assert diff < 0.1 * err_exact


@pytest.mark.system             # 20 000+ points: a memory study
def test_many_points_take_the_inducing_point_path_in_bounded_memory():
    """20 000 points: the layer's GP is the inducing-point one, and fitting it plus its 5-fold CV peaks at
    O(N m) memory (below N m doubles; the exact GP's kernel alone would be N^2 doubles, 3.2 GB)."""
    n = 20_000
    assert n > EXACT_MAX_POINTS
    X, Y = data(n, 4)
    fold = kfold(n, 5, 0)
    tracemalloc.start()
    try:
        gp = fit_gp(X, Y, noise_floor_mm=0.017)
        err = gp_cv_errors(gp, X, Y, fold)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert isinstance(gp, SparseGP) and len(gp.Z) == INDUCING_POINTS and gp.n_train == n
    m = len(gp.Z)
    print(f"N {n}, m {m}: peak {peak / 2**20:.1f} MiB (N m doubles {n * m * 8 / 2**20:.0f} MiB, "
          f"N^2 doubles {n * n * 8 / 2**30:.1f} GiB); CV RMS {rms(err):.4f} mm")
    assert peak < n * m * 8
    assert rms(err) < 1.3 * 0.01 * np.sqrt(3)              # CV close to the noise: the field is learnt


@pytest.mark.unit
def test_sparse_layer_round_trips_through_json():
    X, Y = data(800, 5)
    layer = GPRResidual(SparseGP.fit(X, Y, n_inducing=100, seed=1, noise_floor_mm=0.02))
    back = GPRResidual.from_dict(json.loads(json.dumps(layer.to_dict())))
    assert isinstance(back.gp, SparseGP) and back.gp.noise_floor_mm == 0.02
    Xt, _ = data(50, 6)
    np.testing.assert_allclose(back.predict(Xt), layer.predict(Xt), atol=1e-12)
    np.testing.assert_allclose(back.predict_std(Xt), layer.predict_std(Xt), rtol=1e-9)
