"""Blocked cross-validation of linear models over the calibration points: by pose blocks (small clusters of
neighbouring poses held out together) and by order blocks (contiguous segments of the measurement sequence).

``BlockedCV`` whitens the columns of every candidate once, accumulates one Gram matrix per held-out fold and
then gives the held-out errors of any subset of columns by solving its small normal equations: a forward
selection over many candidates costs a few small solves per candidate and fold, and nothing grows with N^2.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

RIDGE = 1e-9          # on unit-norm columns: directions the data cannot tell apart get no weight


def kfold(n: int, folds: int, seed: int = 0) -> np.ndarray:
    """Fold number (N,) of each point: a seeded random permutation cut into ``folds`` parts."""
    return np.random.default_rng(seed).permutation(n) % folds


def pose_blocks(q_rad: np.ndarray, folds: int, seed: int = 0, block_points: int = 12, iterations: int = 8
                ) -> np.ndarray:
    """Fold number (N,) by pose blocks: k-means clusters of about ``block_points`` poses in joint space (joints
    scaled by their spread), each cluster held out as a whole, the clusters dealt to the folds at random."""
    q = np.asarray(q_rad, float)
    n = len(q)
    k = int(np.clip(n // block_points, folds, 200))
    sd = q.std(axis=0)
    x = q[:, sd > 0] / sd[sd > 0] if np.any(sd > 0) else np.zeros((n, 1))
    rng = np.random.default_rng(seed)
    first = int(rng.integers(n))
    idx, dist = [first], ((x - x[first]) ** 2).sum(axis=1)
    for _ in range(min(k, n) - 1):                  # farthest-point start: every separate group gets a centre
        idx.append(int(np.argmax(dist)))
        dist = np.minimum(dist, ((x - x[idx[-1]]) ** 2).sum(axis=1))
    centres = x[idx].copy()
    label = np.zeros(n, int)
    for _ in range(iterations):
        label = np.concatenate([_nearest(x[s:s + 20000], centres) for s in range(0, n, 20000)])   # bounded memory
        for c in range(len(centres)):
            members = label == c
            if members.any():
                centres[c] = x[members].mean(axis=0)
    deal = rng.permutation(len(centres)) % folds
    return deal[label]


def _nearest(x: np.ndarray, centres: np.ndarray) -> np.ndarray:
    d = (x**2).sum(axis=1)[:, None] - 2.0 * x @ centres.T + (centres**2).sum(axis=1)[None, :]
    return np.argmin(d, axis=1)


def order_blocks(order: np.ndarray, folds: int, segments_per_fold: int = 4) -> np.ndarray:
    """Fold number (N,) by order blocks: the points sorted by their position in the measurement sequence, cut
    into ``folds x segments_per_fold`` contiguous segments, segment s held out in fold s mod ``folds``."""
    rank = np.empty(len(order), int)
    rank[np.argsort(np.asarray(order, float), kind="stable")] = np.arange(len(order))
    segments = folds * segments_per_fold
    seg = (rank * segments) // max(len(order), 1)
    return seg % folds


@dataclass(frozen=True)
class Blocking:
    """One way of holding points out: its name and the fold (N,) of every point."""
    name: str
    fold: np.ndarray


class BlockedCV:
    """Held-out errors of y ~ A[:, S] x for column subsets S of one design, under several blockings.

    ``A`` (N, 3, P) mm per unit parameter, ``y`` (N, 3) mm, ``W`` (N, 3, 3) whitening (inverse Cholesky factor
    of each point's covariance). Fits are weighted least squares on the training folds; errors are returned in
    mm per point (squared 3-D norm)."""

    def __init__(self, A: np.ndarray, y: np.ndarray, W: np.ndarray, blockings: list[Blocking]):
        N, _, P = A.shape
        Aw = np.einsum("nij,njk->nik", W, A)
        self.yw = np.einsum("nij,nj->ni", W, y)
        self.scale = np.sqrt(np.einsum("nik,nik->k", Aw, Aw))
        self.scale[self.scale == 0] = 1.0
        Aw /= self.scale
        self.L = np.linalg.inv(W)
        self.blockings = blockings
        self.P = P
        self._gram, self._sorted = [], []
        for b in blockings:                    # rows sorted by fold: every fold's rows are a view of one copy
            perm = np.argsort(b.fold, kind="stable")
            Ab = Aw[perm]
            edges = np.flatnonzero(np.diff(b.fold[perm])) + 1
            per = []
            for s, e in zip(np.concatenate([[0], edges]), np.concatenate([edges, [N]])):
                rows = perm[s:e]
                Af = Ab[s:e].reshape(-1, P)
                per.append((rows, Af.T @ Af, Af.T @ self.yw[rows].reshape(-1), Af))
            self._gram.append((sum(p[1] for p in per), sum(p[2] for p in per), per))
            self._sorted.append((perm, Ab))
        del Aw

    @property
    def Aw(self) -> np.ndarray:
        """The whitened, unit-norm design (N, 3, P) in row order (a copy)."""
        perm, Ab = self._sorted[0]
        out = np.empty_like(Ab)
        out[perm] = Ab
        return out

    def errors(self, cols, blocking: int = 0) -> np.ndarray:
        """Held-out error vectors (N, 3) mm of the columns ``cols`` under one blocking."""
        cols = np.asarray(cols, int)
        G, c, per = self._gram[blocking]
        out = np.empty((len(self.yw), 3))
        GS, cS = G[np.ix_(cols, cols)], c[cols]
        ridge = RIDGE * np.eye(len(cols))
        for rows, Gf, cf, Af in per:
            x = np.linalg.solve(GS - Gf[np.ix_(cols, cols)] + ridge, cS - cf[cols])
            e_w = self.yw[rows] - (Af[:, cols] @ x).reshape(-1, 3)
            out[rows] = np.einsum("nij,nj->ni", self.L[rows], e_w)
        return out

    def squared_errors(self, cols) -> dict[str, np.ndarray]:
        """Per-point held-out squared errors (N,) mm^2 of the columns ``cols`` under each blocking."""
        return {b.name: np.sum(self.errors(cols, i) ** 2, axis=1) for i, b in enumerate(self.blockings)}

    def absorbed(self, cols, base_cols) -> float:
        """Share of the (whitened, unit-norm) columns ``cols`` inside the span of ``base_cols`` (1 = the base
        absorbs them entirely: their effect cannot be told from it)."""
        G = self._gram[0][0]
        cols, base = np.asarray(cols, int), np.asarray(base_cols, int)
        Gbb = G[np.ix_(base, base)] + RIDGE * np.eye(len(base))
        Gbc = G[np.ix_(base, cols)]
        inside = np.einsum("ij,ij->j", Gbc, np.linalg.solve(Gbb, Gbc))
        return float(np.clip(inside.sum() / max(float(np.trace(G[np.ix_(cols, cols)])), 1e-300), 0.0, 1.0))

    def fit(self, cols) -> np.ndarray:
        """Weighted least-squares parameters of the columns ``cols`` on all points (in the units of A)."""
        cols = np.asarray(cols, int)
        G, c, _ = self._gram[0]
        x = np.linalg.solve(G[np.ix_(cols, cols)] + RIDGE * np.eye(len(cols)), c[cols])
        return x / self.scale[cols]
