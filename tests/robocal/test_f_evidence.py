"""The in-sample evidence of the effect selection (``robocal.effects.select.F_LEVEL``, off by default: issue 32's
seventeenth protocol judges it; bench/bench_f_evidence.py switches it on): ``BlockedCV.nested_p`` is the nested
F-test of a dense least-squares reference."""
from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

import robocal.effects.select as select
from robocal.effects.cv import BlockedCV, Blocking

pytestmark = pytest.mark.unit


def _problem(extra_size: float, seed: int = 5, n: int = 40):
    """Design (n, 3, 5): 3 base columns and 2 extra; y from the base, extra_size x the extra columns and noise
    whitened by a per-point covariance (seeded)."""
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(n, 3, 5))
    L = np.tril(rng.normal(scale=0.2, size=(n, 3, 3))) + np.eye(3) * 0.5
    cov = L @ np.swapaxes(L, 1, 2)
    x = np.array([1.0, -2.0, 0.5, extra_size, -extra_size])
    y = A @ x + (L @ rng.normal(size=(n, 3, 1)))[:, :, 0]
    W = np.linalg.inv(np.linalg.cholesky(cov))
    return A, y, W


def _reference_p(A, y, W, base, extra) -> float:
    """F-test of the whitened stacked rows by np.linalg.lstsq and scipy's F distribution."""
    Aw = np.matmul(W, A).reshape(-1, A.shape[2])
    yw = np.matmul(W, y[:, :, None]).reshape(-1)

    def rss(cols):
        r = yw - Aw[:, cols] @ np.linalg.lstsq(Aw[:, cols], yw, rcond=None)[0]
        return r @ r
    full = list(base) + list(extra)
    k, dof = len(extra), len(yw) - len(full)
    return float(stats.f.sf(((rss(base) - rss(full)) / k) / (rss(full) / dof), k, dof))


@pytest.mark.parametrize("extra_size", [0.0, 0.05, 0.5])
def test_nested_p_is_the_dense_f_test(extra_size):
    A, y, W = _problem(extra_size)
    cv = BlockedCV(A, y, W, [Blocking("all", np.arange(len(A)) % 5)])
    got = cv.nested_p([0, 1, 2], [3, 4], rank_tol=1e-9)
    ref = _reference_p(A, y, W, [0, 1, 2], [3, 4])
    assert np.log(got) == pytest.approx(np.log(ref), rel=1e-3)     # the fits' ridge (1e-6) moves the last digits
    if extra_size == 0.5:
        assert got < 1e-10


def test_columns_inside_the_base_add_no_rank():
    A, y, W = _problem(0.5)
    A[:, :, 4] = 2.0 * A[:, :, 0] - A[:, :, 1]            # the second extra column is inside the base's span
    cv = BlockedCV(A, y, W, [Blocking("all", np.arange(len(A)) % 5)])
    assert cv.nested_p([0, 1, 2], [4]) == 1.0
    assert np.log(cv.nested_p([0, 1, 2], [3, 4])) == pytest.approx(np.log(_reference_p(A, y, W, [0, 1, 2], [3])),
                                                                   rel=1e-3)


def test_the_rule_is_off_by_default():
    assert select.F_LEVEL is None
