"""The Gauss-Newton engine: model evaluation (geometry + effect groups), refits with the exact forward model,
whitened linearised designs and blocked cross-validation over the rows of one dataset."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..kinematics import Kinematics, ParamLayout, apply_update, identification_jacobian
from .candidates import Group
from .records import DiagnosisInput


def _whiten(W, x):
    return np.einsum("nij,nj...->ni...", W, x)


def _orth(M: np.ndarray, tol: float = 1e-9) -> np.ndarray:
    """Orthonormal basis of the column space of M (columns scaled to unit norm first)."""
    if M.shape[1] == 0:
        return np.zeros((M.shape[0], 0))
    nrm = np.linalg.norm(M, axis=0)
    M = M[:, nrm > 1e-300] / nrm[nrm > 1e-300]
    U, s, _ = np.linalg.svd(M, full_matrices=False)
    return U[:, s > tol * max(s[0], 1e-300)] if len(s) else U


def _lstsq_scaled(A, y, rcond=1e-10):
    nrm = np.linalg.norm(A, axis=0)
    nrm[nrm < 1e-300] = 1.0
    x = np.linalg.lstsq(A / nrm, y, rcond=rcond)[0]
    return x / nrm


@dataclass(eq=False)
class _State:
    kin: Kinematics
    groups: list
    theta: np.ndarray
    pred: np.ndarray          # (N, 3) model SMR positions (tracker frame)
    J: np.ndarray             # (N, 3, P) at the effect-shifted joints


class _Engine:
    """Model evaluation, refits and linearised designs over the rows of one dataset."""

    def __init__(self, inp: DiagnosisInput, cols: np.ndarray, fit_rows: np.ndarray, test_rows: np.ndarray):
        self.q, self.p = np.asarray(inp.q_rad, float), np.asarray(inp.p_mm, float)
        self.L = np.linalg.cholesky(np.asarray(inp.cov_mm2, float))
        self.W = np.linalg.inv(self.L)
        self.cols, self.fit_rows, self.test_rows = cols, fit_rows, test_rows
        self.layout = ParamLayout.of(inp.kin)
        self.joint_cols = [c for c, i, k in self.layout.joint_cols if k == 0]     # d p / d q_i

    # ---------------------------------------------------------------- model
    def predict(self, kin, groups, theta) -> tuple[np.ndarray, np.ndarray]:
        dq = np.zeros_like(self.q)
        dp = np.zeros((len(self.q), 3))
        at = 0
        for g in groups:
            th = theta[at:at + g.k]
            at += g.k
            if g.dq is not None:
                dq += g.dq @ th
            if g.dp is not None:
                dp += g.dp @ th
        p, J = identification_jacobian(kin, self.q + dq)
        return p + dp, J

    def regressor(self, J, kin, g: Group) -> np.ndarray:
        """Tracker-frame displacement per unit parameter (N, 3, k) mm."""
        X = np.zeros((len(self.q), 3, g.k))
        if g.dq is not None:
            X += np.einsum("nij,njk->nik", J[:, :, self.joint_cols], g.dq)
        if g.dp is not None:
            X += g.dp
        return X

    def wflat(self, X, rows) -> np.ndarray:
        """Whitened (3m, k) rows of an (N, 3, k) or (N, 3) array."""
        Xw = _whiten(self.W[rows], X[rows])
        return Xw.reshape(3 * len(rows), -1) if Xw.ndim == 3 else Xw.reshape(-1)

    def design(self, st: _State, rows, extra=()) -> np.ndarray:
        parts = [self.wflat(st.J[:, :, self.cols], rows)]
        parts += [self.wflat(self.regressor(st.J, st.kin, g), rows) for g in list(st.groups) + list(extra)]
        return np.concatenate(parts, axis=1)

    def fit(self, kin, groups, theta0=None, iters: int = 8) -> _State:
        """Gauss-Newton on the calibration rows with the exact forward model (geometry + effects)."""
        groups = list(groups)
        k = sum(g.k for g in groups)
        theta = np.zeros(k) if theta0 is None else np.concatenate([theta0, np.zeros(k - len(theta0))])
        rows = self.fit_rows
        nc = len(self.cols)
        full = np.zeros(self.layout.size)
        for _ in range(iters):
            pred, J = self.predict(kin, groups, theta)
            st = _State(kin, groups, theta, pred, J)
            A = self.design(st, rows)
            r = self.wflat(self.p - pred, rows)
            nrm = np.linalg.norm(A, axis=0)
            nrm[nrm < 1e-300] = 1.0
            dx_s = np.linalg.lstsq(A / nrm, r, rcond=1e-10)[0]
            dx = dx_s / nrm
            full[:] = 0.0
            full[self.cols] = dx[:nc]
            kin = apply_update(kin, full)
            theta = theta + dx[nc:]
            if np.linalg.norm(A @ dx) < 1e-4:            # whitened units: far below one noise sigma
                break
        pred, J = self.predict(kin, groups, theta)
        return _State(kin, groups, theta, pred, J)

    # ---------------------------------------------------------------- evaluation
    def resid(self, st: _State) -> np.ndarray:
        return self.p - st.pred

    def test_rms(self, st: _State) -> float:
        if len(self.test_rows) == 0:
            return float("nan")
        r = self.resid(st)[self.test_rows]
        return float(np.sqrt(np.mean(np.sum(r**2, axis=1))))

    def folds(self, by_time: bool, t, K: int, seed: int) -> list[np.ndarray]:
        """K folds of positions into fit_rows: contiguous time blocks or a seeded random partition of poses."""
        m = len(self.fit_rows)
        K = max(2, min(K, m // 10))
        if by_time and t is not None:
            order = np.argsort(np.asarray(t)[self.fit_rows], kind="stable")
        else:
            order = np.random.default_rng(seed).permutation(m)
        return np.array_split(order, K)

    def cv_errors(self, A: np.ndarray, y: np.ndarray, folds) -> np.ndarray:
        """Cross-validated whitened errors (m, 3) of the linear model y ~ A over point folds."""
        m = len(y) // 3
        e = np.zeros((m, 3))
        for f in folds:
            f = np.sort(f)
            train = np.ones(m, bool)
            train[f] = False
            tr = np.repeat(train, 3)
            beta = _lstsq_scaled(A[tr], y[tr])
            te = np.repeat(~train, 3)
            e[f] = (y[te] - A[te] @ beta).reshape(-1, 3)
        return e

    def to_mm(self, e_w: np.ndarray, rows) -> np.ndarray:
        return np.einsum("nij,nj->ni", self.L[rows], e_w)


def _rms(r) -> float:
    r = np.asarray(r, float).reshape(-1, 3)
    return float(np.sqrt(np.mean(np.sum(r**2, axis=1)))) if len(r) else float("nan")


def _absorption(X, Qgeo) -> float:
    """1 - ||X_perp||^2 / ||X||^2 over unit-norm columns (effects.md §6 step 4)."""
    Z = np.concatenate(X, axis=1)
    nrm = np.linalg.norm(Z, axis=0)
    Z = Z[:, nrm > 1e-300] / nrm[nrm > 1e-300]
    if Z.shape[1] == 0:
        return 1.0
    Zp = Z - Qgeo @ (Qgeo.T @ Z)
    return float(1.0 - np.sum(Zp**2) / np.sum(Z**2))


def _overlap(U1, U2) -> float:
    """Cosine of the smallest principal angle between two orthonormal subspaces."""
    if U1 is None or U2 is None or U1.shape[1] == 0 or U2.shape[1] == 0:
        return 0.0
    return float(np.linalg.svd(U1.T @ U2, compute_uv=False)[0])


def _columns_of(eng, st, groups):
    """Design-column indices (after the geometric ones) and fitted parameters of ``groups`` in state ``st``."""
    cols, th, at = [], [], len(eng.cols)
    ti = 0
    for g in st.groups:
        if any(g is h for h in groups):
            cols += list(range(at, at + g.k))
            th.append(st.theta[ti:ti + g.k])
        at += g.k
        ti += g.k
    return np.array(cols, int), (np.concatenate(th) if th else np.zeros(0))


def _split_theta(st):
    out, at = [], 0
    for g in st.groups:
        out.append(st.theta[at:at + g.k])
        at += g.k
    return out
