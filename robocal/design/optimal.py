"""Optimal calibration experiments: which poses to measure, in which order, and what accuracy to expect.

* ``criterion`` / ``information_rows``: per candidate pose the identification Jacobian of the geometry plus the
  regressors of the pose-dependent physical effects, whitened by the measurement covariance and with every column
  scaled by the parameter's prior standard deviation (so mm, rad and rad/(N*m) compare), shape (M, 3, L).
* ``d_optimal``: N of M candidates maximising log det(I + sum A_i^T A_i) (Bayesian D-optimality: the prior
  I regularises the parameters no pose can see, whose columns then do not steer the choice), by greedy forward
  selection and an exchange pass with rank-3 updates of every candidate's quadratic form at once; every prefix
  spreads the major joints over their ranges (a nested Latin hypercube over the candidates).
* ``short_tour``: a measurement order (nearest neighbour + 2-opt) that keeps the joint moves short.
* ``prediction`` / ``predict_rms`` / ``blocked_cv``: the held-out RMS expected of the model fitted on the first n
  planned points, sqrt(floor^2 + unmodelled^2 + s0^2 trace(M(n)^-1 H_test)): the parameter covariance of exactly
  those points, the unmodelled part from blocked cross-validation of the data so far.
* ``forecast``: before measuring, the parameter std and the model's own error at the test poses of a pose set.

Shapes: q (N, n) rad; Jacobians (N, 3, P) mm per unit parameter; covariances (N, 3, 3) mm^2.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from robocal.kinematics.gravity import GravityModel
from robocal.effects.bases import effect_regressor
from robocal.effects.model import EffectChoice
from robocal.effects.library import candidates
from robocal.identify.identification import analyse_identifiability, priority_order
from robocal.identify import geometric_prior_sigma
from robocal.kinematics.models import Kinematics, ParamLayout, identification_jacobian, joint_motion_columns



def whiten_rows(J: np.ndarray, cov_mm2: np.ndarray | None) -> np.ndarray:
    """L^-1 J per point (N, 3, P), cov = L L^T (N, 3, 3) mm^2; J unchanged without a covariance."""
    if cov_mm2 is None:
        return np.asarray(J, float)
    L = np.linalg.cholesky(np.asarray(cov_mm2, float))
    return np.linalg.solve(L, np.asarray(J, float))


def information_rows(J: np.ndarray, cov_mm2: np.ndarray | None, prior_sigma: np.ndarray) -> np.ndarray:
    """Whitened rows (N, 3, L) of the columns J (N, 3, L), each scaled by its prior std (L,) (unit information
    prior in these units)."""
    return whiten_rows(J, cov_mm2) * np.asarray(prior_sigma, float)


# ---------------------------------------------------------------- D-optimal selection
class _Design:
    """The information M = I + sum over chosen A_i^T A_i, its inverse, and every candidate's 3x3 form
    S_i = A_i M^-1 A_i^T, kept current under rank-3 updates (S stored (3, 3, M): the per-candidate 3x3
    algebra runs over contiguous arrays)."""

    def __init__(self, A: np.ndarray, chosen=()) -> None:
        self.A = A
        self.flatT = np.ascontiguousarray(A.reshape(-1, A.shape[2]).T)        # (L, 3M)
        self.chosen = list(chosen)
        self.refresh()

    def refresh(self) -> None:
        """Recompute M^-1 and every S_i from scratch (removes the drift of many updates)."""
        L = self.A.shape[2]
        chosen = self.A[self.chosen].reshape(-1, L)
        self.Minv = np.linalg.inv(np.eye(L) + chosen.T @ chosen)
        B = (self.Minv @ self.flatT).reshape(L, -1, 3)                       # (L, M, 3)
        self.S = np.einsum("lmi,mjl->ijm", B, self.A)

    def _update(self, k: int, sign: float) -> None:
        """Add (sign +1) or remove (sign -1) candidate k."""
        U = self.Minv @ self.A[k].T                                # (L, 3)
        C = np.linalg.inv(np.eye(3) + sign * self.S[:, :, k])
        X = (U.T @ self.flatT).reshape(3, -1, 3).transpose(1, 2, 0)   # (M, 3, 3): A_i M^-1 A_k^T
        Xt = np.ascontiguousarray(X.transpose(1, 2, 0))           # (3, 3, M)
        Yt = np.einsum("ijm,jk->ikm", Xt, C)
        self.Minv = self.Minv - sign * U @ C @ U.T
        self.S -= sign * np.einsum("ijm,kjm->ikm", Yt, Xt)

    def add(self, k: int) -> None:
        self._update(k, 1.0)
        self.chosen.append(int(k))

    def remove(self, k: int) -> None:
        self._update(k, -1.0)
        self.chosen.remove(int(k))

    def gains(self) -> np.ndarray:
        """log det(I + S_i) (M,): the log det gained by adding each candidate."""
        return _logdet3(np.eye(3)[:, :, None] + self.S)

    def losses(self) -> np.ndarray:
        """log det lost by removing each chosen point, in ``chosen`` order."""
        return -_logdet3(np.eye(3)[:, :, None] - self.S[:, :, self.chosen])


def _logdet3(X: np.ndarray) -> np.ndarray:
    """log det of (3, 3, ...) matrices (-inf where not positive), by the explicit 3x3 formula."""
    det = (X[0, 0] * (X[1, 1] * X[2, 2] - X[1, 2] * X[2, 1])
           - X[0, 1] * (X[1, 0] * X[2, 2] - X[1, 2] * X[2, 0])
           + X[0, 2] * (X[1, 0] * X[2, 1] - X[1, 1] * X[2, 0]))
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(det > 0, np.log(np.maximum(det, 1e-300)), -np.inf)


@dataclass(frozen=True, eq=False)
class DesignResult:
    """Chosen candidate indices (N,) in greedy order (every prefix is itself a good design), the log det of
    I + sum A_i^T A_i and how many exchanges improved the greedy start."""
    chosen: np.ndarray
    logdet: float
    exchanges: int


class _Spread:
    """Joint-angle spread (a nested Latin hypercube over the candidates): each stratified joint's candidate values
    ranked; at resolution r every joint's range is cut into r bins of equal candidate count, and a candidate's
    penalty is the number of joints whose bin already holds a chosen point."""

    def __init__(self, values: np.ndarray | None, M: int) -> None:
        v = np.zeros((M, 0)) if values is None else np.asarray(values, float).reshape(M, -1)
        self.ranks = np.argsort(np.argsort(v, axis=0, kind="stable"), axis=0, kind="stable")
        self.M = M

    def penalty(self, chosen: np.ndarray, resolution: int) -> np.ndarray:
        """(M,) occupied bins over the joints at ``resolution`` bins, given the chosen (M,) bool."""
        if self.ranks.shape[1] == 0 or not chosen.any():
            return np.zeros(self.M)
        bins = self.ranks * resolution // self.M
        J = bins.shape[1]
        occ = np.zeros((J, resolution), bool)
        occ[np.broadcast_to(np.arange(J), (int(chosen.sum()), J)), bins[chosen]] = True
        return occ[np.arange(J)[None, :], bins].sum(axis=1).astype(float)

    def same_cell(self, k: int, resolution: int) -> np.ndarray:
        """(M,) bool: candidates in candidate k's bin of every joint at ``resolution``."""
        bins = self.ranks * resolution // self.M
        return np.all(bins == bins[k], axis=1)


def greedy_order(A: np.ndarray, n: int, allowed: np.ndarray | None = None, spread: np.ndarray | None = None
                 ) -> np.ndarray:
    """Greedy forward D-optimal selection of n candidates (among ``allowed`` (M,) bool), in pick order. With
    ``spread`` (M, J) joint values, step t only considers the candidates that fill the most empty bins at
    resolution t + 1 (every prefix spreads each of those joints over its range)."""
    idx = np.arange(len(A)) if allowed is None else np.flatnonzero(allowed)
    d = _Design(A[idx])
    sp = _Spread(None if spread is None else np.asarray(spread)[idx], len(idx))
    chosen = np.zeros(len(idx), bool)
    for t in range(n):
        pen = np.where(chosen, np.inf, sp.penalty(chosen, t + 1))
        k = int(np.argmax(np.where(pen == pen.min(), d.gains(), -np.inf)))
        d.add(k)
        chosen[k] = True
    return idx[np.array(d.chosen, int)]


def d_optimal(A: np.ndarray, n: int, spread: np.ndarray | None = None, max_passes: int = 1, tol: float = 1e-6
              ) -> DesignResult:
    """N = ``n`` of the M candidates A (M, 3, L) maximising log det(I + sum A_i^T A_i): greedy forward selection
    (``greedy_order``), then exchange passes: each chosen point, weakest first, is swapped for the best
    candidate in the same bin of every spread joint (the spread stays as it is), when that raises the log det
    by more than ``tol``; finally the set is re-ordered greedily (so that blocks of the order are good designs
    too)."""
    if not 0 < n <= len(A):
        raise ValueError(f"cannot choose {n} of {len(A)} candidates")
    d = _Design(A, greedy_order(A, n, spread=spread))
    sp = _Spread(spread, len(A))
    swaps = 0
    for _ in range(max_passes):
        improved = False
        for j in [d.chosen[i] for i in np.argsort(d.losses())]:
            loss = float(-_logdet3(np.eye(3) - d.S[:, :, j]))
            d.remove(j)
            chosen = np.zeros(len(A), bool)
            chosen[d.chosen] = True
            g = np.where(chosen | ~sp.same_cell(j, n), -np.inf, d.gains())
            g[j] = -np.inf
            i = int(np.argmax(g))
            if g[i] > loss + tol:
                d.add(i)
                swaps += 1
                improved = True
            else:
                d.add(j)
        d.refresh()
        if not improved:
            break
    in_set = np.zeros(len(A), bool)
    in_set[d.chosen] = True
    order = greedy_order(A, n, in_set, spread)
    L = A.shape[2]
    flat = A[order].reshape(-1, L)
    return DesignResult(order, float(np.linalg.slogdet(np.eye(L) + flat.T @ flat)[1]), swaps)


def joint_levers(J_theta: np.ndarray) -> np.ndarray:
    """RMS lever |dp/dq_j| (n,) mm/rad of every joint over the poses, from J_theta (N, 3, n) mm/rad."""
    return np.sqrt(np.mean(np.sum(np.asarray(J_theta, float) ** 2, axis=1), axis=0))


def lever_scaled(kin: Kinematics, q_rad: np.ndarray, q_over: np.ndarray | None = None) -> np.ndarray:
    """q (N, n) rad scaled by every joint's RMS lever (mm/rad) over the poses ``q_over`` (default q): the joint
    space in which space-filling designs measure distance (mm)."""
    q = np.atleast_2d(np.asarray(q_rad, float))
    over = q if q_over is None else np.atleast_2d(np.asarray(q_over, float))
    return q * joint_levers(joint_motion_columns(kin, identification_jacobian(kin, over)[1]))


def spread_joints(J_theta: np.ndarray, fraction: float = 0.25) -> np.ndarray:
    """Indices of the joints whose angle moves the point most: RMS lever (``joint_levers``) at least ``fraction``
    of the largest (the arm's major axes)."""
    lever = joint_levers(J_theta)
    return np.flatnonzero(lever >= fraction * lever.max())


def farthest_first(X: np.ndarray, n: int) -> np.ndarray:
    """n rows (n,) of X (M, d), each the farthest from those chosen before (a k-center, space-filling design),
    starting from the row nearest the centroid."""
    X = np.asarray(X, float)
    if not 0 < n <= len(X):
        raise ValueError(f"cannot choose {n} of {len(X)} candidates")
    d = np.linalg.norm(X - X[np.argmin(np.linalg.norm(X - X.mean(axis=0), axis=1))], axis=1)
    out = [int(np.argmin(d))]
    for _ in range(n - 1):
        out.append(int(np.argmax(d)))
        d = np.minimum(d, np.linalg.norm(X - X[out[-1]], axis=1))
    return np.array(out)


# ---------------------------------------------------------------- measurement order
def move_cost(q_a: np.ndarray, q_b: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray:
    """Joint-interpolated move time proxy: max_j w_j |q_b - q_a| (broadcast over leading axes), rad."""
    w = 1.0 if weights is None else np.asarray(weights, float)
    return np.max(np.abs(np.asarray(q_b, float) - np.asarray(q_a, float)) * w, axis=-1)


def short_tour(q: np.ndarray, start: np.ndarray | None = None, weights: np.ndarray | None = None,
               passes: int = 20) -> np.ndarray:
    """Order (N,) visiting the poses q (N, n) from ``start`` (n,) (default: the first pose) with short moves:
    nearest neighbour, then 2-opt on the open path (vectorised over the second edge)."""
    q = np.asarray(q, float)
    N = len(q)
    if N <= 2:
        return np.arange(N)
    D = move_cost(q[:, None, :], q[None, :, :], weights)
    if start is None:
        d0 = np.where(np.arange(N) == 0, 0.0, np.inf)
    else:
        d0 = move_cost(np.asarray(start, float), q, weights)
    order = [int(np.argmin(d0))]
    left = np.ones(N, bool)
    left[order[0]] = False
    for _ in range(N - 1):
        k = int(np.argmin(np.where(left, D[order[-1]], np.inf)))
        order.append(k)
        left[k] = False
    path = np.array(order)
    for _ in range(passes):
        better = False
        for i in range(N - 2):                  # reverse path[i+1..j]: edges (i, i+1), (j, j+1) -> (i, j), (i+1, j+1)
            a, b = path[i], path[i + 1]
            c = path[i + 2:]
            d = np.append(path[i + 3:], -1)
            old = D[a, b] + np.where(d >= 0, D[c, np.maximum(d, 0)], 0.0)
            new = D[a, c] + np.where(d >= 0, D[b, np.maximum(d, 0)], 0.0)
            k = int(np.argmax(old - new))
            if old[k] - new[k] > 1e-12:
                j = i + 2 + k
                path[i + 1: j + 1] = path[i + 1: j + 1][::-1]
                better = True
        if not better:
            break
    return path


# ---------------------------------------------------------------- the criterion's columns
def criterion_effects(kin: Kinematics, q_rad: np.ndarray, payload_kg: float) -> list[EffectChoice]:
    """The effects ``calibration.effects: auto`` may take that depend on the pose alone (gravity compliance of
    the loaded joints, gear harmonics of every joint, wrist coupling): those a choice of poses must reveal.
    Backlash and thermal terms depend on the order and time of the measurements, not on the poses."""
    meta = {"payload_kg": np.full(len(np.atleast_2d(q_rad)), float(payload_kg))}
    out = [c for c in candidates(kin, q_rad, meta, GravityModel.of_robot(kin.n))[0] if not c.build(kin.n).needs]
    return [c.with_options(harmonics=(1, 2)) if c.name == "gear_cyclic" else c
            for c in out]                    # the first two harmonics: what a pose set must reveal of a gear error


def design_columns(kin: Kinematics, q_rad: np.ndarray, meta, effects) -> tuple[np.ndarray, tuple[str, ...], np.ndarray]:
    """(J (N, 3, L) mm per unit parameter, names (L,), prior std (L,)): the identification Jacobian of every
    geometric parameter (``ParamLayout`` order) followed by the regressors of ``effects`` (EffectChoice)."""
    q = np.atleast_2d(np.asarray(q_rad, float))
    p, J = identification_jacobian(kin, q)
    layout = ParamLayout.of(kin)
    cols, names = [J], list(layout.names)
    prior = list(geometric_prior_sigma([layout.unit(n) for n in layout.names]))
    for choice in effects:
        eff = choice.build(kin.n)
        cols.append(effect_regressor(kin, q, meta, eff, jacobian=(p, J)))
        names += [f"{choice.label}.{n}" for n in eff.param_names]
        prior += list(eff.typical)
    return np.concatenate(cols, axis=2), tuple(names), np.array(prior, float)


def identifiable_count(A: np.ndarray, names: tuple[str, ...], n_geometric: int, order: list[int],
                       rank_tol: float = 1e-3) -> int:
    """How many of the columns of A (M, 3, L) the candidates can determine (geometric ones in ``order``, the
    calibration's admission order, then the effects)."""
    flat = A.reshape(-1, A.shape[2])
    full_order = list(order) + list(range(n_geometric, A.shape[2]))
    return int(analyse_identifiability(flat, names, full_order, rank_tol).keep.sum())


# ---------------------------------------------------------------- what accuracy to expect
@dataclass(frozen=True, eq=False)
class Prediction:
    """Held-out RMS (mm) predicted for the model fitted on the first ``n_points`` planned points (B,), from the
    noise floor at the test poses, the unmodelled part (blocked CV) and the parameter covariance."""
    n_points: np.ndarray
    rms_mm: np.ndarray
    floor_mm: float
    unmodelled_mm: float
    s0: float
    cv_rms_mm: float


def blocked_cv(Gw: np.ndarray, rw: np.ndarray, J: np.ndarray, r: np.ndarray, folds: int = 5
               ) -> tuple[np.ndarray, np.ndarray]:
    """Blocked cross-validation of a linearised fit: the points, in measurement order, cut into ``folds``
    consecutive blocks; each block predicted by the fit on the others. Gw (N, 3, P) whitened columns, rw (N, 3)
    whitened residuals of the fit on all points, J (N, 3, P) and r (N, 3) the same in mm. Returns per point the
    held-out squared error (N,) mm^2 and its expected part from the parameter uncertainty (N,) (mm^2 per unit
    weight variance)."""
    N, _, P = Gw.shape
    fold = np.arange(N) * folds // N
    scale = np.linalg.norm(Gw.reshape(-1, P), axis=0)
    scale[scale == 0] = 1.0
    se, var = np.empty(N), np.empty(N)
    for f in range(folds):
        tr, te = fold != f, fold == f
        A = Gw[tr].reshape(-1, P) / scale
        x = np.linalg.lstsq(A, rw[tr].reshape(-1), rcond=1e-10)[0] / scale
        se[te] = np.sum((r[te] - J[te] @ x) ** 2, axis=1)
        Cinv = np.linalg.pinv(A.T @ A, rcond=1e-12) / np.outer(scale, scale)
        var[te] = np.einsum("nip,pq,niq->n", J[te], Cinv, J[te])
    return se, var


def predict_rms(G_plan: np.ndarray, n_points: np.ndarray, H_test: np.ndarray, floor_test_mm: float,
                unmodelled_mm2: float, s0: float) -> np.ndarray:
    """Predicted held-out RMS (B,) mm of the model fitted on the first n (``n_points`` (B,)) of the planned
    points, whose whitened columns are G_plan (N, 3, P): sqrt(floor^2 + unmodelled^2 + s0^2 trace(M_n^-1 H)),
    M_n = G_n^T G_n, H_test (P, P) = mean over test poses of J^T J (mm^2)."""
    P = G_plan.shape[2]
    flat = np.asarray(G_plan, float)
    out = np.full(len(n_points), np.inf)
    for b, n in enumerate(np.asarray(n_points, int)):
        A = flat[:n].reshape(-1, P)
        scale = np.linalg.norm(A, axis=0)
        scale[scale == 0] = 1.0
        M = (A / scale).T @ (A / scale)
        if 3 * n <= P or np.linalg.cond(M) > 1e12:
            continue
        Minv = np.linalg.inv(M) / np.outer(scale, scale)
        out[b] = np.sqrt(floor_test_mm**2 + unmodelled_mm2 + s0**2 * float(np.sum(Minv * H_test)))
    return out


def prediction(G_plan: np.ndarray, n_done: int, n_points: np.ndarray, Gw: np.ndarray, rw: np.ndarray,
               J: np.ndarray, r: np.ndarray, cov_mm2: np.ndarray, J_test: np.ndarray, cov_test_mm2: np.ndarray,
               folds: int = 5) -> Prediction:
    """The learning curve after ``n_done`` measured points: their fit (whitened Gw, rw; mm J, r; covariances
    cov (N, 3, 3)) gives the unit-weight error s0 and, by blocked CV, the unmodelled part; the planned points'
    columns G_plan give the parameter covariance at every count in ``n_points``; J_test (T, 3, P) and
    cov_test (T, 3, 3) describe the held-out poses."""
    N, _, P = Gw.shape
    s0 = float(np.sqrt(np.sum(rw**2) / max(3 * N - P, 1)))
    se, var = blocked_cv(Gw, rw, J, r, folds)
    floor_cal2 = float(np.mean(np.trace(cov_mm2, axis1=1, axis2=2)))
    floor_test2 = float(np.mean(np.trace(cov_test_mm2, axis1=1, axis2=2)))
    unmodelled2 = max(0.0, float(np.mean(se)) - floor_cal2 - s0**2 * float(np.mean(var)))
    H = np.einsum("tip,tiq->pq", J_test, J_test) / max(len(J_test), 1)
    rms = predict_rms(G_plan, n_points, H, np.sqrt(floor_test2), unmodelled2, s0)
    return Prediction(np.asarray(n_points, int), rms, float(np.sqrt(floor_test2)), float(np.sqrt(unmodelled2)), s0,
                      float(np.sqrt(np.mean(se))))


# ---------------------------------------------------------------- the criterion of a pose set, and its forecast
@dataclass(frozen=True, eq=False)
class Criterion:
    """What the selection works on: whitened, prior-scaled rows A (M, 3, L) with column ``names``, the values
    (M, J) of the joints to spread (``spread_joints``), how many columns the candidates can identify, and how many
    of the geometric ones (what every calibration identifies; the effects are taken only when the data support
    them)."""
    A: np.ndarray
    names: tuple[str, ...]
    spread: np.ndarray
    identifiable: int
    identifiable_geometric: int
    levers_mm_per_rad: np.ndarray | None = None     # every joint's RMS lever over the candidates (``joint_levers``)


def criterion(kin: Kinematics, q_rad: np.ndarray, cov_mm2: np.ndarray, payload_kg: float = 0.0,
              effects: list[EffectChoice] | None = None) -> Criterion:
    """The selection criterion of candidate poses q (M, n) rad measured with covariances (M, 3, 3) mm^2: geometry
    and the pose-dependent effects ``auto`` may take (``criterion_effects``; or the given ``effects``), whitened
    and prior-scaled."""
    q = np.atleast_2d(np.asarray(q_rad, float))
    effects = criterion_effects(kin, q, payload_kg) if effects is None else effects
    J, names, prior = design_columns(kin, q, {"payload_kg": np.full(len(q), float(payload_kg))}, effects)
    A = information_rows(J, cov_mm2, prior)
    layout = ParamLayout.of(kin)
    Jq = joint_motion_columns(kin, J)
    order = priority_order(layout)
    P = identifiable_count(A, names, layout.size, order)
    P_geo = identifiable_count(A[:, :, :layout.size], names[:layout.size], layout.size, order)
    return Criterion(A, names, q[:, spread_joints(Jq)], P, P_geo, joint_levers(Jq))


@dataclass(frozen=True, eq=False)
class Forecast:
    """Before measuring: the std (P,) of the identifiable geometric parameters ``names`` (``units``: mm or rad),
    the RMS of the calibrated model's own error at the test poses (AP(theta), from the parameter covariance;
    geometry only and with the pose-dependent effects), the noise floor there, and the observability O1 / condition
    number."""
    names: tuple[str, ...]
    units: tuple[str, ...]
    std: np.ndarray
    model_rms_mm: float
    model_rms_effects_mm: float
    floor_mm: float
    O1: float
    condition_number: float


def forecast(kin: Kinematics, q_cal: np.ndarray, cov_cal: np.ndarray, q_test: np.ndarray, cov_test: np.ndarray,
             payload_kg: float = 0.0, rank_tol: float = 1e-3) -> Forecast:
    """Forecast of a pose set: calibration poses q_cal (N, n) rad with covariances (N, 3, 3) mm^2, judged at the
    test poses q_test (T, n) (covariances (T, 3, 3)); unit-weight error 1 (the covariances are right)."""
    layout = ParamLayout.of(kin)
    eff = criterion_effects(kin, q_cal, payload_kg)
    meta = lambda q: {"payload_kg": np.full(len(q), float(payload_kg))}  # noqa: E731
    J, names, _ = design_columns(kin, q_cal, meta(q_cal), eff)
    Jt, _, _ = design_columns(kin, q_test, meta(q_test), eff)
    G = whiten_rows(J, cov_cal)
    flat = G[:, :, : layout.size].reshape(-1, layout.size)
    ident = analyse_identifiability(flat, layout.names, priority_order(layout), rank_tol)
    geo = np.flatnonzero(ident.keep)
    cols = np.concatenate([geo, layout.size + np.arange(J.shape[2] - layout.size)])
    floor = float(np.sqrt(np.mean(np.trace(cov_test, axis1=1, axis2=2)))) if len(q_test) else float("nan")

    def model_rms(c):
        A = G[:, :, c].reshape(-1, len(c))
        s = np.linalg.norm(A, axis=0)
        s[s == 0] = 1.0
        cov = np.linalg.pinv((A / s).T @ (A / s), rcond=1e-12) / np.outer(s, s)
        H = np.einsum("tip,tiq->pq", Jt[:, :, c], Jt[:, :, c]) / max(len(q_test), 1)
        return cov, float(np.sqrt(max(np.sum(cov * H), 0.0)))
    cov_geo, rms_geo = model_rms(geo)
    _, rms_eff = model_rms(cols)
    return Forecast(tuple(layout.names[c] for c in geo), tuple(layout.unit(layout.names[c]) for c in geo),
                    np.sqrt(np.diag(cov_geo)), rms_geo, rms_eff, floor,
                    float(ident.observability["O1"]), float(ident.condition_number))


def space_filling(kin: Kinematics, crit: Criterion, q_rad: np.ndarray, n: int) -> tuple[np.ndarray, bool]:
    """(n candidate indices, True) chosen farthest-first in joint space scaled by each joint's lever (mm: how far
    a joint's angle moves the point), a design for a model with a non-parametric part; (the D-optimal choice with
    the spread, False) when those n do not determine every geometric parameter the candidates determine."""
    chosen = farthest_first(np.atleast_2d(q_rad) * crit.levers_mm_per_rad, n)
    layout = ParamLayout.of(kin)
    geo = crit.A[chosen][:, :, :layout.size]
    if identifiable_count(geo, crit.names[:layout.size], layout.size, priority_order(layout)) \
            >= crit.identifiable_geometric:
        return chosen, True
    return d_optimal(crit.A, n, crit.spread).chosen, False
