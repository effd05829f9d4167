"""Blocked cross-validation of linear models over the calibration points: by pose blocks (small clusters of
neighbouring poses held out together) and by order blocks (contiguous segments of the measurement sequence).

``BlockedCV`` whitens the columns of every candidate once, accumulates one Gram matrix per held-out fold and
then gives the held-out errors of any subset of columns by solving its small normal equations: a forward
selection over many candidates costs a few small solves per candidate and fold, and nothing grows with N^2.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from robocal.measure.stats import f_sf

RIDGE = 1e-6          # on unit-norm columns: (rank_tol = 1e-3)^2 of the fit that follows (robocal.identify
#                       CalibrationOptions.rank_tol): a direction whose relative residual is below 1e-3 is fixed at
#                       zero there, so it gets no weight here (bench/bench_cv_ridge.py; it was 1e-9)
CHUNK_ROWS = 8192     # rows per block of the in-place whitening
CV_MAX_ROWS = 200_000  # the cross-validated choices (effects, residual layer) and the diagnosis's analyses work on at
#                        most this many rows: a seeded subset beyond (their memory and time stay bounded at any size)


def capped_rows(n: int, max_rows: int = CV_MAX_ROWS, seed: int = 0) -> np.ndarray | None:
    """Sorted indices of a seeded random subset of ``max_rows`` of ``n`` rows (measurement order kept), or None
    when ``n <= max_rows`` (all rows)."""
    if n <= max_rows:
        return None
    return np.sort(np.random.default_rng(seed).choice(n, max_rows, replace=False))


def kfold(n: int, folds: int, seed: int = 0) -> np.ndarray:
    """Fold number (N,) of each point: a seeded random permutation cut into ``folds`` parts."""
    return np.random.default_rng(seed).permutation(n) % folds


def pose_blocks(q_rad: np.ndarray, folds: int, seed: int = 0, block_points: int = 12, iterations: int = 8
                ) -> np.ndarray:
    """Fold number (N,) by pose blocks: k-means clusters of about ``block_points`` poses in joint space (joints
    scaled by their spread), each cluster held out as a whole, the clusters dealt to the folds at random."""
    n = len(q_rad)
    rng = np.random.default_rng(seed)
    label, k = _clusters(q_rad, int(np.clip(n // block_points, folds, 200)), rng, iterations)
    deal = rng.permutation(k) % folds
    return deal[label]


def pose_clusters(q_rad: np.ndarray, block_points: int = 12, seed: int = 0, max_clusters: int = 200) -> np.ndarray:
    """Cluster number (N,) of each pose: the k-means pose blocks of ``pose_blocks`` (about ``block_points`` poses
    each, at most ``max_clusters``) before they are dealt to folds (the units of a block bootstrap)."""
    n = len(q_rad)
    return _clusters(q_rad, int(np.clip(n // max(block_points, 1), 1, max_clusters)), np.random.default_rng(seed),
                     8)[0]


def varies(X: np.ndarray, rel_tol: float = 1e-9) -> np.ndarray:
    """(d,) bool: the columns of X (N, d) whose spread exceeds ``rel_tol`` x their largest magnitude; a smaller
    spread is rounding (a joint held at one angle whose values differ in the last bits)."""
    X = np.asarray(X, float).reshape(len(X), -1)
    return X.std(axis=0) > rel_tol * np.abs(X).max(axis=0, initial=0.0)


def spread_scaled(X: np.ndarray) -> np.ndarray:
    """X (N, d) centred and divided by each column's spread, (N, d') with the columns that do not vary (``varies``)
    left out: dividing by a spread of rounding would make that rounding the largest coordinate."""
    X = np.asarray(X, float).reshape(len(X), -1)
    X = X[:, varies(X)]
    return (X - X.mean(axis=0)) / X.std(axis=0)


def _clusters(q_rad: np.ndarray, k: int, rng: np.random.Generator, iterations: int) -> tuple[np.ndarray, int]:
    """(label (N,), number of centres) of k-means in joint space (joints scaled by their spread) from a
    farthest-point start."""
    q = np.asarray(q_rad, float)
    n = len(q)
    x = spread_scaled(q)
    x = x if x.shape[1] else np.zeros((n, 1))
    first = int(rng.integers(n))
    idx, dist = [first], ((x - x[first]) ** 2).sum(axis=1)
    for _ in range(min(k, n) - 1):                  # farthest-point start: every separate group gets a centre
        idx.append(int(np.argmax(dist)))
        dist = np.minimum(dist, ((x - x[idx[-1]]) ** 2).sum(axis=1))
    centres = x[idx].copy()
    label = np.zeros(n, int)
    for _ in range(iterations):
        label = np.concatenate([_nearest(x[s:s + 20000], centres) for s in range(0, n, 20000)])   # bounded memory
        order = np.argsort(label, kind="stable")          # each cluster's members contiguous, in row order
        xs, ids = x[order], np.arange(len(centres))
        first, last = np.searchsorted(label[order], ids), np.searchsorted(label[order], ids, side="right")
        for c in np.flatnonzero(last > first):
            centres[c] = xs[first[c]:last[c]].mean(axis=0)
    return label, len(centres)


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


def design_array(n_points: int, n_params: int) -> np.ndarray:
    """An empty design (N, 3, P), the row-order view of a parameter-major (P, N, 3) array: ``BlockedCV(...,
    copy=False)`` whitens it in place."""
    return np.empty((n_params, n_points, 3)).transpose(1, 2, 0)


@dataclass(frozen=True)
class Blocking:
    """One way of holding points out: its name and the fold (N,) of every point."""
    name: str
    fold: np.ndarray


class BlockedCV:
    """Held-out errors of y ~ A[:, S] x for column subsets S of one design, under several blockings.

    ``A`` (N, 3, P) mm per unit parameter, ``y`` (N, 3) mm, ``W`` (N, 3, 3) whitening (inverse Cholesky factor
    of each point's covariance). Fits are weighted least squares on the training folds; errors are returned in
    mm per point (squared 3-D norm). The whitened design is kept parameter-major, (P, N, 3) C-ordered, so the
    held-out errors of a subset S read only S's columns. Memory: that design once, whitened in place when
    ``copy`` is False and ``A`` is the (N, 3, P) view of such an array (``design_array``; any other ``A`` is
    copied), one Gram matrix (P, P) per fold, and per call one block of ``CHUNK_ROWS`` rows at a time."""

    def __init__(self, A: np.ndarray, y: np.ndarray, W: np.ndarray, blockings: list[Blocking], copy: bool = True):
        N, _, P = A.shape
        At = np.asarray(A, float).transpose(2, 0, 1)                    # (P, N, 3)
        if copy or not At.flags.c_contiguous:
            At = np.array(At, order="C")
        for s in range(0, N, CHUNK_ROWS):      # whitened in row blocks: no second P x N x 3 array
            b = slice(s, s + CHUNK_ROWS)
            At[:, b] = np.einsum("nij,knj->kni", W[b], At[:, b])
        self.yw = np.einsum("nij,nj->ni", W, y)
        self.scale = np.sqrt(np.einsum("knj,knj->k", At, At))
        self.scale[self.scale == 0] = 1.0
        At /= self.scale[:, None, None]
        self._At = At
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
                Af = At[:, rows].reshape(P, -1)           # one fold's rows at a time
                per.append((rows, Af @ Af.T, Af @ self.yw[rows].reshape(-1)))
                del Af
            self._gram.append((sum(p[1] for p in per), sum(p[2] for p in per), per))
            self._fold_at.append(np.searchsorted(np.unique(b.fold), b.fold))     # (N,) index of each row's fold

    @classmethod
    def of_blocks(cls, blocks, n: int, P: int, W: np.ndarray, blockings: list[Blocking],
                  dtype=np.float32) -> "BlockedCV":
        """The same cross-validation from a design given as row blocks (rows slice, A_b (b, 3, P) mm per unit
        parameter, y_b (b, 3) mm): each block is whitened and added to every fold's Gram matrix in float64, then
        kept in ``dtype``. Every fit reads the float64 Gram matrices; only the held-out predictions read the kept
        columns, which float32 rounds to 6e-8 of their size (half the memory of the design)."""
        self = cls.__new__(cls)
        At, yw, ss = np.empty((P, n, 3), dtype), np.empty((n, 3)), np.zeros(P)
        folds = [np.searchsorted(np.unique(b.fold), b.fold) for b in blockings]
        G = [np.zeros((int(f.max()) + 1, P, P)) for f in folds]
        c = [np.zeros((int(f.max()) + 1, P)) for f in folds]
        for b, A_b, y_b in blocks:
            Aw = np.einsum("nij,njk->kni", W[b], A_b)                            # (P, b, 3) whitened
            yw[b] = np.einsum("nij,nj->ni", W[b], y_b)
            ss += np.einsum("knj,knj->k", Aw, Aw)
            for f, Gf, cf in zip(folds, G, c):
                for k in np.unique(f[b]):
                    m = f[b] == k
                    Af = Aw[:, m].reshape(P, -1)
                    Gf[k] += Af @ Af.T
                    cf[k] += Af @ yw[b][m].reshape(-1)
            At[:, b] = Aw
        self.scale = np.sqrt(ss)
        self.scale[self.scale == 0] = 1.0
        for s in range(0, n, CHUNK_ROWS):
            At[:, s:s + CHUNK_ROWS] /= self.scale[:, None, None].astype(dtype)
        self._At, self.yw, self.L, self.blockings, self.P = At, yw, np.linalg.inv(W), blockings, P
        outer = np.outer(self.scale, self.scale)
        self._gram = [(Gf.sum(axis=0) / outer, cf.sum(axis=0) / self.scale,
                       [(np.flatnonzero(f == k), Gf[k] / outer, cf[k] / self.scale) for k in range(len(Gf))])
                      for f, Gf, cf in zip(folds, G, c)]
        self._fold_at = folds
        return self

    @property
    def Aw(self) -> np.ndarray:
        """The whitened, unit-norm design (N, 3, P) in row order (a read-only view of the parameter-major array,
        not a copy)."""
        out = self._At.transpose(1, 2, 0)
        out.flags.writeable = False
        return out

    def errors(self, cols, blocking: int = 0) -> np.ndarray:
        """Held-out error vectors (N, 3) mm of the columns ``cols`` under one blocking."""
        cols = np.asarray(cols, int)
        G, c, per = self._gram[blocking]
        GS, cS = G[np.ix_(cols, cols)], c[cols]
        ridge = RIDGE * np.eye(len(cols))
        X = np.empty((len(per), len(cols)))                  # every fold's fit of ``cols``
        for f, (rows, Gf, cf) in enumerate(per):
            X[f] = np.linalg.solve(GS - Gf[np.ix_(cols, cols)] + ridge, cS - cf[cols])
        return self._predict_errors(X, cols, blocking)

    def _explained(self, G, c, base, alts) -> np.ndarray:
        """(K,) weighted sum of squares each alternative column set explains beyond ``base`` (fits on the Gram G,
        c): the larger, the smaller the residual of base + that set on the same rows."""
        every = np.concatenate(alts)
        Gbb = G[np.ix_(base, base)] + RIDGE * np.eye(len(base))
        Gbe = G[np.ix_(base, every)]
        Z = np.linalg.solve(Gbb, np.column_stack([c[base], Gbe]))       # base's share once, for every alternative
        r_all = c[every] - Gbe.T @ Z[:, 0]
        S_all = G[np.ix_(every, every)] - Gbe.T @ Z[:, 1:]
        m = len(alts[0])
        if all(len(a) == m for a in alts):            # every alternative adds its Schur complement's part (batched)
            K = len(alts)
            S = S_all.reshape(K, m, K, m)[np.arange(K), :, np.arange(K), :] + RIDGE * np.eye(m)
            r = r_all.reshape(K, m)
            return np.einsum("ki,ki->k", r, np.linalg.solve(S, r[:, :, None])[:, :, 0])
        out, at = np.empty(len(alts)), 0
        for k, a in enumerate(alts):
            i = slice(at, at + len(a))
            at += len(a)
            out[k] = r_all[i] @ np.linalg.solve(S_all[i, i] + RIDGE * np.eye(len(a)), r_all[i])
        return out

    def scan_pick(self, base_cols, alts) -> int:
        """Index of the alternative column set (each beside ``base_cols``) that fits all points best."""
        G, c, _ = self._gram[0]
        return int(np.argmax(self._explained(G, c, np.asarray(base_cols, int), [np.asarray(a, int) for a in alts])))

    def scan_errors(self, base_cols, alts, blocking: int = 0) -> np.ndarray:
        """Held-out error vectors (N, 3) mm of a scan: in every fold the alternative column set that fits the
        training rows best (beside ``base_cols``) is chosen on those rows alone and predicts the held-out rows.
        The choice is part of what is cross-validated (nested), so picking the best of many alternatives does not
        make the held-out errors optimistic."""
        base = np.asarray(base_cols, int)
        alts = [np.asarray(a, int) for a in alts]
        union = np.concatenate([base] + alts)
        where = {int(col): i for i, col in enumerate(union)}
        G, c, per = self._gram[blocking]
        X = np.zeros((len(per), len(union)))
        for f, (rows, Gf, cf) in enumerate(per):
            Gt, ct = G - Gf, c - cf
            k = int(np.argmax(self._explained(Gt, ct, base, alts)))
            cols = np.concatenate([base, alts[k]])
            x = np.linalg.solve(Gt[np.ix_(cols, cols)] + RIDGE * np.eye(len(cols)), ct[cols])
            X[f, [where[int(col)] for col in cols]] = x
        return self._predict_errors(X, union, blocking)

    def _predict_errors(self, X: np.ndarray, cols: np.ndarray, blocking: int) -> np.ndarray:
        """Held-out error vectors (N, 3) mm of the per-fold fits X (folds, len(cols)) of the columns ``cols``."""
        at = self._fold_at[blocking]
        out = np.empty((len(self.yw), 3))
        for s in range(0, len(out), CHUNK_ROWS):    # row blocks: all folds' predictions, each row keeps its own
            b = slice(s, s + CHUNK_ROWS)
            m = len(at[b])
            pred = (X @ self._At[cols, b].reshape(len(cols), -1)).reshape(len(X), m, 3)
            e_w = self.yw[b] - pred[at[b], np.arange(m)]
            out[b] = np.matmul(self.L[b], e_w[:, :, None])[:, :, 0]
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

    def nested_p(self, base_cols, extra_cols, rank_tol: float = 1e-6) -> float:
        """p-value of a nested F-test on all points: that the columns ``extra_cols`` fit nothing beyond
        ``base_cols`` (whitened rows; the residual variance estimated from them, not taken from the noise model).
        ``extra_cols`` add the rank of their unit-norm part beyond the base whose eigenvalues exceed ``rank_tol``;
        1.0 when they add none."""
        G, c, _ = self._gram[0]
        base, extra = np.asarray(base_cols, int), np.asarray(extra_cols, int)
        Gbe = G[np.ix_(base, extra)]
        Z = np.linalg.solve(G[np.ix_(base, base)] + RIDGE * np.eye(len(base)), np.column_stack([c[base], Gbe]))
        r = c[extra] - Gbe.T @ Z[:, 0]                          # what the extra columns explain beyond the base
        w, V = np.linalg.eigh(G[np.ix_(extra, extra)] - Gbe.T @ Z[:, 1:])
        keep = w > rank_tol
        k, dof = int(keep.sum()), self.yw.size - len(base) - int(keep.sum())
        if k == 0 or dof <= 0:
            return 1.0
        gained = float(np.sum((V[:, keep].T @ r) ** 2 / w[keep]))
        rss = float(np.sum(self.yw ** 2)) - float(c[base] @ Z[:, 0]) - gained
        return 0.0 if rss <= 0 else float(f_sf((gained / k) / (rss / dof), k, dof))

    def fit(self, cols) -> np.ndarray:
        """Weighted least-squares parameters of the columns ``cols`` on all points (in the units of A)."""
        cols = np.asarray(cols, int)
        G, c, _ = self._gram[0]
        x = np.linalg.solve(G[np.ix_(cols, cols)] + RIDGE * np.eye(len(cols)), c[cols])
        return x / self.scale[cols]
