"""Error statistics of seed 000 Table 3: max / mean / RMS of the 3-D position error; the tests the calibration and
the diagnosis decide with (paired t, Wilcoxon signed rank, Welch t) and the tail probabilities of the t, chi^2 and
F distributions they read.

The distributions come from ``scipy.special`` (the functions ``scipy.stats`` itself calls), imported where they
are evaluated: ``scipy.stats`` would cost about 0.45 s of the start of every command that calibrates, more than the
tests take in a whole calibration, and a command that only reads reports (``report``) loads neither.
"""
from __future__ import annotations

from dataclasses import dataclass, asdict

import numpy as np


@dataclass(frozen=True)
class ErrorStats:
    """Statistics of 3-D position errors in mm over n points."""
    max_mm: float
    mean_mm: float
    rms_mm: float
    n: int

    def to_dict(self) -> dict:
        return asdict(self)


def error_stats(err_mm: np.ndarray) -> ErrorStats:
    """err_mm (N, 3) measured - predicted -> ErrorStats of |err| (NaN stats for N = 0)."""
    e = np.linalg.norm(np.atleast_2d(np.asarray(err_mm, float)).reshape(-1, 3), axis=1)
    if len(e) == 0:
        return ErrorStats(float("nan"), float("nan"), float("nan"), 0)
    return ErrorStats(float(e.max()), float(e.mean()), float(np.sqrt(np.mean(e**2))), int(len(e)))


# significance of a cross-validated gain: per-point squared errors of two models on the same held-out points
SIGNIFICANT_T = 3.0          # one-sided paired t (p ~ 1e-3 under the null)
SIGNIFICANT_GAIN = 0.02      # and at least 2 % lower CV RMS
# a choice made for prediction alone (a residual layer, which claims no cause): the one-standard-error rule
# (Hastie, Tibshirani & Friedman, ESL 7.10): the richer model when its CV error is lower by more than one standard
# error of the paired difference, and by at least SIGNIFICANT_GAIN
ONE_SE_T = 1.0


@dataclass(frozen=True)
class PairedGain:
    """CV RMS (mm) of a base and a candidate model on the same held-out points, the relative RMS gain
    1 - rms_cand / rms_base, and the paired t statistic of the per-point squared-error differences."""
    rms_base_mm: float
    rms_cand_mm: float
    gain: float
    t: float
    n: int

    @property
    def significant(self) -> bool:
        """Evidence for a claim (an effect, structure): t > 3 and a gain above 2 %."""
        return self.t > SIGNIFICANT_T and self.gain > SIGNIFICANT_GAIN

    @property
    def beats_one_se(self) -> bool:
        """Better for prediction by the one-standard-error rule: t > 1 and a gain above 2 %."""
        return self.t > ONE_SE_T and self.gain > SIGNIFICANT_GAIN

    def to_dict(self) -> dict:
        return {"rms_base_mm": self.rms_base_mm, "rms_cand_mm": self.rms_cand_mm, "gain": self.gain, "t": self.t,
                "n": self.n, "significant": self.significant}


def paired_gain(se_base_mm2: np.ndarray, se_cand_mm2: np.ndarray) -> PairedGain:
    """Paired test on per-point squared errors (N,) mm^2 of two models at the same held-out points:
    t = mean(d) / (std(d) / sqrt(N)), d = se_base - se_cand (positive when the candidate is better)."""
    a, b = np.asarray(se_base_mm2, float), np.asarray(se_cand_mm2, float)
    d = a - b
    n = len(d)
    sd = float(np.std(d, ddof=1)) if n > 1 else 0.0
    t = float(np.mean(d) / (sd / np.sqrt(n))) if sd > 0 else 0.0
    ra, rb = float(np.sqrt(np.mean(a))), float(np.sqrt(np.mean(b)))
    return PairedGain(ra, rb, 1.0 - rb / ra if ra > 0 else 0.0, t, n)


def signed_rank_z(se_base_mm2: np.ndarray, se_cand_mm2: np.ndarray) -> float:
    """One-sided Wilcoxon signed-rank statistic of the per-point differences d = se_base - se_cand (N,) mm^2, as a
    normal z (ties and zeros as in Wilcoxon's treatment: zeros dropped, tied |d| given their mean rank, the variance
    corrected for ties); positive when the candidate is better. It reads the ranks, not the sizes: a gain spread
    over most points is not drowned by a few large differences, as the paired t is."""
    d = np.asarray(se_base_mm2, float) - np.asarray(se_cand_mm2, float)
    d = d[d != 0]
    n = len(d)
    if n == 0:
        return 0.0
    r = average_ranks(np.abs(d))
    _, ties = np.unique(np.abs(d), return_counts=True)
    var = n * (n + 1) * (2 * n + 1) / 24 - np.sum(ties**3 - ties) / 48
    return float((r[d > 0].sum() - n * (n + 1) / 4) / np.sqrt(var)) if var > 0 else 0.0


def _special():
    """``scipy.special``, loaded on first use (see the module docstring)."""
    from scipy import special
    return special


def average_ranks(x: np.ndarray) -> np.ndarray:
    """Ranks 1..N of x (N,), tied values given their mean rank (``scipy.stats.rankdata``'s default)."""
    x = np.asarray(x, float)
    order = np.argsort(x, kind="mergesort")
    xs = x[order]
    first = np.r_[True, xs[1:] != xs[:-1]]                  # the first of each run of equal values
    starts = np.r_[np.flatnonzero(first), len(x)]
    mean_rank = 0.5 * (starts[:-1] + starts[1:] - 1) + 1.0  # mean of the 1-based ranks of each run
    ranks = np.empty(len(x))
    ranks[order] = mean_rank[np.cumsum(first) - 1]
    return ranks


def t_sf(t, dof):
    """P(T > t) of Student's t with ``dof`` degrees of freedom (broadcast arrays or floats)."""
    return _special().stdtr(dof, -np.asarray(t, float))


def chi2_sf(x, dof):
    """P(X > x) of the chi-squared distribution with ``dof`` degrees of freedom."""
    return _special().chdtrc(dof, x)


def f_sf(x, dfn, dfd):
    """P(F > x) of the F distribution with (dfn, dfd) degrees of freedom."""
    return _special().fdtrc(dfn, dfd, x)


def f_isf(alpha, dfn, dfd):
    """The value the F distribution with (dfn, dfd) degrees of freedom exceeds with probability ``alpha``."""
    return _special().fdtri(dfn, dfd, 1.0 - np.asarray(alpha, float))


def welch_t(x: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """(t, two-sided p) of Welch's test that x (n,) and y (m,) have the same mean, their variances unequal; NaN
    when both samples are constant."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    vx, vy = np.var(x, ddof=1) / len(x), np.var(y, ddof=1) / len(y)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (np.mean(x) - np.mean(y)) / np.sqrt(vx + vy)
        dof = (vx + vy) ** 2 / (vx**2 / (len(x) - 1) + vy**2 / (len(y) - 1))
    return float(t), float(2.0 * t_sf(np.abs(t), dof))
