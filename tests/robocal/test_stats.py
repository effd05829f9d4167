"""robocal.measure.stats against scipy.stats (the independent reference the module no longer imports)."""
from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from robocal.measure.stats import average_ranks, chi2_sf, f_isf, f_sf, t_sf, welch_t

pytestmark = pytest.mark.unit


def test_average_ranks_equal_rankdata_with_and_without_ties():
    rng = np.random.default_rng(11)
    for x in (rng.normal(size=200), rng.integers(0, 7, size=300).astype(float), np.array([3.0]), np.zeros(5),
              np.array([2.0, 1.0, 2.0, 1.0, 0.5])):
        np.testing.assert_array_equal(average_ranks(x), stats.rankdata(x))


def test_tail_probabilities_equal_scipy_stats():
    rng = np.random.default_rng(12)
    x = np.abs(rng.normal(0, 3, 50))
    for dof in (1, 3, 17, 250):
        np.testing.assert_allclose(t_sf(x, dof), stats.t.sf(x, dof), rtol=1e-12, atol=1e-300)
        np.testing.assert_allclose(chi2_sf(x * dof, dof), stats.chi2.sf(x * dof, dof), rtol=1e-12, atol=1e-300)
        for dfd in (4, 60, 3000):
            np.testing.assert_allclose(f_sf(x, dof, dfd), stats.f.sf(x, dof, dfd), rtol=1e-12, atol=1e-300)
            for alpha in (0.2, 0.05, 1e-3):
                assert f_isf(alpha, dof, dfd) == pytest.approx(stats.f.isf(alpha, dof, dfd), rel=1e-10)


def test_welch_t_equals_ttest_ind_with_unequal_variances():
    rng = np.random.default_rng(13)
    for n, m, shift, scale in ((6, 9, 0.0, 1.0), (40, 12, 0.7, 3.0), (200, 150, -0.1, 0.2)):
        a, b = rng.normal(shift, 1.0, n), rng.normal(0.0, scale, m)
        ref = stats.ttest_ind(a, b, equal_var=False)
        t, p = welch_t(a, b)
        assert t == pytest.approx(ref.statistic, rel=1e-12) and p == pytest.approx(ref.pvalue, rel=1e-10)
    t, p = welch_t(np.ones(5), np.ones(6))
    assert np.isnan(t) and np.isnan(p)
