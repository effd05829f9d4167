"""Adaptive pose selection: the next batch of poses, chosen with the model fitted to the poses measured so far.

The fitted model is described to the selection by its uncertainty, term by term (each a Bayesian description of
one part of the model, updated exactly when a candidate is added, whatever it will measure):

* ``LinearTerm``: a linear-Gaussian part, y = B w + noise, w ~ N(0, I) in prior-scaled units. The parametric model
  (geometry and effects linearised at the fit; rows whitened by the measurement covariance, columns scaled by the
  parameters' prior std, variance scaled by the fit's s0^2) and the joint-error GP layer (its reduced-rank features,
  prior std per weight, rows whitened by the layer's noise) are both of this kind.
* ``KernelTerm``: a GP layer with a squared-exponential ARD kernel on the joint angles (the GPR layer, or a GP
  fitted to the residuals when the model has no GP layer).

Every term answers, for every candidate: how much measuring it lowers the mean predictive variance at the task
poses (``reduction``, mm^2; I-optimality) and how much it tells about the term (``information``, nats: D-optimality,
"the parameters least determined"). ``choose_batch`` picks greedily by the sum over the terms; the variance is the
model's own prediction variance (at the task poses, without the noise), so the sum of the terms' variances plus the
noise floor and the part no term describes is the predicted held-out mean square error. ``Coverage`` asks nothing
of the model: rule ``f`` picks the candidate farthest from every pose (a space-filling continuation), and the terms
still say what each pick removes of the variance.

Shapes: A (M, 3, L) whitened prior-scaled rows; B (T, 3, L) prior-scaled rows at the task poses (mm per unit);
X (M, d) kernel inputs divided by the length scales.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

CRITERIA = ("i", "d", "df", "f")  # i: integrated variance at the task poses; d: information about the model;
#                                   f: the farthest candidate from every pose (``Coverage``); df: d and f in turn


class LinearTerm:
    """A linear-Gaussian part of the model over M candidates: posterior precision I + sum A_i^T A_i over the
    measured rows and the candidates chosen since, with G = A M^-1 and Q = G H kept under rank-3 updates.
    ``scale_mm2`` turns the unit-noise variance into mm^2 (the fit's s0^2 x ... )."""

    def __init__(self, A_cand: np.ndarray, A_done: np.ndarray, B_task: np.ndarray, scale_mm2: float = 1.0) -> None:
        L = A_cand.shape[2]
        self.flat = np.ascontiguousarray(A_cand.reshape(-1, L))                    # (3M, L)
        done = np.asarray(A_done, float).reshape(-1, L)
        B = np.asarray(B_task, float)
        self.H = np.einsum("tip,tiq->pq", B, B) / max(len(B), 1)
        self.Minv = np.linalg.inv(np.eye(L) + done.T @ done)
        self.G = self.flat @ self.Minv                                               # (3M, L)
        self.Q = self.G @ self.H
        self.scale = float(scale_mm2)

    def _forms(self, X: np.ndarray, Y: np.ndarray) -> np.ndarray:
        """Per candidate the 3 x 3 form X_c Y_c^T (M, 3, 3) of rows X, Y (3M, L)."""
        M = len(self.flat) // 3
        return np.einsum("mil,mjl->mij", X.reshape(M, 3, -1), Y.reshape(M, 3, -1))

    def task_variance(self) -> float:
        """Mean predictive variance of this term at the task poses (mm^2, three axes summed)."""
        return self.scale * float(np.sum(self.Minv * self.H))

    def reduction(self) -> np.ndarray:
        """(M,) mm^2: task variance removed by measuring each candidate, trace((I + S_c)^-1 T_c)."""
        S, T = self._forms(self.G, self.flat), self._forms(self.Q, self.G)
        return self.scale * np.einsum("mij,mji->m", np.linalg.inv(np.eye(3) + S), T)

    def information(self) -> np.ndarray:
        """(M,) nats: log det(I + S_c), what measuring each candidate tells about this term's weights."""
        sign, logdet = np.linalg.slogdet(np.eye(3) + self._forms(self.G, self.flat))
        return np.where(sign > 0, logdet, 0.0)

    def add(self, k: int) -> None:
        """Measure candidate k: M += A_k^T A_k."""
        Ak = self.flat[3 * k: 3 * k + 3]                                             # (3, L)
        U = self.Minv @ Ak.T                                                         # (L, 3)
        C = np.linalg.inv(np.eye(3) + Ak @ U)
        AU = self.flat @ U                                                           # (3M, 3)
        self.G -= (AU @ C) @ U.T
        self.Q -= (AU @ C) @ (U.T @ self.H)
        self.Minv -= U @ C @ U.T


class KernelTerm:
    """A GP over kernel inputs (length-scaled, so the kernel is exp(-|x - x'|^2 / 2)) with signal variance
    ``signal_mm2`` (three axes summed) and noise ``noise_ratio2`` = noise / signal variance; the posterior
    covariance between the task poses and the candidates is kept under rank-1 updates."""

    def __init__(self, X_cand: np.ndarray, X_done: np.ndarray, X_task: np.ndarray, signal_mm2: float,
                 noise_ratio2: float) -> None:
        self.X, self.s2, self.r2 = np.asarray(X_cand, float), float(signal_mm2), max(float(noise_ratio2), 1e-8)
        D = np.asarray(X_done, float)
        Kdd = _se(D, D) + self.r2 * np.eye(len(D))
        self.Ld = np.linalg.cholesky(Kdd) if len(D) else np.zeros((0, 0))
        self.D = D
        self.Zc = self._solve(_se(D, self.X))                                        # (N, M)
        Zt = self._solve(_se(D, X_task))
        self.cov_tc = _se(np.asarray(X_task, float), self.X) - Zt.T @ self.Zc        # (T, M)
        self.var_c = np.maximum(1.0 - np.sum(self.Zc**2, axis=0), 0.0)
        self.var_t = float(np.mean(np.maximum(1.0 - np.sum(Zt**2, axis=0), 0.0)))
        self.V = np.zeros((0, len(self.X)))                                          # rows of the picks' updates

    def _solve(self, K: np.ndarray) -> np.ndarray:
        return np.linalg.solve(self.Ld, K) if len(self.D) else np.zeros((0, K.shape[1]))

    def task_variance(self) -> float:
        return self.s2 * self.var_t

    def reduction(self) -> np.ndarray:
        return self.s2 * np.mean(self.cov_tc**2, axis=0) / (self.var_c + self.r2)

    def information(self) -> np.ndarray:
        return 3.0 * np.log1p(self.var_c / self.r2)

    def add(self, k: int) -> None:
        c = _se(self.X[k: k + 1], self.X)[0] - self.Zc[:, k] @ self.Zc - self.V[:, k] @ self.V
        v = c / np.sqrt(max(c[k], 0.0) + self.r2)
        w = self.cov_tc[:, k] / np.sqrt(max(c[k], 0.0) + self.r2)
        self.var_t -= float(np.mean(w**2))
        self.cov_tc -= np.outer(w, v)
        self.var_c = np.maximum(self.var_c - v**2, 0.0)
        self.V = np.vstack([self.V, v])


def _se(Xa: np.ndarray, Xb: np.ndarray) -> np.ndarray:
    """Unit squared-exponential kernel (Na, Nb) of length-scaled inputs."""
    d2 = np.sum(Xa**2, 1)[:, None] + np.sum(Xb**2, 1)[None, :] - 2.0 * Xa @ Xb.T
    return np.exp(-0.5 * np.maximum(d2, 0.0))


class Coverage:
    """Distance (M,) of every candidate X_cand (M, d) to the nearest pose of X_done (N, d) and of the picks since:
    the part of the design that asks nothing of the model (what no term describes is best found by spreading).
    With task poses X_task (T, d) (where the robot will work) the picks cover the task instead of every candidate:
    each the free candidate nearest the task pose farthest from every pose measured or picked (once every task pose
    is itself measured or picked, the farthest candidate again)."""

    def __init__(self, X_cand: np.ndarray, X_done: np.ndarray, X_task: np.ndarray | None = None) -> None:
        self.X = np.asarray(X_cand, float)
        D = np.asarray(X_done, float).reshape(-1, self.X.shape[1])
        self.dist = _nearest(self.X, D)
        self.task = None if X_task is None else np.asarray(X_task, float).reshape(-1, self.X.shape[1])
        self.task_dist = None if self.task is None else _nearest(self.task, D)

    def pick(self, free: np.ndarray) -> int:
        """The next candidate among ``free`` (M,) bool: the farthest from every pose, or the nearest the task pose
        farthest from every pose."""
        if self.task is None or not np.max(self.task_dist) > 0:          # no task, or every task pose measured
            return int(np.argmax(np.where(free, self.dist, -np.inf)))
        t = self.task[int(np.argmax(self.task_dist))]
        return int(np.argmin(np.where(free, np.linalg.norm(self.X - t, axis=1), np.inf)))

    def add(self, k: int) -> None:
        self.dist = np.minimum(self.dist, np.linalg.norm(self.X - self.X[k], axis=1))
        if self.task is not None:
            self.task_dist = np.minimum(self.task_dist, np.linalg.norm(self.task - self.X[k], axis=1))


def _nearest(X: np.ndarray, D: np.ndarray) -> np.ndarray:
    """Distance (M,) of every row of X (M, d) to the nearest row of D (N, d) (inf without D), in chunks of D."""
    dist = np.full(len(X), np.inf)
    for chunk in np.array_split(D, max(1, len(D) // 64)) if len(D) else []:
        dist = np.minimum(dist, np.min(np.linalg.norm(X[:, None] - chunk[None], axis=2), axis=1))
    return dist


@dataclass(frozen=True, eq=False)
class Batch:
    """Candidates chosen (B,) in pick order; the mean predictive variance of the model at the task poses (mm^2,
    the terms summed) before the batch and after each pick (B + 1,)."""
    chosen: np.ndarray
    task_variance_mm2: np.ndarray


def choose_batch(terms, n: int, available: np.ndarray, criterion: str = "i", cover: Coverage | None = None) -> Batch:
    """Greedy batch of ``n`` candidates among ``available`` (M,) bool: each pick the candidate with the largest
    sum over ``terms`` of the task variance it removes (``criterion`` "i") or of the information it brings ("d");
    "f": ``cover``'s pick (the candidate farthest from every pose, or nearest the least covered task pose); "df":
    the picks of "d" and "f" in turn, "d" first.
    Every term is updated before the next pick (the variances do not depend on what will be measured)."""
    if criterion not in CRITERIA:
        raise ValueError(f"unknown criterion {criterion!r} (expected one of {CRITERIA})")
    if "f" in criterion and cover is None:
        raise ValueError(f"criterion {criterion!r} needs the candidates' coverage")
    free = np.asarray(available, bool).copy()
    chosen, curve = [], [sum(t.task_variance() for t in terms)]
    for j in range(min(n, int(free.sum()))):
        if criterion == "f" or (criterion == "df" and j % 2):
            k = cover.pick(free)
        else:
            g = sum((t.reduction() if criterion == "i" else t.information()) for t in terms)
            k = int(np.argmax(np.where(free, g, -np.inf)))
        for t in terms:
            t.add(k)
        if cover is not None:
            cover.add(k)
        free[k] = False
        chosen.append(k)
        curve.append(sum(t.task_variance() for t in terms))
    return Batch(np.array(chosen, int), np.array(curve, float))


def learning_curve(A: np.ndarray, B_task: np.ndarray, floor_mm: float, sizes) -> np.ndarray:
    """Before measuring: the held-out RMS (len(sizes),) mm of the model fitted on the first n rows of A (N, 3, L)
    (whitened by the noise model, prior-scaled: a parameter no row determines keeps its prior) for every n in
    ``sizes``, at the task rows B_task (T, 3, L): sqrt(floor^2 + trace(H (I + sum_{i<n} A_i^T A_i)^-1)), H the
    task's mean B^T B. What the model cannot express is not in it."""
    L = A.shape[2]
    H = np.einsum("tip,tiq->pq", B_task, B_task) / max(len(B_task), 1)
    out, M, done = [], np.eye(L), 0
    for n in sizes:
        rows = A[done:n].reshape(-1, L)
        M, done = M + rows.T @ rows, max(done, n)
        out.append(np.sqrt(floor_mm**2 + max(float(np.sum(H * np.linalg.inv(M))), 0.0)))
    return np.array(out)
