"""Gaussian-process regression of robot errors (seed 003 §1.2, eq. 4-9); the RBF-network baseline is robocal/layers/rbf.py.

One output per model: ``e = Omega(x) + eps`` with a squared-exponential ARD kernel

    k(x_a, x_b) = sigma_f^2 exp(-1/2 (x_a - x_b)^T diag(lambda)^-2 (x_a - x_b))

(one length scale ``lambda_i`` per input), white noise ``eps ~ N(0, sigma_n^2)`` and a constant mean (the
training mean; the seed uses zero mean, which is the same after centring). Hyperparameters
``theta = (sigma_f, sigma_n, lambda_1..lambda_d)`` minimise the negative log marginal likelihood (eq. 9) with
its analytic gradient, by L-BFGS-B on log-parameters from a heuristic start plus a few seeded restarts.
Predictive mean and variance are eq. 7 and eq. 8 (eq. 8 includes sigma_n^2: the spread of a new
*measurement*; ``include_noise=False`` gives the latent function's). Everything is Cholesky based.

Inputs are joint angles in rad (N, n), with the payload in kg appended as one more column when a model is
trained across payloads (seed 003 §5 suggestion). Outputs in mm. ``GPRResidual`` is the residual layer of
``CalibratedModel`` (kind ``"gpr"``): one GP per base-frame axis on the kinematic model's residuals.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.linalg import cho_factor, cho_solve, solve_triangular
from scipy.linalg.lapack import dpotri
from scipy.optimize import minimize


LOG_2PI = float(np.log(2.0 * np.pi))
JITTER = 1e-10            # added to the diagonal, relative to var(y), for a safe Cholesky
KERNEL_BLOCK_BYTES = 64 * 2**20   # test-point kernel rows are computed in blocks of at most this size
NEGLIGIBLE_LOG = -115.0   # kernel entries below exp(-115) ~ 1e-50 of sigma_f^2 are exactly 0 (se_ard)


# ---------------------------------------------------------------- kernel and likelihood
def se_ard(Xa: np.ndarray, Xb: np.ndarray, length: np.ndarray, sigma_f: float) -> np.ndarray:
    """Squared-exponential ARD covariance (Na, Nb) between inputs Xa (Na, d) and Xb (Nb, d).

    Entries below 1e-50 sigma_f^2 are exactly 0: far below the rounding of any sum they enter, and kept they turn
    into subnormal numbers inside the Cholesky factor and its inverse at short length scales (slow arithmetic in
    the hyperparameter search)."""
    A, B = Xa / length, Xb / length
    d2 = np.sum(A**2, 1)[:, None] + np.sum(B**2, 1)[None, :]
    d2 -= 2.0 * A @ B.T                                   # in place from here: one (Na, Nb) array, no temporaries
    np.maximum(d2, 0.0, out=d2)
    d2 *= -0.5
    np.putmask(d2, d2 < NEGLIGIBLE_LOG, -np.inf)
    np.exp(d2, out=d2)
    d2 *= sigma_f**2
    return d2


def kernel_blocks(n_rows: int, n_cols: int, budget_bytes: int | None = None) -> list[slice]:
    """Row blocks of an (n_rows, n_cols) kernel matrix of at most ``budget_bytes`` each (default
    ``KERNEL_BLOCK_BYTES``; one block, the whole matrix, when it fits): predictions at any number of points in
    bounded memory."""
    budget = KERNEL_BLOCK_BYTES if budget_bytes is None else budget_bytes
    step = max(1, budget // (8 * max(n_cols, 1)))
    return [slice(s, s + step) for s in range(0, max(n_rows, 1), step)]


def cholesky_inverse(c: tuple[np.ndarray, bool]) -> np.ndarray:
    """H^-1 (m, m) from the lower Cholesky factor ``c`` of ``cho_factor(H, lower=True)`` (LAPACK potri: a third
    of the work of solving against the identity)."""
    inv, info = dpotri(c[0], lower=1)
    if info != 0:
        raise np.linalg.LinAlgError(f"potri failed ({info})")
    upper = np.triu_indices(len(inv), 1)
    inv[upper] = inv.T[upper]                             # mirror the lower triangle potri wrote
    return inv


def unpack(log_theta: np.ndarray) -> tuple[float, float, np.ndarray]:
    """log-parameter vector (log sigma_f, log sigma_n, log lambda_1..d) -> (sigma_f, sigma_n, lambda)."""
    t = np.asarray(log_theta, float)
    return float(np.exp(t[0])), float(np.exp(t[1])), np.exp(t[2:])


def neg_log_marginal_likelihood(log_theta: np.ndarray, X: np.ndarray, y: np.ndarray, jitter: float = 0.0,
                                grad: bool = True):
    """L(theta) = -log p(y | X, theta) (eq. 9) and its analytic gradient w.r.t. the log-parameters.

    With H = K + sigma_n^2 I, alpha = H^-1 y and W = alpha alpha^T - H^-1:
    dL/dlog(sigma_f) = -sum(W o K), dL/dlog(sigma_n) = -sigma_n^2 tr(W),
    dL/dlog(lambda_i) = -1/2 sum_ab W_ab K_ab (x_ai - x_bi)^2 / lambda_i^2 (expanded, no (m, m, d) array).
    X (m, d) should be centred (the kernel is translation invariant; centring avoids cancellation).
    Returns L or (L, gradient (d + 2,)).
    """
    sf, sn, lam = unpack(log_theta)
    m = len(y)
    K = se_ard(X, X, lam, sf)
    H = K + (sn**2 + jitter) * np.eye(m)
    try:
        c = cho_factor(H, lower=True, check_finite=False)
    except np.linalg.LinAlgError:
        return (np.inf, np.zeros_like(log_theta)) if grad else np.inf
    alpha = cho_solve(c, y, check_finite=False)
    L = 0.5 * y @ alpha + np.sum(np.log(np.diag(c[0]))) + 0.5 * m * LOG_2PI
    if not grad:
        return float(L)
    W = np.outer(alpha, alpha) - cholesky_inverse(c)
    M = W * K
    r = M.sum(axis=1)
    quad = (X**2).T @ r - np.sum((M @ X) * X, axis=0)       # = 1/2 sum_ab M_ab (x_ai - x_bi)^2
    g = np.empty(len(log_theta))
    g[0] = -np.sum(M)
    g[1] = -sn**2 * np.trace(W)
    g[2:] = -quad / lam**2
    return float(L), g


def nlml_shared(log_theta: np.ndarray, X: np.ndarray, Y: np.ndarray, jitter: float = 0.0):
    """Sum over the k columns of Y (m, k) of the negative log marginal likelihood with one shared set of
    hyperparameters (the columns standardised by the caller), and its gradient: one Cholesky per evaluation
    for all outputs. Same formulas as ``neg_log_marginal_likelihood`` with W = A A^T - k H^-1, A = H^-1 Y."""
    sf, sn, lam = unpack(log_theta)
    m, k = Y.shape
    K = se_ard(X, X, lam, sf)
    H = K.copy()
    H.flat[::m + 1] += sn**2 + jitter
    try:
        c = cho_factor(H, lower=True, overwrite_a=True, check_finite=False)
    except np.linalg.LinAlgError:
        return np.inf, np.zeros_like(log_theta)
    A = cho_solve(c, Y, check_finite=False)
    L = 0.5 * np.sum(Y * A) + k * np.sum(np.log(np.diag(c[0]))) + 0.5 * m * k * LOG_2PI
    Hinv = cholesky_inverse(c)
    Hinv *= k
    W = A @ A.T
    W -= Hinv
    trace_W = np.trace(W)
    M = W
    M *= K                                                # in place: W is not needed after its trace
    r = M.sum(axis=1)
    quad = (X**2).T @ r - np.sum((M @ X) * X, axis=0)
    g = np.empty(len(log_theta))
    g[0] = -np.sum(M)
    g[1] = -sn**2 * trace_W
    g[2:] = -quad / lam**2
    return float(L), g


def noise_floor_bound(noise_floor_mm: float | None, y_std: np.ndarray) -> float | None:
    """Lower bound of the standardised shared sigma_n so that the model's noise, as a 3-D RMS over the outputs
    (sqrt(sum_j (sigma_n y_std_j)^2), mm), is at least the measurement noise floor (a 3-D RMS, mm): a GP never
    explains its own points more closely than the instrument measures them. None without a floor."""
    if noise_floor_mm is None or not noise_floor_mm > 0:
        return None
    return float(noise_floor_mm / max(float(np.sqrt(np.sum(np.square(y_std)))), 1e-12))


def fit_shared_hyperparameters(X: np.ndarray, Y: np.ndarray, *, log_theta0: np.ndarray | None = None,
                               n_restarts: int = 0, seed: int = 0, max_iter: int = 150,
                               sn_min: float | None = None) -> np.ndarray:
    """Shared log-hyperparameters (log sigma_f, log sigma_n, log lambda) of standardised outputs Y (m, k),
    by L-BFGS-B on ``nlml_shared`` from a heuristic (or given) start plus ``n_restarts`` seeded starts;
    ``sn_min`` bounds sigma_n below (``noise_floor_bound``)."""
    Xc = X - X.mean(axis=0)
    s_x = np.where(X.std(axis=0) > 1e-12, X.std(axis=0), 1.0)
    start = np.log(np.concatenate([[1.0, 0.3], s_x])) if log_theta0 is None else np.asarray(log_theta0, float)
    sn_lo = np.log(max(1e-4, sn_min or 0.0))
    bounds = [(np.log(1e-3), np.log(1e2)), (sn_lo, max(np.log(10.0), sn_lo + np.log(10.0)))]
    bounds += [(np.log(1e-2 * s), np.log(1e3 * s)) for s in s_x]
    lo, hi = np.array(bounds).T
    rng = np.random.default_rng(seed)
    starts = [np.clip(start, lo, hi)] + [np.clip(start + rng.normal(0.0, 1.0, start.shape), lo, hi)
                                         for _ in range(n_restarts)]
    best = None
    for t0 in starts:
        res = minimize(nlml_shared, t0, args=(Xc, Y, JITTER), jac=True, method="L-BFGS-B", bounds=bounds,
                       options={"maxiter": max_iter})
        if np.isfinite(res.fun) and (best is None or res.fun < best.fun):
            best = res
    return best.x if best is not None else starts[0]


# ---------------------------------------------------------------- one-output GP
@dataclass(frozen=True, eq=False)
class GaussianProcess:
    """A trained one-output GP: training inputs X (m, d) and outputs y (m,), hyperparameters
    sigma_f, sigma_n (output units), length (d,) (input units) and the constant mean y_mean.
    The Cholesky factor and alpha are derived (recomputed by ``from_dict``)."""
    X: np.ndarray
    y: np.ndarray
    sigma_f: float
    sigma_n: float
    length: np.ndarray
    y_mean: float = 0.0
    x_centre: np.ndarray | None = None
    _chol: np.ndarray = field(init=False, repr=False)
    _alpha: np.ndarray = field(init=False, repr=False)

    def __post_init__(self):
        put = lambda k, v: object.__setattr__(self, k, v)  # noqa: E731
        put("X", np.atleast_2d(np.asarray(self.X, float)))
        put("y", np.asarray(self.y, float).ravel())
        put("length", np.asarray(self.length, float).ravel())
        put("x_centre", self.X.mean(axis=0) if self.x_centre is None else np.asarray(self.x_centre, float))
        Xc = self.X - self.x_centre
        H = se_ard(Xc, Xc, self.length, self.sigma_f) + (self.sigma_n**2 + self._jitter()) * np.eye(len(self.y))
        L = np.linalg.cholesky(H)
        put("_chol", L)
        put("_alpha", cho_solve((L, True), self.y - self.y_mean, check_finite=False))

    @classmethod
    def from_factor(cls, X, y, sigma_f, sigma_n, length, y_mean, x_centre, chol, alpha=None) -> "GaussianProcess":
        """A GP whose Cholesky factor of K + (sigma_n^2 + jitter) I is already known (shared by outputs that differ
        only by scale), and optionally its alpha = H^-1 (y - y_mean): no O(m^3) work here."""
        gp = object.__new__(cls)
        put = lambda k, v: object.__setattr__(gp, k, v)  # noqa: E731
        put("X", np.atleast_2d(np.asarray(X, float)))
        put("y", np.asarray(y, float).ravel())
        put("sigma_f", float(sigma_f))
        put("sigma_n", float(sigma_n))
        put("length", np.asarray(length, float).ravel())
        put("y_mean", float(y_mean))
        put("x_centre", np.asarray(x_centre, float))
        put("_chol", chol)
        put("_alpha", cho_solve((chol, True), gp.y - gp.y_mean, check_finite=False) if alpha is None
            else np.asarray(alpha, float))
        return gp

    def _jitter(self) -> float:
        return JITTER * max(float(np.var(self.y)), 1e-30)

    @property
    def log_theta(self) -> np.ndarray:
        return np.log(np.concatenate([[self.sigma_f, self.sigma_n], self.length]))

    @property
    def nlml(self) -> float:
        """Negative log marginal likelihood at the stored hyperparameters."""
        return neg_log_marginal_likelihood(self.log_theta, self.X - self.x_centre, self.y - self.y_mean,
                                           self._jitter(), grad=False)

    @classmethod
    def fit(cls, X: np.ndarray, y: np.ndarray, *, n_restarts: int = 3, seed: int = 0,
            log_theta0: np.ndarray | None = None, max_iter: int = 200) -> "GaussianProcess":
        """Maximise the marginal likelihood (L-BFGS-B, analytic gradient) from a heuristic start and
        ``n_restarts`` seeded random starts around it; keep the best."""
        X = np.atleast_2d(np.asarray(X, float))
        y = np.asarray(y, float).ravel()
        y_mean = float(y.mean())
        x_centre = X.mean(axis=0)
        Xc, yc = X - x_centre, y - y_mean
        s_y = max(float(yc.std()), 1e-12)
        s_x = np.where(X.std(axis=0) > 1e-12, X.std(axis=0), 1.0)
        start = np.log(np.concatenate([[s_y, 0.1 * s_y], s_x])) if log_theta0 is None else np.asarray(log_theta0)
        bounds = [(np.log(1e-3 * s_y), np.log(1e2 * s_y)), (np.log(1e-6 * s_y), np.log(10 * s_y))]
        bounds += [(np.log(1e-2 * s), np.log(1e3 * s)) for s in s_x]
        lo, hi = np.array(bounds).T
        rng = np.random.default_rng(seed)
        starts = [np.clip(start, lo, hi)] + [np.clip(start + rng.normal(0.0, 1.0, start.shape), lo, hi)
                                             for _ in range(n_restarts)]
        jitter = JITTER * max(float(np.var(y)), 1e-30)
        best = None
        for t0 in starts:
            res = minimize(neg_log_marginal_likelihood, t0, args=(Xc, yc, jitter), jac=True, method="L-BFGS-B",
                           bounds=bounds, options={"maxiter": max_iter})
            if np.isfinite(res.fun) and (best is None or res.fun < best.fun):
                best = res
        sf, sn, lam = unpack(best.x if best is not None else starts[0])
        return cls(X, y, sf, sn, lam, y_mean, x_centre)

    @classmethod
    def fit_subset(cls, X: np.ndarray, y: np.ndarray, *, hyper_points: int = 250, n_restarts: int = 1, seed: int = 0,
                   max_iter: int = 150, log_theta0: np.ndarray | None = None) -> "GaussianProcess":
        """Fast fit for many points: hyperparameters by marginal likelihood on a seeded random subset of at most
        ``hyper_points`` points (O(h^3) per evaluation instead of O(m^3)), then the exact GP on all m points with
        those hyperparameters (one O(m^3) Cholesky)."""
        X = np.atleast_2d(np.asarray(X, float))
        y = np.asarray(y, float).ravel()
        if len(y) <= hyper_points:
            return cls.fit(X, y, n_restarts=n_restarts, seed=seed, max_iter=max_iter, log_theta0=log_theta0)
        sub = np.sort(np.random.default_rng(seed).choice(len(y), hyper_points, replace=False))
        h = cls.fit(X[sub], y[sub], n_restarts=n_restarts, seed=seed, max_iter=max_iter, log_theta0=log_theta0)
        return cls(X, y, h.sigma_f, h.sigma_n, h.length, float(y.mean()), X.mean(axis=0))

    def kfold_errors(self, fold: np.ndarray) -> np.ndarray:
        """Held-out prediction errors y - mean (m,) of every training point when its fold is left out, with
        the hyperparameters fixed (closed form: e_I = [H^-1]_II^-1 alpha_I, no refit)."""
        Hinv = cho_solve((self._chol, True), np.eye(len(self.y)), check_finite=False)
        e = np.empty(len(self.y))
        for k in np.unique(fold):
            idx = np.flatnonzero(fold == k)
            e[idx] = np.linalg.solve(Hinv[np.ix_(idx, idx)], self._alpha[idx])
        return e

    def predict(self, Xs: np.ndarray, return_var: bool = False, include_noise: bool = True):
        """Predictive mean (N,) (eq. 7) and optionally variance (N,) (eq. 8; without sigma_n^2 if
        ``include_noise`` is False)."""
        Xs = np.atleast_2d(np.asarray(Xs, float)) - self.x_centre
        Xc = self.X - self.x_centre
        mean, var = np.empty(len(Xs)), np.empty(len(Xs))
        for b in kernel_blocks(len(Xs), len(Xc)):                    # (test rows x training points) per block
            Ks = se_ard(Xs[b], Xc, self.length, self.sigma_f)
            mean[b] = Ks @ self._alpha + self.y_mean
            if return_var:
                v = solve_triangular(self._chol, Ks.T, lower=True, check_finite=False)
                var[b] = self.sigma_f**2 - np.sum(v**2, axis=0) + (self.sigma_n**2 if include_noise else 0.0)
        return (mean, np.maximum(var, 0.0)) if return_var else mean

    def to_dict(self) -> dict:
        return {"X": self.X.tolist(), "y": self.y.tolist(), "sigma_f": self.sigma_f, "sigma_n": self.sigma_n,
                "length": self.length.tolist(), "y_mean": self.y_mean, "x_centre": self.x_centre.tolist()}

    @classmethod
    def from_dict(cls, d: dict) -> "GaussianProcess":
        return cls(np.array(d["X"], float), np.array(d["y"], float), float(d["sigma_f"]), float(d["sigma_n"]),
                   np.array(d["length"], float), float(d["y_mean"]), np.array(d["x_centre"], float))


@dataclass(frozen=True, eq=False)
class MultiOutputGP:
    """Independent GPs on the same inputs, one per output column (seed 003: one model per axis)."""
    models: tuple[GaussianProcess, ...]
    noise_floor_mm: float | None = None      # the bound of sigma_n a ``fit_subset`` model was fitted with

    kind = "exact"

    @classmethod
    def fit(cls, X: np.ndarray, Y: np.ndarray, *, n_restarts: int = 3, seed: int = 0) -> "MultiOutputGP":
        """X (m, d), Y (m, k): k GPs, each with its own hyperparameters (seeds seed, seed+1, ...)."""
        Y = np.asarray(Y, float).reshape(len(X), -1)
        return cls(tuple(GaussianProcess.fit(X, Y[:, j], n_restarts=n_restarts, seed=seed + j)
                         for j in range(Y.shape[1])))

    @classmethod
    def fit_subset(cls, X: np.ndarray, Y: np.ndarray, *, hyper_points: int = 300, n_restarts: int = 1,
                   seed: int = 0, max_iter: int = 150, log_theta0: np.ndarray | None = None,
                   noise_floor_mm: float | None = None) -> "MultiOutputGP":
        """Fast fit: every output standardised, one shared set of hyperparameters (length scales and
        signal-to-noise ratio) by marginal likelihood on a seeded random subset of at most ``hyper_points``
        points, then the exact GP of every output on all points with sigma_f, sigma_n scaled back by the
        output's standard deviation. ``log_theta0`` (standardised units) warm-starts the search;
        ``noise_floor_mm`` (3-D RMS) bounds the noise below (``noise_floor_bound``)."""
        X = np.atleast_2d(np.asarray(X, float))
        Y = np.asarray(Y, float).reshape(len(X), -1)
        mu, sd = Y.mean(axis=0), np.maximum(Y.std(axis=0), 1e-12)
        Z = (Y - mu) / sd
        sub = np.arange(len(X)) if len(X) <= hyper_points else \
            np.sort(np.random.default_rng(seed).choice(len(X), hyper_points, replace=False))
        t = fit_shared_hyperparameters(X[sub], Z[sub], log_theta0=log_theta0, n_restarts=n_restarts, seed=seed,
                                       max_iter=max_iter, sn_min=noise_floor_bound(noise_floor_mm, sd))
        sf, sn, lam = unpack(t)
        centre = X.mean(axis=0)
        Xc = X - centre
        H0 = se_ard(Xc, Xc, lam, sf)                                  # standardised units
        H0.flat[::len(X) + 1] += sn**2 + JITTER                        # in place: no (m, m) identity
        L0 = np.linalg.cholesky(H0)
        A0 = cho_solve((L0.T, False), Y - mu, check_finite=False)      # all outputs at once; L0.T is Fortran-ordered
        return cls(tuple(GaussianProcess.from_factor(X, Y[:, j], sf * sd[j], sn * sd[j], lam, float(mu[j]), centre,
                                                     sd[j] * L0, A0[:, j] / sd[j] ** 2) for j in range(Y.shape[1])),
                   noise_floor_mm)

    @property
    def shared_log_theta(self) -> np.ndarray:
        """Standardised shared log-hyperparameters of a ``fit_subset`` model (of the first output)."""
        g = self.models[0]
        sd = max(float(g.y.std()), 1e-12)
        return np.log(np.concatenate([[g.sigma_f / sd, g.sigma_n / sd], g.length]))

    def cv_errors(self, fold: np.ndarray, *, hyper_points: int = 300, max_iter: int = 40, seed: int = 0) -> np.ndarray:
        """Honest k-fold held-out errors (m, k) of a ``fit_subset`` model: per fold, the shared hyperparameters are
        re-fitted on the training folds only (warm-started from this model's, one start), then the exact GPs of
        the training folds predict the held-out fold."""
        X = self.models[0].X
        Y = np.stack([g.y for g in self.models], axis=1)
        err = np.empty_like(Y)
        for k in np.unique(fold):
            tr, te = fold != k, fold == k
            gk = MultiOutputGP.fit_subset(X[tr], Y[tr], hyper_points=hyper_points, n_restarts=0, seed=seed,
                                          max_iter=max_iter, log_theta0=self.shared_log_theta,
                                          noise_floor_mm=self.noise_floor_mm)
            err[te] = Y[te] - gk.predict(X[te])
        return err

    def kfold_errors(self, fold: np.ndarray) -> np.ndarray:
        """Held-out errors (m, k) of every output with the hyperparameters fixed (``GaussianProcess.kfold_errors``;
        optimistic when the hyperparameters were fitted on the held-out points too: see ``cv_errors``)."""
        return np.stack([g.kfold_errors(fold) for g in self.models], axis=1)

    def predict(self, Xs: np.ndarray) -> np.ndarray:
        """Predictive means (N, k); one kernel matrix for all outputs when they share inputs and length scales
        (``fit_subset``: their kernels differ by the factor sigma_f^2 only)."""
        g0 = self.models[0]
        if len(self.models) == 1 or not all(_same_inputs(g0, g) for g in self.models[1:]):
            return np.stack([g.predict(Xs) for g in self.models], axis=1)
        Xs = np.atleast_2d(np.asarray(Xs, float)) - g0.x_centre
        Xc, alpha = g0.X - g0.x_centre, np.stack([g.sigma_f**2 * g._alpha for g in self.models], axis=1)
        out = np.empty((len(Xs), len(self.models)))
        for b in kernel_blocks(len(Xs), len(Xc)):
            out[b] = se_ard(Xs[b], Xc, g0.length, 1.0) @ alpha + [g.y_mean for g in self.models]
        return out

    def predict_std(self, Xs: np.ndarray, include_noise: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """(mean (N, k), predictive standard deviation (N, k))."""
        out = [g.predict(Xs, return_var=True, include_noise=include_noise) for g in self.models]
        return np.stack([m for m, _ in out], 1), np.sqrt(np.stack([v for _, v in out], 1))

    @property
    def sigma_n_mm(self) -> np.ndarray:
        """Noise standard deviation (k,) per output, mm."""
        return np.array([g.sigma_n for g in self.models])

    @property
    def n_train(self) -> int:
        return len(self.models[0].y)

    def to_dict(self) -> dict:
        return {"approximation": self.kind, "models": [g.to_dict() for g in self.models],
                "noise_floor_mm": self.noise_floor_mm}

    @classmethod
    def from_dict(cls, d: dict) -> "MultiOutputGP":
        floor = d.get("noise_floor_mm")
        return cls(tuple(GaussianProcess.from_dict(g) for g in d["models"]), None if floor is None else float(floor))


def _same_inputs(a: GaussianProcess, b: GaussianProcess) -> bool:
    """Same training inputs, centre and length scales (then the kernels differ by sigma_f^2 only)."""
    return ((a.X is b.X or np.array_equal(a.X, b.X)) and np.array_equal(a.x_centre, b.x_centre)
            and np.array_equal(a.length, b.length))
