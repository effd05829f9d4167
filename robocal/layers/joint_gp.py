"""Joint-error GP residual layer (kind ``"joint_gp"``): what is left after the kinematic model, read as each joint's
angle error, a smooth function of that joint's own angle, moved to the SMR through the arm's Jacobian:

    e_base(q) = sum_j dp_base/dtheta_j(q) f_j(q_j),   f_j ~ GP(0, s_j^2 exp(-(q_j - q_j')^2 / (2 l_j^2))).

Transmission errors (a gear's or an encoder's cyclic errors of any order, a joint's angle-dependent deflection) have
this form. A GP over all joint angles at once (kind ``"gpr"``) has to learn each joint's error afresh at every
combination of the other joints; this layer learns one curve per joint, so a few hundred poses describe errors of
periods a 6-D GP would need dense poses for.

Reduced-rank form (Hilbert-space GP: Solin & Sarkka, Statistics and Computing 30, 2020): f_j = sum_m w_jm phi_m(q_j)
with the Laplacian's eigenfunctions phi_m on the joint's calibrated range widened by ``BOUNDARY`` (zero outside:
the prior mean, no periodic echo) and independent weights w_jm ~ N(0, S_j(omega_m)), S_j the kernel's spectral
density. The fit is Bayesian linear regression on K = sum_j M_j weights: the Gram matrix of the features is summed
over row blocks (memory bounded at any N), the hyperparameters (s_j, l_j, the noise) maximise the marginal
likelihood (analytic gradient), and the k-fold CV re-fits them on every training fold from the Gram of the training
rows (the whole one minus the fold's). The noise per axis is bounded below by the noise floor / sqrt(3).

Shapes: q (N, n) rad; residuals (N, 3) mm in the base frame; s_j in rad, l_j in rad.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import solve_triangular
from scipy.linalg.lapack import dpotrf, dpotrs, dtrtri
from scipy.optimize import minimize

from robocal.kinematics.models import Kinematics, identification_jacobian, joint_motion_columns

BOUNDARY = 1.5              # the basis lives on the calibrated range of each joint widened 1.5 x about its centre
MAX_ORDER = 40              # the basis resolves cyclic errors up to 40 periods per revolution ...
BASIS_RANGE = (8, 64)       # ... with 8 to 64 functions per joint
MIN_SPAN_RAD = np.radians(5.0)      # a joint that moves less has no curve of its own (its error is geometry)
SIGMA_RAD = (1e-7, 1e-2)    # bounds of the hyperparameters: error amplitude ...
LENGTH_RAD = (5e-3, 10.0)   # ... and length scale
STARTS_LENGTH_RAD = (0.05, 0.5)     # optimiser starts (the better optimum is kept)
BLOCK_ROWS = 4096


def joint_directions(kin: Kinematics, q_rad: np.ndarray, joints: np.ndarray) -> np.ndarray:
    """dp_smr_base / dtheta_j (N, 3, len(joints)) mm/rad."""
    _, J = identification_jacobian(kin, q_rad)
    R = kin.T_tracker_base[:3, :3]
    return np.einsum("ai,naj->nij", R, joint_motion_columns(kin, J)[:, :, joints])


@dataclass(frozen=True, eq=False)
class Basis:
    """Per used joint: centre and half-width (rad) of the domain, number of eigenfunctions."""
    centre_rad: np.ndarray
    half_rad: np.ndarray
    sizes: tuple[int, ...]

    @classmethod
    def of(cls, q_rad: np.ndarray) -> "Basis":
        lo, hi = q_rad.min(axis=0), q_rad.max(axis=0)
        half = BOUNDARY * (hi - lo) / 2
        sizes = np.clip(np.ceil(2 * MAX_ORDER * half / np.pi), *BASIS_RANGE).astype(int)
        return cls((lo + hi) / 2, half, tuple(int(m) for m in sizes))

    def omega(self) -> np.ndarray:
        """Frequencies (K,) rad^-1 of all eigenfunctions, joint by joint."""
        return np.concatenate([np.pi * np.arange(1, m + 1) / (2 * L) for m, L in zip(self.sizes, self.half_rad)])

    def owner(self) -> np.ndarray:
        """Index (K,) of the used joint of each eigenfunction."""
        return np.repeat(np.arange(len(self.sizes)), self.sizes)

    def phi(self, q_rad: np.ndarray) -> np.ndarray:
        """Eigenfunctions (N, K) at the used joints' angles q_rad (N, J); zero outside each domain."""
        own, om = self.owner(), self.omega()
        x = q_rad[:, own] - self.centre_rad[own] + self.half_rad[own]
        inside = (x >= 0) & (x <= 2 * self.half_rad[own])
        return np.where(inside, np.sin(om * x) / np.sqrt(self.half_rad[own]), 0.0)


def _features(kin: Kinematics, q_rad: np.ndarray, joints: np.ndarray, basis: Basis) -> np.ndarray:
    """Feature rows (N, 3, K): joint direction times eigenfunction."""
    A = joint_directions(kin, q_rad, joints)
    return A[:, :, basis.owner()] * basis.phi(q_rad[:, joints])[:, None, :]


@dataclass(frozen=True, eq=False)
class Gram:
    """Sufficient statistics of a linear-Gaussian fit: Phi^T Phi (K, K), Phi^T y (K,), y^T y, number of values."""
    PtP: np.ndarray
    Pty: np.ndarray
    yy: float
    n: int

    def __sub__(self, o: "Gram") -> "Gram":
        return Gram(self.PtP - o.PtP, self.Pty - o.Pty, self.yy - o.yy, self.n - o.n)


def _grams(kin, q_rad, e_mm, joints, basis, fold: np.ndarray | None) -> tuple[Gram, list[Gram]]:
    """The Gram of all rows and one per fold (none without ``fold``), summed over row blocks."""
    K = sum(basis.sizes)
    group = np.zeros(len(q_rad), int) if fold is None else np.searchsorted(np.unique(fold), fold)
    n_groups = int(group.max()) + 1 if len(group) else 1
    PtP, Pty, yy, n = np.zeros((n_groups, K, K)), np.zeros((n_groups, K)), np.zeros(n_groups), np.zeros(n_groups, int)
    for s in range(0, len(q_rad), BLOCK_ROWS):
        F = _features(kin, q_rad[s:s + BLOCK_ROWS], joints, basis)
        y, gb = e_mm[s:s + BLOCK_ROWS], group[s:s + BLOCK_ROWS]
        for k in np.unique(gb):
            P, yk = F[gb == k].reshape(-1, K), y[gb == k].reshape(-1)
            PtP[k] += P.T @ P
            Pty[k] += P.T @ yk
            yy[k] += float(yk @ yk)
            n[k] += yk.size
    whole = Gram(PtP.sum(axis=0), Pty.sum(axis=0), float(yy.sum()), int(n.sum()))
    return whole, [] if fold is None else [Gram(PtP[k], Pty[k], float(yy[k]), int(n[k])) for k in range(n_groups)]


def _prior(theta: np.ndarray, omega: np.ndarray, owner: np.ndarray, J: int) -> tuple[np.ndarray, ...]:
    """Prior variances lambda (K,) of the weights from log s (J,), log l (J,), and their derivatives."""
    s, l = np.exp(theta[:J])[owner], np.exp(theta[J:2 * J])[owner]
    lam = s**2 * np.sqrt(2 * np.pi) * l * np.exp(-0.5 * (omega * l) ** 2) + 1e-30
    return lam, 2 * lam, lam * (1 - (omega * l) ** 2)


def _posterior(g: Gram, lam: np.ndarray, var: float):
    """Cholesky factor C of B = PtP / var + diag(1 / lam) and the posterior mean alpha = B^-1 PtY / var."""
    B = g.PtP / var
    B[np.diag_indices_from(B)] += 1.0 / lam
    C, info = dpotrf(B.T, lower=1, clean=1, overwrite_a=1)    # B.T: B's own memory in Fortran order (B symmetric)
    if info != 0:
        raise np.linalg.LinAlgError(f"posterior precision not positive definite (LAPACK dpotrf info {info})")
    return C, dpotrs(C, g.Pty / var, lower=1)[0]


def _nll(theta: np.ndarray, g: Gram, omega, owner, J: int, floor_var: float):
    """Negative log marginal likelihood and its gradient in theta = (log s (J,), log l (J,), log excess noise)."""
    lam, dlam_ds, dlam_dl = _prior(theta, omega, owner, J)
    sd = np.sqrt(floor_var) + np.exp(theta[-1])
    var = sd**2
    try:
        C, alpha = _posterior(g, lam, var)
    except np.linalg.LinAlgError:
        return 1e30, np.zeros_like(theta)
    b = g.Pty / var
    Binv_diag = np.sum(dtrtri(C, lower=1)[0] ** 2, axis=0)       # diag(B^-1): column norms of C^-1
    f = 0.5 * (g.yy / var - b @ alpha + g.n * np.log(var) + 2 * np.sum(np.log(np.diag(C))) + np.sum(np.log(lam)))
    d_lam = 0.5 * (-(alpha**2) / lam**2 - Binv_diag / lam**2 + 1.0 / lam)
    grad_s = np.bincount(owner, d_lam * dlam_ds, J)
    grad_l = np.bincount(owner, d_lam * dlam_dl, J)
    # PtP = var (B - diag(1/lam)) and B alpha = b: the traces and forms below need no other (K, K) product
    tr_Binv_PtP = var * (len(lam) - np.sum(Binv_diag / lam))
    a_PtP_a = var * (alpha @ b - np.sum(alpha**2 / lam))
    d_var = 0.5 * (-g.yy / var**2 + 2 * (alpha @ g.Pty) / var**2 - a_PtP_a / var**2 + g.n / var
                   - tr_Binv_PtP / var**2)
    return f, np.concatenate([grad_s, grad_l, [d_var * 2 * sd * np.exp(theta[-1])]])


def _fit_hyper(g: Gram, basis: Basis, floor_var: float) -> np.ndarray:
    """theta maximising the marginal likelihood (best of the ``STARTS_LENGTH_RAD`` starts)."""
    J, omega, owner = len(basis.sizes), basis.omega(), basis.owner()
    noise0 = np.log(max(np.sqrt(max(g.yy / max(g.n, 1) - floor_var, 0.0)) * 0.5, 1e-4))
    bounds = [tuple(np.log(SIGMA_RAD))] * J + [tuple(np.log(LENGTH_RAD))] * J + [(np.log(1e-6), np.log(10.0))]
    best = None
    for l0 in STARTS_LENGTH_RAD:
        x0 = np.concatenate([np.full(J, np.log(1e-4)), np.full(J, np.log(l0)), [noise0]])
        r = minimize(_nll, x0, args=(g, omega, owner, J, floor_var), jac=True, method="L-BFGS-B", bounds=bounds)
        if best is None or r.fun < best.fun:
            best = r
    return best.x


@dataclass(frozen=True, eq=False)
class JointGPResidual:
    """The fitted layer: the kinematics whose joint axes carry the errors, the used joints (0-based), the basis,
    per joint amplitude and length scale (rad), noise per axis (mm), posterior mean weights (K,) and the Cholesky
    factor (K, K) of the posterior precision, the noise floor that bounded the noise (3-D, mm) and the training size."""
    kinematics: Kinematics
    joints: np.ndarray
    basis: Basis
    sigma_rad: np.ndarray
    length_rad: np.ndarray
    noise_mm: float
    weights: np.ndarray
    precision_chol: np.ndarray
    noise_floor_mm: float | None = None
    n_train: int = 0

    kind = "joint_gp"
    approximation = "reduced-rank joint curves"

    def predict(self, q_rad: np.ndarray, p_base_mm: np.ndarray | None = None, payload_kg=None) -> np.ndarray:
        """Predicted residual (N, 3) mm in the base frame at q_rad (N, n); p_base_mm and payload_kg unused."""
        q = np.atleast_2d(np.asarray(q_rad, float))
        return np.concatenate([_features(self.kinematics, q[s:s + BLOCK_ROWS], self.joints, self.basis) @ self.weights
                               for s in range(0, len(q), BLOCK_ROWS)]) if len(q) else np.zeros((0, 3))

    def predict_std(self, q_rad: np.ndarray, p_base_mm: np.ndarray | None = None, payload_kg=None,
                    include_noise: bool = True) -> np.ndarray:
        """Predictive standard deviation (N, 3) mm per base-frame axis."""
        q = np.atleast_2d(np.asarray(q_rad, float))
        F = _features(self.kinematics, q, self.joints, self.basis)           # (N, 3, K)
        Z = solve_triangular(self.precision_chol, F.reshape(-1, F.shape[2]).T, lower=True)
        var = np.sum(Z**2, axis=0).reshape(len(q), 3)
        return np.sqrt(var + (self.noise_mm**2 if include_noise else 0.0))

    def features(self, q_rad: np.ndarray) -> np.ndarray:
        """The layer's feature rows (N, 3, K) at q_rad (N, n): residual = features @ weights (mm, base frame)."""
        return _features(self.kinematics, np.atleast_2d(np.asarray(q_rad, float)), self.joints, self.basis)

    def prior_std(self) -> np.ndarray:
        """Prior standard deviation (K,) of every weight under the fitted amplitudes and length scales."""
        theta = np.log(np.concatenate([self.sigma_rad, self.length_rad, [1.0]]))
        return np.sqrt(_prior(theta, self.basis.omega(), self.basis.owner(), len(self.joints))[0])

    def curves_rad(self, q_rad: np.ndarray) -> np.ndarray:
        """Each used joint's fitted angle error f_j(q_j) (N, J) rad at q_rad (N, n)."""
        P = self.basis.phi(np.atleast_2d(q_rad)[:, self.joints]) * self.weights
        return np.stack([P[:, self.basis.owner() == j].sum(axis=1) for j in range(len(self.joints))], axis=1)

    def curve_rms_rad(self, points: int = 200) -> dict[int, float]:
        """RMS (rad) of each used joint's fitted angle error over its calibrated range, keyed by 1-based joint."""
        t = np.linspace(-1.0, 1.0, points)[:, None] / BOUNDARY
        q = self.basis.centre_rad + t * self.basis.half_rad                 # (points, J): the calibrated ranges
        P = self.basis.phi(q) * self.weights
        own = self.basis.owner()
        return {int(j) + 1: float(np.sqrt(np.mean(P[:, own == i].sum(axis=1) ** 2)))
                for i, j in enumerate(self.joints)}

    def to_dict(self) -> dict:
        K = len(self.weights)
        low = np.tril_indices(K)
        return {"kind": self.kind, "frame": "base", "units": {"inputs": "rad (joints)", "outputs": "mm",
                                                              "sigma": "rad", "length": "rad"},
                "kinematics": self.kinematics.to_dict(), "joints": [int(j) + 1 for j in self.joints],
                "centre_rad": self.basis.centre_rad.tolist(), "half_width_rad": self.basis.half_rad.tolist(),
                "basis_sizes": list(self.basis.sizes), "sigma_rad": self.sigma_rad.tolist(),
                "length_rad": self.length_rad.tolist(), "noise_mm": self.noise_mm,
                "noise_floor_mm": self.noise_floor_mm, "n_train": self.n_train, "weights": self.weights.tolist(),
                "precision_chol_lower": self.precision_chol[low].tolist()}

    @classmethod
    def from_dict(cls, d: dict) -> "JointGPResidual":
        basis = Basis(np.array(d["centre_rad"], float), np.array(d["half_width_rad"], float),
                      tuple(int(m) for m in d["basis_sizes"]))
        w = np.array(d["weights"], float)
        C = np.zeros((len(w), len(w)))
        C[np.tril_indices(len(w))] = np.array(d["precision_chol_lower"], float)
        floor = d.get("noise_floor_mm")
        return cls(Kinematics.from_dict(d["kinematics"]), np.array(d["joints"], int) - 1, basis,
                   np.array(d["sigma_rad"], float), np.array(d["length_rad"], float), float(d["noise_mm"]), w, C,
                   None if floor is None else float(floor), int(d.get("n_train", 0)))


def used_joints(q_rad: np.ndarray) -> np.ndarray:
    """The joints (0-based) that move at least ``MIN_SPAN_RAD`` over q_rad (N, n)."""
    return np.flatnonzero(np.ptp(np.atleast_2d(q_rad), axis=0) >= MIN_SPAN_RAD)


def _layer(kin, joints, basis, g: Gram, floor_var: float, floor_mm) -> JointGPResidual:
    theta = _fit_hyper(g, basis, floor_var)
    J = len(joints)
    lam = _prior(theta, basis.omega(), basis.owner(), J)[0]
    sd = np.sqrt(floor_var) + np.exp(theta[-1])
    C, alpha = _posterior(g, lam, sd**2)
    return JointGPResidual(kin, joints, basis, np.exp(theta[:J]), np.exp(theta[J:2 * J]), float(sd), alpha, C,
                           floor_mm, g.n // 3)


def fit_joint_gp(kin: Kinematics, q_rad: np.ndarray, e_base_mm: np.ndarray, noise_floor_mm: float | None = None,
                 fold: np.ndarray | None = None) -> tuple[JointGPResidual | None, np.ndarray | None]:
    """(layer fitted on all rows, k-fold held-out errors (N, 3) mm or None without ``fold``) of the residuals
    e_base_mm (N, 3) at q_rad (N, n); hyperparameters re-fitted on every training fold. (None, None) when no joint
    moves ``MIN_SPAN_RAD``."""
    q = np.atleast_2d(np.asarray(q_rad, float))
    e = np.asarray(e_base_mm, float)
    joints = used_joints(q)
    if len(joints) == 0:
        return None, None
    basis = Basis.of(q[:, joints])
    floor_var = 0.0 if noise_floor_mm is None else float(noise_floor_mm) ** 2 / 3.0
    whole, per_fold = _grams(kin, q, e, joints, basis, fold)
    layer = _layer(kin, joints, basis, whole, floor_var, noise_floor_mm)
    if fold is None:
        return layer, None
    err = np.empty_like(e)
    for k, g in zip(np.unique(fold), per_fold):
        part = _layer(kin, joints, basis, whole - g, floor_var, noise_floor_mm)
        te = fold == k
        err[te] = e[te] - part.predict(q[te])
    return layer, err


PRIOR_SIGMA_RAD = 3.5e-5        # design prior of a joint's angle-error curve: a gear harmonic's typical amplitude ...
PRIOR_LENGTH_RAD = 1.0 / MAX_ORDER      # ... varying up to the highest order the basis resolves


def prior_columns(kin: Kinematics, q_rad: np.ndarray, sigma_rad: float = PRIOR_SIGMA_RAD,
                  length_rad: float = PRIOR_LENGTH_RAD) -> tuple[np.ndarray, tuple[str, ...], np.ndarray]:
    """The layer's weights as columns of a design criterion, before any measurement: (J (N, 3, K) mm per unit
    weight, names (K,), prior std (K,)) at candidate poses q_rad (N, n), the basis on the candidates' range."""
    q = np.atleast_2d(np.asarray(q_rad, float))
    joints = used_joints(q)
    if len(joints) == 0:
        return np.zeros((len(q), 3, 0)), (), np.zeros(0)
    basis = Basis.of(q[:, joints])
    lam = _prior(np.concatenate([np.full(len(joints), np.log(sigma_rad)), np.full(len(joints), np.log(length_rad)),
                                 [0.0]]), basis.omega(), basis.owner(), len(joints))[0]
    own = basis.owner()
    m = np.concatenate([np.arange(1, s + 1) for s in basis.sizes])
    names = tuple(f"joint_gp.J{joints[o] + 1}.m{k}" for o, k in zip(own, m))
    return _features(kin, q, joints, basis), names, np.sqrt(lam)
