"""Registration, identifiability analysis and parameter identification.

Residuals are always the x/y/z components ``p_meas - p_model`` in the tracker frame (never one distance
per point), optionally whitened by each point's 3x3 measurement covariance. Two estimators:

* ``lm``: Levenberg-Marquardt least squares;
* ``robust_ridge``: seed 000 eq. 9-12, Gauss-Newton steps ``dx = (A^T P A + mu I)^-1 A^T P r`` on
  column-scaled normal equations, re-weighted with IGG3 (or Huber) on standardized residuals until
  ``max |dx| < eps``.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .lm import Normal, levenberg_marquardt
from .whitened import DESIGN_ROWS, DesignFactor, r_factor, whiten, whiten_t, whitening
from robocal.kinematics.frames import fit_rigid, make_T, rotvec_to_matrix, skew
from robocal.kinematics.models import (Kinematics, ParamLayout, apply_update, fk, jacobian_blocks,
                                       parameter_difference, smr_base, smr_tracker)
from .parameters import GEOMETRY, ParameterTable


class IdentificationError(ValueError):
    """The data cannot support an identification (too few points, degenerate pose set, ...)."""


@dataclass(frozen=True)
class CalibrationOptions:
    """Options of ``calibrate``. ``fixed`` names parameters kept at their start values."""
    method: str = "robust_ridge"      # robust_ridge | lm
    weights: str = "igg3"             # igg3 | huber | none (robust_ridge only)
    k0: float = 1.5
    k1: float = 2.5
    ridge_mu: float = 1e-6            # on the column-scaled normal equations
    max_iter: int = 100
    step_tol: float = 1e-7            # max |dx| (mm or rad) for convergence
    rank_tol: float = 1e-3            # relative residual of a scaled column below which it is unidentifiable
    sigma0: str = "mad"               # mad | posterior: unit-weight error used to standardize residuals
    fixed: tuple[str, ...] = ()
    register: bool = True


@dataclass(frozen=True)
class Unidentifiable:
    """A parameter fixed because the pose set cannot determine it."""
    name: str
    redundant_with: tuple[str, ...]
    reason: str

    def to_dict(self) -> dict:
        return {"name": self.name, "redundant_with": list(self.redundant_with), "reason": self.reason}


@dataclass(frozen=True, eq=False)
class CalibrationResult:
    """Identified model with its uncertainties and diagnostics.

    ``delta``/``std`` follow ``names`` (all candidates; std NaN where not identified), in mm or rad;
    the base entries are relative to the registered start frame. ``point_weights`` (N,) are the final
    robust weights (0 = rejected); ``residual_tracker_mm`` (N, 3) = measured - model. ``condition_number`` and
    ``observability`` are those of the column-scaled, whitened Jacobian of the identified parameters at the solution
    (the quantity ``robocal.design.optimal.forecast`` predicts at the nominal geometry).
    """
    kinematics: Kinematics
    start: Kinematics
    names: tuple[str, ...]
    identified: tuple[str, ...]
    delta: np.ndarray
    std: np.ndarray
    unidentifiable: tuple[Unidentifiable, ...]
    condition_number: float
    observability: dict
    point_weights: np.ndarray
    residual_tracker_mm: np.ndarray
    sigma0: float
    iterations: int
    converged: bool
    units: tuple[str, ...] = field(default=())

    def parameters_table(self) -> list[dict]:
        """One dict per candidate: name, unit, delta, std, identified."""
        ident = set(self.identified)
        return [{"name": n, "unit": u, "delta": float(d), "std": None if not np.isfinite(s) else float(s),
                 "identified": n in ident}
                for n, u, d, s in zip(self.names, self.units, self.delta, self.std)]

    def table(self) -> ParameterTable:
        """The parameter record of the geometric model (``robocal.identify.parameters``)."""
        return ParameterTable.of(self.kinematics, self.start, self.identified, self.std, GEOMETRY, self.sigma0)


# ---------------------------------------------------------------- registration
def register(kin: Kinematics, q_rad: np.ndarray, p_tracker_mm: np.ndarray, weights=None) -> Kinematics:
    """Closed-form first guess of T_tracker_base from nominal vs measured SMR points (any distance/rotation)."""
    p_nom = smr_base(kin, q_rad)
    if len(p_nom) < 3 or np.linalg.matrix_rank(p_nom - p_nom.mean(0), tol=1.0) < 2:
        raise IdentificationError("registration needs at least 3 non-collinear points")
    return kin.with_(T_tracker_base=fit_rigid(p_nom, p_tracker_mm, weights))


TOOL_DIRECTION_TOL = 0.01      # an SMR-offset direction is registered when the poses' orientations turn it by
                               # more than ~0.6 deg RMS (its residual then exceeds 1 % of the offset error)
HUBER_C = 2.5                  # robust registration: points beyond 2.5 x the median residual are down-weighted


@dataclass(frozen=True, eq=False)
class ToolRegistration:
    """Base frame and SMR offsets registered together on a fixed (nominal) geometry.

    ``T_tracker_base`` (4, 4) mm; ``p_flange_smr_mm`` (k, 3) mm, one row per SMR; ``determined`` how many of the
    3k offset directions the pose set determines (the others keep their start values: with one SMR orientation
    an offset cannot be told from a base translation); ``weights`` (N,) the final robust point weights."""
    T_tracker_base: np.ndarray
    p_flange_smr_mm: np.ndarray
    determined: int
    weights: np.ndarray


def _registered_points(R_flange, t_flange, offsets, R, t):
    """(k, N, 3): SMR centres in the tracker frame for offsets (k, 3), flange poses (N, 3, 3) / (N, 3)."""
    return (np.einsum("nij,kj->kni", R_flange, offsets) + t_flange) @ R.T + t


def register_tool(kin: Kinematics, q_rad: np.ndarray, p_tracker_mm: np.ndarray, p_flange_smr_mm=None,
                  max_iter: int = 30) -> ToolRegistration:
    """Register T_tracker_base and the SMR offsets together on the geometry of ``kin``: a small robust
    (Huber) Gauss-Newton fit of 6 + 3k parameters from the closed-form registration at the start offsets.

    ``p_tracker_mm`` (N, 3) for one SMR or (k, N, 3) for k SMRs; ``p_flange_smr_mm`` (3,) or (k, 3) start
    offsets (default ``kin.p_flange_smr_mm``). Offset directions the poses' orientations do not turn by more
    than ``TOOL_DIRECTION_TOL`` (rad RMS) keep their start values."""
    q = np.atleast_2d(np.asarray(q_rad, float))
    P = np.asarray(p_tracker_mm, float)
    P = P[None] if P.ndim == 2 else P
    k, N = P.shape[0], P.shape[1]
    offs = np.array(kin.p_flange_smr_mm if p_flange_smr_mm is None else p_flange_smr_mm, float).reshape(k, 3)
    T_flange = fk(kin, q)
    Rf, tf = T_flange[:, :3, :3].copy(), T_flange[:, :3, 3].copy()
    del T_flange
    a = np.einsum("nij,kj->kni", Rf, offs) + tf
    if N < 3 or np.linalg.matrix_rank(a[0] - a[0].mean(0), tol=1.0) < 2:
        raise IdentificationError("registration needs at least 3 non-collinear points")
    T = fit_rigid(a.reshape(-1, 3), P.reshape(-1, 3))
    del a
    R, t = T[:3, :3], T[:3, 3]
    w = np.ones(N)
    basis = None
    for _ in range(max_iter):
        if N <= DESIGN_ROWS:
            A, b = _tool_design(Rf, tf, offs, R, t, P, w)
            if basis is None:                                                # fixed at the start offsets
                basis = _determined_tool_directions(A, np.sqrt(np.sum(w)))
            A = np.column_stack([A[:, :6], A[:, 6:] @ basis])
            D = np.maximum(np.linalg.norm(A, axis=0), 1e-12)
            x = np.linalg.lstsq(A / D, b, rcond=None)[0] / D
        else:                                      # the same least squares from the factor of [A b] over row blocks
            Ab = DesignFactor(np.column_stack(_tool_design(Rf[r], tf[r], offs, R, t, P[:, r], w[r]))
                              for r in _blocks(N)).R
            if basis is None:
                basis = _determined_tool_directions(Ab[:, :-1], np.sqrt(np.sum(w)))
            m = 6 + basis.shape[1]
            M = np.zeros((Ab.shape[1], m + 1))
            M[:6, :6], M[6:-1, 6:m], M[-1, m] = np.eye(6), basis, 1.0
            Rr = np.linalg.qr(Ab @ M, mode="r")
            D = np.maximum(np.linalg.norm(Rr[:, :m], axis=0), 1e-12)
            x = np.linalg.lstsq(Rr[:m, :m] / D, Rr[:m, m], rcond=None)[0] / D
        R, t = rotvec_to_matrix(x[:3]) @ R, t + x[3:6]
        offs = offs + (basis @ x[6:]).reshape(k, 3)
        e = np.linalg.norm(P - _registered_points(Rf, tf, offs, R, t), axis=2).max(axis=0)     # (N,)
        scale = max(float(np.median(e)), 1e-9)
        w_new = np.minimum(1.0, HUBER_C * scale / np.maximum(e, 1e-300))
        done = np.max(np.abs(x[3:])) < 1e-7 and np.max(np.abs(x[:3])) < 1e-10 and np.max(np.abs(w_new - w)) < 1e-4
        w = w_new
        if done:
            break
    return ToolRegistration(make_T(R, t), offs, int(basis.shape[1]), w)


def _tool_design(Rf, tf, offs, R, t, P, w) -> tuple[np.ndarray, np.ndarray]:
    """(A (3kN, 6 + 3k), b (3kN,)) of one Gauss-Newton step of ``register_tool``, weighted by sqrt(w) (N,)."""
    k, N = P.shape[0], P.shape[1]
    pred = _registered_points(Rf, tf, offs, R, t)
    r = P - pred                                                         # (k, N, 3)
    J = np.zeros((k, N, 3, 6 + 3 * k))
    J[..., :3] = -skew(pred - t)
    J[..., 3:6] = np.eye(3)
    for s in range(k):
        J[s, :, :, 6 + 3 * s:9 + 3 * s] = R @ Rf
    sw = np.sqrt(np.broadcast_to(w[None, :, None], r.shape)).reshape(-1)
    return J.reshape(-1, 6 + 3 * k) * sw[:, None], r.reshape(-1) * sw


def _determined_tool_directions(A: np.ndarray, tool_norm: float) -> np.ndarray:
    """(3k, m) orthonormal offset directions whose effect on the points is not a rigid motion: the SVD of the
    offset columns of A (M, 6 + 3k) projected off the registration columns, kept above TOOL_DIRECTION_TOL."""
    reg = A[:, :6] / np.maximum(np.linalg.norm(A[:, :6], axis=0), 1e-12)
    Q = np.linalg.qr(reg)[0]
    tool = A[:, 6:] - Q @ (Q.T @ A[:, 6:])
    _, s, Vt = np.linalg.svd(tool, full_matrices=False)
    return Vt[s / tool_norm > TOOL_DIRECTION_TOL].T


# ---------------------------------------------------------------- weighting
def igg3_weight(v_std: np.ndarray, k0: float = 1.5, k1: float = 2.5) -> np.ndarray:
    """IGG3 equivalent-weight factor of seed 000 eq. 12 for standardized residuals."""
    a = np.abs(v_std)
    mid = k0 / np.maximum(a, 1e-300) * ((k1 - a) / (k1 - k0)) ** 2
    return np.where(a <= k0, 1.0, np.where(a <= k1, mid, 0.0))


def huber_weight(v_std: np.ndarray, k0: float = 1.5) -> np.ndarray:
    """Huber equivalent-weight factor."""
    a = np.abs(v_std)
    return np.where(a <= k0, 1.0, k0 / np.maximum(a, 1e-300))


# ---------------------------------------------------------------- identifiability
@dataclass(frozen=True)
class Identifiability:
    keep: np.ndarray               # (P,) bool
    unidentifiable: tuple[Unidentifiable, ...]
    condition_number: float
    observability: dict
    rel: np.ndarray                # (P,) relative residual of each column against the ones admitted before it


def priority_order(layout: ParamLayout) -> list[int]:
    """Order in which candidates are admitted: base, tool, then joints from the last to the first.

    With this order the redundant member of each classical pair is the one dropped: theta1 (base rz),
    d1 (base z), d2 (d3 on parallel axes), last-joint parameters (SMR offset)."""
    nj = len(layout.joint_cols)
    joint_cols = sorted(layout.joint_cols, key=lambda c: (-c[1], c[2]))
    return list(range(nj, layout.size)) + [c[0] for c in joint_cols]


def observability_indices(A: np.ndarray) -> dict:
    """Observability indices of a column-scaled Jacobian A (m, L) with singular values s1 >= ... >= sL: O1 =
    (s1 s2 ... sL)^(1/L) / sqrt(m) (Borm & Menq 1991), O2 = sL / s1 (Driels & Pathre 1990), O3 = sL (Nahvi,
    Hollerbach & Hayward 1994), O4 = sL^2 / s1 (Nahvi & Hollerbach 1996), O5 = 1 / sum(1 / s) (Sun & Hollerbach
    2008)."""
    return _indices(np.linalg.svd(A, compute_uv=False), *A.shape)


def observability_of_normal(N: np.ndarray, m: int) -> dict:
    """``observability_indices`` of the column-normalised A (m, L) from its normal matrix N = A^T A (L, L) alone:
    its singular values are the square roots of the eigenvalues of D^-1 N D^-1, D = sqrt(diag N)."""
    d = np.sqrt(np.maximum(np.diag(N), 1e-300))
    ev = np.linalg.eigvalsh(N / np.outer(d, d))[::-1]
    return _indices(np.sqrt(np.maximum(ev, 0.0)), m, len(N))


def _indices(s: np.ndarray, m: int, L: int) -> dict:
    """The indices of the singular values s (L,), descending, of a column-normalised A with m rows."""
    if L == 0 or s[-1] <= 0:
        return {"O1": 0.0, "O2": 0.0, "O3": 0.0, "O4": 0.0, "O5": 0.0, "condition_number": float("inf")}
    return {"O1": float(np.exp(np.mean(np.log(s))) / np.sqrt(m)), "O2": float(s[-1] / s[0]), "O3": float(s[-1]),
            "O4": float(s[-1] ** 2 / s[0]), "O5": float(1.0 / np.sum(1.0 / s)), "condition_number": float(s[0] / s[-1])}


def analyse_identifiability(A: np.ndarray, names: tuple[str, ...], order: list[int], rank_tol: float,
                            fixed: tuple[str, ...] = ()) -> Identifiability:
    """Admit columns of A (m, P) in ``order`` when their part orthogonal to the admitted ones keeps more
    than ``rank_tol`` of their (unit-scaled) norm; the rest are reported with what they are redundant with.
    Works on A's triangular factor (``r_factor``): the same answer, with no (m, P) temporaries."""
    A = r_factor(np.asarray(A, float))
    norms = np.linalg.norm(A, axis=0)
    keep = np.zeros(A.shape[1], bool)
    rels = np.zeros(A.shape[1])
    Q = np.zeros((A.shape[0], 0))
    dropped = []
    for j in order:
        if names[j] in fixed:
            dropped.append(Unidentifiable(names[j], (), "fixed by the user"))
            continue
        if norms[j] < 1e-9 * norms.max():
            dropped.append(Unidentifiable(names[j], (), "no effect on the measured points"))
            continue
        c = A[:, j] / norms[j]
        r = c - Q @ (Q.T @ c)
        rel = rels[j] = np.linalg.norm(r)
        if rel > rank_tol:
            keep[j] = True
            Q = np.column_stack([Q, r / rel])
            continue
        acc = np.flatnonzero(keep)
        beta = np.linalg.lstsq(A[:, acc] / norms[acc], c, rcond=None)[0]
        top = acc[np.argsort(-np.abs(beta))][: 3]
        top = [names[t] for t, b in zip(top, np.sort(-np.abs(beta))[:3]) if -b > 0.1 * np.max(np.abs(beta))]
        dropped.append(Unidentifiable(names[j], tuple(top), f"linearly dependent (relative residual {rel:.1e})"))
    idx = np.flatnonzero(keep)
    obs = observability_indices(A[:, idx] / norms[idx])
    return Identifiability(keep, tuple(dropped), obs["condition_number"], obs, rels)


# ---------------------------------------------------------------- estimation
def _blocks(n: int) -> list[slice]:
    """Row blocks of ``DESIGN_ROWS`` poses."""
    return [slice(s, min(s + DESIGN_ROWS, n)) for s in range(0, n, DESIGN_ROWS)]


class _Design:
    """The whitened, column-scaled identification design of the columns ``cols`` at one model: A (3N, P) kept as
    the transpose of a C-ordered (P, 3N) array (A^T A and A^T r are single BLAS calls on each block) and the
    whitened residual r (3N,), computed in row blocks of ``DESIGN_ROWS`` poses (the Jacobian of every candidate
    is never held for all rows); its products (normal equations, A x, leverages) are sums over the same blocks."""

    def __init__(self, kin, q, p_meas, W, cols, D):
        n = len(q)
        At, r = np.empty((len(cols), n, 3)), np.empty((n, 3))
        for b, p, Jt in jacobian_blocks(kin, q, DESIGN_ROWS):
            Wb = None if W is None else W[b]
            r[b] = whiten(Wb, p_meas[b] - p)
            At[:, b] = whiten_t(Wb, Jt, cols)
        At /= D[:, None, None]
        self.A, self.r = At.reshape(len(cols), -1).T, r.reshape(-1)
        self.rows = [slice(3 * b.start, 3 * b.stop) for b in _blocks(n)]

    def gram(self, w_rows: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(A^T P A, A^T P r) with the row weights P = diag(w_rows) (3N,) (None: unit weights)."""
        A, r = self.A, self.r
        if w_rows is None:
            return sum(A[b].T @ A[b] for b in self.rows), sum(A[b].T @ r[b] for b in self.rows)
        return (sum(A[b].T @ (w_rows[b, None] * A[b]) for b in self.rows),
                sum(A[b].T @ (w_rows[b] * r[b]) for b in self.rows))

    def normal(self) -> Normal:
        H, g = self.gram()
        return Normal(H, g, float(self.r @ self.r), len(self.r))

    def times(self, x: np.ndarray) -> np.ndarray:
        """A x (3N,)."""
        return np.concatenate([self.A[b] @ x for b in self.rows])

    def leverage(self, M: np.ndarray) -> np.ndarray:
        """diag(A M A^T) (3N,) of a (P, P) matrix M."""
        return np.concatenate([np.einsum("ij,jk,ik->i", self.A[b], M, self.A[b]) for b in self.rows])


def _full_design(kin, q, W):
    """Row blocks (3b, P) of the whitened design of every candidate parameter (unit scale) at ``kin``."""
    for b, _, Jt in jacobian_blocks(kin, q, DESIGN_ROWS):
        yield whiten_t(None if W is None else W[b], Jt).reshape(len(Jt), -1).T


def _apply(kin, layout, cols, dx_scaled, D):
    full = np.zeros(layout.size)
    full[cols] = dx_scaled / D
    return apply_update(kin, full), full[cols]


def _normal(kin, q, p_meas, W, cols, D) -> Normal:
    """``_Design(...).normal()`` accumulated block by block, the design of each block dropped once added."""
    if len(q) <= DESIGN_ROWS:
        return _Design(kin, q, p_meas, W, cols, D).normal()
    out = None
    for b, p, Jt in jacobian_blocks(kin, q, DESIGN_ROWS):
        Wb = None if W is None else W[b]
        At = whiten_t(Wb, Jt, cols)
        At /= D[:, None, None]
        ne = Normal.of(whiten(Wb, p_meas[b] - p).reshape(-1), At.reshape(len(cols), -1).T)
        out = ne if out is None else out + ne
    return out


def _weighted_normal(kin, q, p_meas, W, cols, D, w) -> tuple[np.ndarray, np.ndarray, float]:
    """(A^T A, A^T P A, r^T P r) of ``_Design`` with the point weights w (N,) (P = w per row), block by block."""
    N0, N, wrr = 0.0, 0.0, 0.0
    for b in _blocks(len(q)) if len(q) > DESIGN_ROWS else [slice(0, len(q))]:
        design = _Design(kin, q[b], p_meas[b], None if W is None else W[b], cols, D)
        w_rows = np.repeat(w[b], 3)
        N0 = N0 + design.gram()[0]
        N = N + design.gram(w_rows)[0]
        wrr = wrr + np.sum(w_rows * design.r**2)
    return N0, N, float(wrr)


def _levenberg_marquardt(kin, q, p_meas, W, cols, D, layout, opt):
    fit = levenberg_marquardt(kin, lambda k: _normal(k, q, p_meas, W, cols, D),
                              lambda k, dx: _apply(k, layout, cols, dx, D), opt.ridge_mu, opt.max_iter, opt.step_tol)
    return fit.state, np.ones(len(q)), fit.iterations, fit.converged


def _standardized(design, v, w_rows, Ninv, p, sigma0_mode):
    """Standardized residuals v / (sigma0 sqrt(q_v)), q_v = 1/P - a N^-1 a^T on the original unit weights
    (1/P + a N^-1 a^T for rejected rows). sigma0 is the a-posteriori unit-weight error of the weighted fit
    (``posterior``, seed 000) or its robust MAD estimate (``mad``), which does not shrink as IGG3 trims the
    tails and so cannot cascade into rejecting good points."""
    h = design.leverage(Ninv)
    qv = np.where(w_rows > 0, np.maximum(1.0 - w_rows * h, 1e-6), 1.0 + h)
    u = v / np.sqrt(qv)
    if sigma0_mode == "mad":
        sigma0 = 1.4826 * np.median(np.abs(u))
    else:
        sigma0 = np.sqrt(np.sum(w_rows * v**2) / max(np.count_nonzero(w_rows) - p, 1))
    return u / max(sigma0, 1e-300), sigma0


FREEZE_WEIGHTS_AFTER = 30


def _robust_ridge(kin, q, p_meas, W, cols, D, layout, opt):
    n, p = len(q), len(cols)
    w = np.ones(n)
    converged = False
    for it in range(1, opt.max_iter + 1):
        design = _Design(kin, q, p_meas, W, cols, D)
        w_rows = np.repeat(w, 3)
        N, g = design.gram(w_rows)
        N = N + opt.ridge_mu * np.eye(p)
        dx = np.linalg.solve(N, g)
        kin, step = _apply(kin, layout, cols, dx, D)
        if opt.weights == "none":
            w_new = w
        else:
            v = design.times(dx) - design.r         # seed 000 eq. 10
            v_std, _ = _standardized(design, v, w_rows, np.linalg.inv(N), p, opt.sigma0)
            v_pt = np.sqrt(np.mean(v_std.reshape(n, 3) ** 2, axis=1))   # one statistic per point (x, y, z)
            w_new = igg3_weight(v_pt, opt.k0, opt.k1) if opt.weights == "igg3" else huber_weight(v_pt, opt.k0)
        small = np.max(np.abs(step)) < opt.step_tol
        if small and np.max(np.abs(w_new - w)) < 1e-3:
            converged = True
            break
        if it < FREEZE_WEIGHTS_AFTER:          # then the weights are frozen: borderline points cannot oscillate
            w = w_new
        if np.count_nonzero(w) * 3 <= p:
            raise IdentificationError("robust weighting rejected too many points to identify the model")
    return kin, w, it, converged


def calibrate(kin0: Kinematics, q_rad: np.ndarray, p_tracker_mm: np.ndarray, cov_mm2: np.ndarray | None = None,
              options: CalibrationOptions = CalibrationOptions()) -> CalibrationResult:
    """Identify base, tool and joint parameters from joint angles (N, n) rad and measured SMR points
    (N, 3) mm in the tracker frame; ``cov_mm2`` (N, 3, 3) optional measurement covariances."""
    q = np.atleast_2d(np.asarray(q_rad, float))
    p_meas = np.asarray(p_tracker_mm, float)
    if len(q) != len(p_meas):
        raise IdentificationError(f"{len(q)} joint vectors but {len(p_meas)} measured points")
    kin = register(kin0, q, p_meas) if options.register else kin0
    start = kin
    layout = ParamLayout.of(kin)
    W = whitening(cov_mm2, len(q))
    solver = _levenberg_marquardt if options.method == "lm" else _robust_ridge
    cols, iters = None, 0
    for _ in range(3):
        # identifiability depends on where the model is (theta6, a5, alpha5 are degenerate while the SMR estimate
        # sits on the J6 axis): re-analyse at the solution and re-solve when a parameter became clearly
        # identifiable (10x the rank tolerance, so a borderline column never enters on the way)
        full = DesignFactor(_full_design(kin, q, W))
        ident = analyse_identifiability(full.R, layout.names, priority_order(layout), options.rank_tol,
                                        options.fixed)
        if cols is None:
            cols = np.flatnonzero(ident.keep)
        else:
            strong = {c for c in np.flatnonzero(ident.keep) if c not in set(cols) and ident.rel[c] > 10 * options.rank_tol}
            if not strong:
                break
            cols = np.array([c for c in np.flatnonzero(ident.keep) if c in set(cols) | strong])
        if 3 * len(q) <= len(cols):
            raise IdentificationError(f"{len(q)} points cannot determine {len(cols)} parameters")
        D = full.norms(cols)
        kin, w, it, converged = solver(kin, q, p_meas, W, cols, D, layout, options)
        iters += it
    identified = set(cols)
    ident = Identifiability(np.isin(np.arange(layout.size), cols),
                            tuple(u for u in ident.unidentifiable if layout.index(u.name) not in identified)
                            + tuple(Unidentifiable(layout.names[c], (), "identifiable only marginally at the solution; "
                                                   "kept at its start value") for c in np.flatnonzero(ident.keep)
                                    if c not in identified),
                            ident.condition_number, ident.observability, ident.rel)
    N0, N, wrr = _weighted_normal(kin, q, p_meas, W, cols, D, w)
    # the identified columns only: a column admitted only marginally at the solution is kept at its start value
    # and amplifies no noise into the identified ones (it would turn a good condition number into a poor one)
    obs = observability_of_normal(N0, 3 * len(q))
    n_eff = 3 * np.count_nonzero(w)
    sigma0 = float(np.sqrt(wrr / max(n_eff - len(cols), 1)))
    cov_scaled = sigma0**2 * np.linalg.pinv(N)
    std = np.full(layout.size, np.nan)
    std[cols] = np.sqrt(np.diag(cov_scaled)) / D
    p_model = smr_tracker(kin, q)
    return CalibrationResult(
        kinematics=kin, start=start, names=layout.names, identified=tuple(layout.names[c] for c in cols),
        delta=parameter_difference(kin, start), std=std, unidentifiable=ident.unidentifiable,
        condition_number=obs["condition_number"], observability=obs, point_weights=w,
        residual_tracker_mm=p_meas - p_model, sigma0=sigma0, iterations=iters, converged=converged,
        units=tuple(layout.unit(n) for n in layout.names))
