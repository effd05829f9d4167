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
CHUNK_ROWS = 8192     # rows per block of the in-place whitening


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
    mm per point (squared 3-D norm). Memory: the whitened design once (N x 3 x P), whitened in place when
    ``copy`` is False (the caller hands ``A`` over), one Gram matrix (P, P) per fold, and per call
    one block of ``CHUNK_ROWS`` rows at a time."""

    def __init__(self, A: np.ndarray, y: np.ndarray, W: np.ndarray, blockings: list[Blocking], copy: bool = True):
        N, _, P = A.shape
        Aw = np.array(A, float) if copy else np.asarray(A, float)
        for s in range(0, N, CHUNK_ROWS):      # whitened in row blocks: no second N x 3 x P array
            Aw[s:s + CHUNK_ROWS] = np.einsum("nij,njk->nik", W[s:s + CHUNK_ROWS], Aw[s:s + CHUNK_ROWS])
        self.yw = np.einsum("nij,nj->ni", W, y)
        self.scale = np.sqrt(np.einsum("nik,nik->k", Aw, Aw))
        self.scale[self.scale == 0] = 1.0
        Aw /= self.scale
        self._Aw = Aw
        self.L = np.linalg.inv(W)
        self.blockings = blockings
        self.P = P
        self._gram, self._fold_at = [], []
        for b in blockings:
            perm = np.argsort(b.fold, kind="stable")
            edges = np.flatnonzero(np.diff(b.fold[perm])) + 1
            per = []
            for s, e in zip(np.concatenate([[0], edges]), np.concatenate([edges, [N]])):
                rows = perm[s:e]
                Af = Aw[rows].reshape(-1, P)           # one fold's rows at a time
                per.append((rows, Af.T @ Af, Af.T @ self.yw[rows].reshape(-1)))
                del Af
            self._gram.append((sum(p[1] for p in per), sum(p[2] for p in per), per))
            self._fold_at.append(np.searchsorted(np.unique(b.fold), b.fold))     # (N,) index of each row's fold

    @property
    def Aw(self) -> np.ndarray:
        """The whitened, unit-norm design (N, 3, P) in row order (read-only, not a copy)."""
        out = self._Aw.view()
        out.flags.writeable = False
        return out

    def errors(self, cols, blocking: int = 0) -> np.ndarray:
        """Held-out error vectors (N, 3) mm of the columns ``cols`` under one blocking."""
        cols = np.asarray(cols, int)
        G, c, per = self._gram[blocking]
        out = np.empty((len(self.yw), 3))
        GS, cS = G[np.ix_(cols, cols)], c[cols]
        ridge = RIDGE * np.eye(len(cols))
        X = np.zeros((self.P, len(per)))                      # every fold's fit, zero outside ``cols``
        for f, (rows, Gf, cf) in enumerate(per):
            X[cols, f] = np.linalg.solve(GS - Gf[np.ix_(cols, cols)] + ridge, cS - cf[cols])
        at = self._fold_at[blocking]
        for s in range(0, len(out), CHUNK_ROWS):    # row blocks: all folds' predictions, each row keeps its own
            b = slice(s, s + CHUNK_ROWS)
            pred = (self._Aw[b].reshape(-1, self.P) @ X).reshape(-1, 3, len(per))
            e_w = self.yw[b] - np.take_along_axis(pred, at[b, None, None], axis=2)[:, :, 0]
            out[b] = np.einsum("nij,nj->ni", self.L[b], e_w)
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
