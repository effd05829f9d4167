"""Inducing-point GP regression for many points: bounded memory, the residual layer's GPR beyond a size.

The exact GP (``robocal.layers.gp.MultiOutputGP``) needs the (N, N) kernel matrix: 144 GiB at N = 139 000. Beyond
``EXACT_MAX_POINTS`` the layer uses the deterministic-training-conditional (DTC, projected-process) approximation
(Quinonero-Candela & Rasmussen 2005; Rasmussen & Williams 2006 §8.3.3) on ``m`` inducing inputs Z, a seeded
random subset of the training inputs, with the same squared-exponential ARD kernel, standardised outputs and
shared hyperparameters as ``MultiOutputGP.fit_subset`` (marginal likelihood on a random subset, the noise bounded
below by the measurement noise floor). With L = chol(K_ZZ), V = L^-1 K_ZX (m, N), B = sigma_n^2 I + V V^T
(= sigma_n^2 I + L^-1 (K_ZX K_XZ) L^-T, accumulated as K_ZX K_XZ):

    mean(x*) = v*^T B^-1 V y,   var(x*) = sigma_f^2 - |v*|^2 + sigma_n^2 |chol(B)^-1 v*|^2 (+ sigma_n^2),
    v* = L^-1 k_Z(x*),

accumulated over row chunks of ``CHUNK_ROWS``: O(N m^2) time, O(m^2 + m * chunk) memory, never an (N, N) or
(N, m) array beyond one chunk. With Z = X it is the exact GP (tests/robocal/test_sparse_gp.py).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import cho_solve, solve_triangular

from .gp import fit_shared_hyperparameters, noise_floor_bound, se_ard, unpack

EXACT_MAX_POINTS = 3000         # the exact GP up to this many training points, the inducing-point one above
INDUCING_POINTS = 300           # m
CHUNK_ROWS = 2048
KZZ_JITTER = 1e-6               # relative to sigma_f^2: K_ZZ of random inputs is nearly singular


def _kernel_chunks(X: np.ndarray, Z: np.ndarray, length: np.ndarray, sigma_f: float, chunk: int):
    """(rows slice, K_ZX (m, c)) for consecutive row chunks of X (N, d): the kernel one chunk at a time."""
    for start in range(0, len(X), chunk):
        rows = slice(start, min(start + chunk, len(X)))
        yield rows, se_ard(Z, X[rows], length, sigma_f)


@dataclass(frozen=True, eq=False)
class SparseGP:
    """Inducing-point GP of k outputs (shared standardised hyperparameters).

    ``Z`` (m, d) inducing inputs (centred by ``x_centre``); ``sigma_f``, ``sigma_n`` standardised, ``length`` (d,)
    input units; ``y_mean``, ``y_std`` (k,) output units (mm); ``weights`` (m, k) standardised, mean = K_xZ w;
    ``chol_Kzz``, ``chol_B`` (m, m) lower factors; ``n_train`` points; ``noise_floor_mm`` the bound applied."""
    Z: np.ndarray
    x_centre: np.ndarray
    sigma_f: float
    sigma_n: float
    length: np.ndarray
    y_mean: np.ndarray
    y_std: np.ndarray
    weights: np.ndarray
    chol_Kzz: np.ndarray
    chol_B: np.ndarray
    n_train: int
    noise_floor_mm: float | None = None

    kind = "inducing_points"

    @classmethod
    def fit(cls, X: np.ndarray, Y: np.ndarray, *, n_inducing: int = INDUCING_POINTS, hyper_points: int = 300,
            n_restarts: int = 1, seed: int = 0, max_iter: int = 150, log_theta0: np.ndarray | None = None,
            noise_floor_mm: float | None = None, chunk: int = CHUNK_ROWS, Z: np.ndarray | None = None) -> "SparseGP":
        """Hyperparameters as ``MultiOutputGP.fit_subset`` (seeded subset of ``hyper_points``), inducing inputs a
        seeded random subset of ``n_inducing`` training inputs (or ``Z``), then one chunked pass over the data."""
        X = np.atleast_2d(np.asarray(X, float))
        Y = np.asarray(Y, float).reshape(len(X), -1)
        rng = np.random.default_rng(seed)
        mu, sd = Y.mean(axis=0), np.maximum(Y.std(axis=0), 1e-12)
        sub = np.arange(len(X)) if len(X) <= hyper_points else np.sort(rng.choice(len(X), hyper_points, replace=False))
        t = fit_shared_hyperparameters(X[sub], (Y[sub] - mu) / sd, log_theta0=log_theta0, n_restarts=n_restarts,
                                       seed=seed, max_iter=max_iter, sn_min=noise_floor_bound(noise_floor_mm, sd))
        sf, sn, lam = unpack(t)
        centre = X.mean(axis=0)
        if Z is None:
            Z = X[np.sort(rng.choice(len(X), min(n_inducing, len(X)), replace=False))]
        Zc = np.asarray(Z, float) - centre
        m = len(Zc)
        Lz = np.linalg.cholesky(se_ard(Zc, Zc, lam, sf) + KZZ_JITTER * sf**2 * np.eye(m))
        G = np.zeros((m, m))
        g = np.zeros((m, Y.shape[1]))
        for rows, K in _kernel_chunks(X - centre, Zc, lam, sf, chunk):
            G += K @ K.T
            g += K @ ((Y[rows] - mu) / sd)
        V_G = solve_triangular(Lz, G, lower=True, check_finite=False)                 # L^-1 G
        B = sn**2 * np.eye(m) + solve_triangular(Lz, V_G.T, lower=True, check_finite=False)   # + L^-1 G L^-T
        Lb = np.linalg.cholesky(0.5 * (B + B.T))
        b = solve_triangular(Lz, g, lower=True, check_finite=False)
        w = solve_triangular(Lz.T, cho_solve((Lb, True), b, check_finite=False), lower=False, check_finite=False)
        return cls(Zc + centre, centre, sf, sn, lam, mu, sd, w, Lz, Lb, len(X), noise_floor_mm)

    @property
    def shared_log_theta(self) -> np.ndarray:
        return np.log(np.concatenate([[self.sigma_f, self.sigma_n], self.length]))

    @property
    def sigma_n_mm(self) -> np.ndarray:
        """Noise standard deviation (k,) per output, mm."""
        return self.sigma_n * self.y_std

    def _std_mean(self, Xs: np.ndarray, chunk: int = CHUNK_ROWS):
        Xs = np.atleast_2d(np.asarray(Xs, float)) - self.x_centre
        Zc = self.Z - self.x_centre
        for rows, K in _kernel_chunks(Xs, Zc, self.length, self.sigma_f, chunk):
            yield rows, K, K.T @ self.weights

    def predict(self, Xs: np.ndarray) -> np.ndarray:
        """Predictive means (N, k)."""
        out = np.empty((len(np.atleast_2d(Xs)), len(self.y_mean)))
        for rows, _, mean in self._std_mean(Xs):
            out[rows] = self.y_mean + self.y_std * mean
        return out

    def predict_std(self, Xs: np.ndarray, include_noise: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """(mean (N, k), predictive standard deviation (N, k)), DTC variance."""
        n, k = len(np.atleast_2d(Xs)), len(self.y_mean)
        mean, std = np.empty((n, k)), np.empty((n, k))
        for rows, K, m in self._std_mean(Xs):
            v = solve_triangular(self.chol_Kzz, K, lower=True, check_finite=False)
            u = solve_triangular(self.chol_B, v, lower=True, check_finite=False)
            var = self.sigma_f**2 - np.sum(v**2, axis=0) + self.sigma_n**2 * np.sum(u**2, axis=0)
            var = np.maximum(var, 0.0) + (self.sigma_n**2 if include_noise else 0.0)
            mean[rows] = self.y_mean + self.y_std * m
            std[rows] = np.sqrt(var)[:, None] * self.y_std
        return mean, std

    def cv_errors(self, X: np.ndarray, Y: np.ndarray, fold: np.ndarray, *, hyper_points: int = 300,
                  max_iter: int = 40, seed: int = 0) -> np.ndarray:
        """Honest k-fold held-out errors (N, k) on the training data X, Y, as ``MultiOutputGP.cv_errors``: per fold
        the hyperparameters are re-fitted on the training folds only (warm-started from this model's) and a
        sparse GP of the training folds (its own inducing inputs) predicts the held-out fold."""
        X = np.atleast_2d(np.asarray(X, float))
        Y = np.asarray(Y, float).reshape(len(X), -1)
        err = np.empty_like(Y)
        for k in np.unique(fold):
            tr, te = fold != k, fold == k
            gk = SparseGP.fit(X[tr], Y[tr], n_inducing=len(self.Z), hyper_points=hyper_points, n_restarts=0,
                              seed=seed, max_iter=max_iter, log_theta0=self.shared_log_theta,
                              noise_floor_mm=self.noise_floor_mm)
            err[te] = Y[te] - gk.predict(X[te])
        return err

    def to_dict(self) -> dict:
        return {"approximation": self.kind, "Z": self.Z.tolist(), "x_centre": self.x_centre.tolist(),
                "sigma_f": self.sigma_f, "sigma_n": self.sigma_n, "length": self.length.tolist(),
                "y_mean": self.y_mean.tolist(), "y_std": self.y_std.tolist(), "weights": self.weights.tolist(),
                "chol_B": self.chol_B.tolist(), "n_train": self.n_train, "noise_floor_mm": self.noise_floor_mm,
                "units": "standardised outputs (x y_std + y_mean = mm); inputs rad (joints), kg (payload)"}

    @classmethod
    def from_dict(cls, d: dict) -> "SparseGP":
        Z, c = np.array(d["Z"], float), np.array(d["x_centre"], float)
        sf, lam = float(d["sigma_f"]), np.array(d["length"], float)
        Lz = np.linalg.cholesky(se_ard(Z - c, Z - c, lam, sf) + KZZ_JITTER * sf**2 * np.eye(len(Z)))
        floor = d.get("noise_floor_mm")
        return cls(Z, c, sf, float(d["sigma_n"]), lam, np.array(d["y_mean"], float), np.array(d["y_std"], float),
                   np.array(d["weights"], float), Lz, np.array(d["chol_B"], float), int(d["n_train"]),
                   None if floor is None else float(floor))

