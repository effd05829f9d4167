"""robocal.design.adaptive against direct computations: the variance each candidate removes at the task poses and the
information it brings, before and after rank updates, for the linear and the kernel terms."""
from __future__ import annotations

import numpy as np
import pytest

from robocal.design.adaptive import Coverage, KernelTerm, LinearTerm, choose_batch
from robocal.design.optimal import farthest_first

pytestmark = pytest.mark.unit


def _linear(seed=0, M=40, N=6, T=15, L=7):
    rng = np.random.default_rng(seed)
    return rng.normal(size=(M, 3, L)), rng.normal(size=(N, 3, L)), rng.normal(size=(T, 3, L))


def _direct_linear(A, done, B, scale):
    """(task variance, reduction (M,), information (M,)) by explicit inverses."""
    L = A.shape[2]
    H = np.einsum("tip,tiq->pq", B, B) / len(B)
    M0 = np.eye(L) + done.reshape(-1, L).T @ done.reshape(-1, L)
    var = lambda M: scale * np.trace(H @ np.linalg.inv(M))  # noqa: E731
    red = np.array([var(M0) - var(M0 + a.T @ a) for a in A])
    info = np.array([np.linalg.slogdet(M0 + a.T @ a)[1] - np.linalg.slogdet(M0)[1] for a in A])
    return var(M0), red, info


def test_linear_term_matches_explicit_inverses_before_and_after_picks():
    A, done, B = _linear()
    term = LinearTerm(A, done, B, scale_mm2=0.3)
    for step in range(3):
        var, red, info = _direct_linear(A, done, B, 0.3)
        assert term.task_variance() == pytest.approx(var, rel=1e-9)
        np.testing.assert_allclose(term.reduction(), red, rtol=1e-7, atol=1e-12)
        np.testing.assert_allclose(term.information(), info, rtol=1e-7, atol=1e-12)
        k = [3, 17, 29][step]
        term.add(k)
        done = np.concatenate([done, A[k:k + 1]])


def _direct_kernel(Xc, Xd, Xt, s2, r2):
    """(task variance, reduction (M,), information (M,)) of a unit-SE GP by explicit posterior covariances."""
    def k(a, b):
        return np.exp(-0.5 * np.sum((a[:, None] - b[None]) ** 2, axis=2))

    def post(a, b, D):
        if not len(D):
            return k(a, b)
        return k(a, b) - k(a, D) @ np.linalg.solve(k(D, D) + r2 * np.eye(len(D)), k(D, b))
    var = s2 * np.mean(np.diag(post(Xt, Xt, Xd)))
    red = np.array([var - s2 * np.mean(np.diag(post(Xt, Xt, np.vstack([Xd, x[None]])))) for x in Xc])
    info = 3 * np.log1p(np.diag(post(Xc, Xc, Xd)) / r2)
    return var, red, info


def test_kernel_term_matches_the_explicit_posterior_before_and_after_picks():
    rng = np.random.default_rng(1)
    Xc, Xd, Xt = rng.normal(size=(30, 3)), rng.normal(size=(5, 3)), rng.normal(size=(12, 3))
    term = KernelTerm(Xc, Xd, Xt, 0.02, 0.1)
    for k in (4, 11, 4):
        var, red, info = _direct_kernel(Xc, Xd, Xt, 0.02, 0.1)
        assert term.task_variance() == pytest.approx(var, rel=1e-8)
        np.testing.assert_allclose(term.reduction(), red, rtol=1e-6, atol=1e-14)
        np.testing.assert_allclose(term.information(), info, rtol=1e-6, atol=1e-12)
        term.add(k)                                  # a repeated pose is a second measurement of it
        Xd = np.vstack([Xd, Xc[k]])


def test_choose_batch_takes_the_largest_sum_and_reports_the_variance_it_leaves():
    A, done, B = _linear(2)
    avail = np.ones(len(A), bool)
    avail[:5] = False
    b = choose_batch([LinearTerm(A, done, B)], 4, avail, "i")
    assert len(set(b.chosen)) == 4 and not set(b.chosen) & set(range(5))
    _, red, _ = _direct_linear(A, done, B, 1.0)
    assert b.chosen[0] == int(np.argmax(np.where(avail, red, -np.inf)))
    assert np.all(np.diff(b.task_variance_mm2) < 0)
    var_after, _, _ = _direct_linear(A, np.concatenate([done, A[b.chosen]]), B, 1.0)
    assert b.task_variance_mm2[-1] == pytest.approx(var_after, rel=1e-8)
    with pytest.raises(ValueError):
        choose_batch([], 1, avail, "x")


def test_coverage_picks_continue_farthest_first_and_df_alternates_with_d():
    """"f" from the first pick of a farthest-first design continues that design; "df" takes the "d" pick, then the
    candidate farthest from the measured poses and that pick, in turn."""
    rng = np.random.default_rng(3)
    X = rng.normal(size=(60, 4))
    ff = farthest_first(X, 8)
    done = np.zeros(len(X), bool)
    done[ff[:2]] = True
    b = choose_batch([], 6, ~done, "f", Coverage(X, X[done]))
    np.testing.assert_array_equal(b.chosen, ff[2:])
    A, done_rows, B = _linear(4, M=60)
    d_only = choose_batch([LinearTerm(A, done_rows, B)], 1, np.ones(60, bool), "d").chosen[0]
    cover = Coverage(X, X[:3])
    b = choose_batch([LinearTerm(A, done_rows, B)], 2, np.ones(60, bool), "df", cover)
    assert b.chosen[0] == d_only
    dist = np.min(np.linalg.norm(X[:, None] - X[[0, 1, 2, d_only]][None], axis=2), axis=1)
    assert b.chosen[1] == int(np.argmax(dist)) and dist[b.chosen[1]] > 0
    with pytest.raises(ValueError, match="coverage"):
        choose_batch([], 1, np.ones(60, bool), "df")


def test_coverage_with_a_task_covers_the_task_poses_farthest_first():
    """With task poses among the candidates, "f" picks only task poses, each the one farthest from every pose
    measured or picked (farthest-first over the task); task poses off the candidates get the nearest candidate."""
    rng = np.random.default_rng(5)
    X = rng.uniform(-1.0, 1.0, size=(200, 3))
    done = np.zeros(len(X), bool)
    done[:5] = True
    in_task = np.flatnonzero(np.all(X[:, :2] > 0.2, axis=1) & ~done)
    b = choose_batch([], 6, ~done, "f", Coverage(X, X[done], X[in_task]))
    assert set(b.chosen) <= set(in_task)
    D = X[done]
    for k in b.chosen:                                   # each pick: the task pose farthest from all poses so far
        dist = np.min(np.linalg.norm(X[in_task][:, None] - D[None], axis=2), axis=1)
        assert k == in_task[int(np.argmax(dist))]
        D = np.vstack([D, X[k]])
    untasked = choose_batch([], 6, ~done, "f", Coverage(X, X[done])).chosen
    assert not set(untasked) <= set(in_task)             # without the task the picks leave the box
    target = np.array([[2.0, 2.0, 2.0]])                 # off the candidates: the nearest free candidate
    k = choose_batch([], 1, ~done, "f", Coverage(X, X[done], target)).chosen[0]
    assert k == int(np.argmin(np.where(~done, np.linalg.norm(X - target, axis=1), np.inf)))
    b = choose_batch([], len(in_task) + 3, ~done, "f", Coverage(X, X[done], X[in_task]))
    assert set(b.chosen[:len(in_task)]) == set(in_task)  # the task used up: farthest-first over every candidate
    D = np.vstack([X[done], X[b.chosen[:len(in_task)]]])
    assert b.chosen[len(in_task)] == int(np.argmax(np.min(np.linalg.norm(X[:, None] - D[None], axis=2), axis=1)))
