"""6D pose of a three-SMR tool from one measured and two GPR-predicted SMRs, with measurement adjustment
(seed 003 §2-3, eq. 10-25).

Offline (§2 steps 2-3): at many joint configurations the tracker measures SMRs 2 and 3; their errors
``delta_k = P_k^M - P_k^N`` (eq. 10, tracker frame, ``P^N = T_tracker_base Fkine(q) p_flange_k``) train one GPR
model per SMR and per axis (Omega_2, Omega_3; the seed's Omega_1, Omega_2 for its target points 1 and 2).
Online (steps 4-5): SMR 1 is measured, SMRs 2 and 3 are predicted (eq. 11), and a rigid 3-point fit of the
tool's flange-frame coordinates to the three points gives the flange pose in the tracker frame.
Adjustment (§3): observations ``L = [P1, P2, P3, d12, d13, d23]`` (12) must satisfy the rigid-body conditions
``Gamma_ij = |P_i - P_j|^2 - d_ij^2 = 0`` (eq. 12). With the weight matrix of eq. 20 (tracker spherical
propagation for P1, eq. 14-16; tracker + GPR variance for P2, P3, eq. 17-18; CMM length uncertainty for the
d_ij, eq. 19) the corrections minimise ``Delta^T P Delta`` subject to the linearised conditions (eq. 22-25);
the linearisation is iterated (Gauss-Newton on the constrained problem) until the adjusted values satisfy
the conditions exactly. The unit-weight variance sigma0^2 of eq. 16/18/19 scales every weight alike and
cancels from the corrections (it is a parameter only for fidelity to the equations); the a-posteriori
variance factor ``sqrt(v^T D^-1 v / 3)`` (about 1 when the covariances are right) is reported instead.

Tracker frame: the tracker at the origin; spherical coordinates of the seed: ``x = rho sinV cosH``,
``y = rho sinV sinH``, ``z = rho cosV`` (H azimuth, V zenith). Lengths mm, angles rad (degrees in names).
Everything is batched over poses (leading dimension N).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from robocal.kinematics.frames import make_T, transform_points
from robocal.layers.gp import MultiOutputGP
from robocal.kinematics.models import Kinematics, fk
from robocal.measure.noise import TrackerUncertainty, cartesian_to_spherical

PAIRS = ((0, 1), (0, 2), (1, 2))           # d12, d13, d23


# ---------------------------------------------------------------- tool
@dataclass(frozen=True, eq=False)
class SMRTool:
    """Three SMRs on a tool: centres ``p_flange_mm`` (3, 3) in the flange frame (row 0 = SMR 1, measured online;
    rows 1, 2 = SMRs 2 and 3, predicted), CMM-measured distances ``d_mm`` (d12, d13, d23; default from the
    coordinates) and the CMM length uncertainty ``sigma_d = a + b * d`` (eq. 19; a in um, b in um/m)."""
    p_flange_mm: np.ndarray
    d_mm: np.ndarray | None = None
    cmm_a_um: float = 2.5
    cmm_b_um_per_m: float = 3.0

    def __post_init__(self):
        p = np.asarray(self.p_flange_mm, float).reshape(3, 3)
        object.__setattr__(self, "p_flange_mm", p)
        d = pair_distances(p[None])[0] if self.d_mm is None else np.asarray(self.d_mm, float)
        object.__setattr__(self, "d_mm", d)

    def sigma_d_mm(self) -> np.ndarray:
        """Standard uncertainty (3,) mm of d12, d13, d23 (eq. 19)."""
        return (self.cmm_a_um + self.cmm_b_um_per_m * self.d_mm / 1000.0) / 1000.0


def seed003_tool(z_mm: float = 80.0) -> SMRTool:
    """A tool with the CMM distances of seed 003 Table 4 (d12 = 144.833, d13 = 210.149, d23 = 210.684 mm): the
    SMR triangle in a plane z = z_mm of the flange frame, centred on the flange axis (about 150 x 200 mm)."""
    d12, d13, d23 = 144.833, 210.149, 210.684
    x3 = (d13**2 - d23**2 + d12**2) / (2 * d12)
    p = np.array([[0.0, 0.0], [d12, 0.0], [x3, np.sqrt(d13**2 - x3**2)]])
    p -= p.mean(axis=0)
    return SMRTool(np.column_stack([p, np.full(3, z_mm)]), np.array([d12, d13, d23]))


def pair_distances(points_mm: np.ndarray) -> np.ndarray:
    """(N, 3, 3) points -> (N, 3) distances d12, d13, d23."""
    return np.stack([np.linalg.norm(points_mm[:, i] - points_mm[:, j], axis=1) for i, j in PAIRS], axis=1)


# ---------------------------------------------------------------- tracker error propagation (eq. 14-16)
def spherical_jacobian(p_tracker_mm: np.ndarray) -> np.ndarray:
    """C_L (N, 3, 3) = d(x, y, z) / d(H, V, rho) (eq. 14; the printed matrix has typos in three entries)."""
    rho, H, V = cartesian_to_spherical(np.atleast_2d(p_tracker_mm))
    sH, cH, sV, cV = np.sin(H), np.cos(H), np.sin(V), np.cos(V)
    C = np.empty((len(rho), 3, 3))
    C[:, :, 0] = np.stack([-rho * sV * sH, rho * sV * cH, np.zeros_like(rho)], 1)
    C[:, :, 1] = np.stack([rho * cV * cH, rho * cV * sH, -rho * sV], 1)
    C[:, :, 2] = np.stack([sV * cH, sV * sH, cV], 1)
    return C


def spherical_covariance(p_tracker_mm: np.ndarray, sigma_H_rad, sigma_V_rad, sigma_rho_mm) -> np.ndarray:
    """D_XYZ^M (N, 3, 3) mm^2 = C_L diag(sigma_H^2, sigma_V^2, sigma_rho^2) C_L^T (eq. 15); sigmas scalar or (N,)."""
    C = spherical_jacobian(p_tracker_mm)
    n = len(C)
    D = np.stack([np.broadcast_to(np.asarray(s, float) ** 2, (n,)) for s in (sigma_H_rad, sigma_V_rad, sigma_rho_mm)], 1)
    return np.einsum("nij,nj,nkj->nik", C, D, C)


def tracker_spherical_sigmas(tracker: TrackerUncertainty, p_tracker_mm: np.ndarray):
    """(sigma_H rad, sigma_V rad, sigma_rho mm), each (N,), from the MPE model of noise.py: a transverse
    uncertainty u_t is an angle u_t / rho in V and u_t / (rho sinV) in H; the range one is u_r."""
    rho, _, V = cartesian_to_spherical(np.atleast_2d(p_tracker_mm))
    u_r, u_t = tracker.sigmas_mm(rho)
    return u_t / (rho * np.sin(V)), u_t / rho, u_r


def measured_covariance(tracker: TrackerUncertainty, p_tracker_mm: np.ndarray) -> np.ndarray:
    """D_XYZ^M (N, 3, 3) mm^2 of tracker measurements by the spherical propagation of eq. 14-15."""
    return spherical_covariance(p_tracker_mm, *tracker_spherical_sigmas(tracker, p_tracker_mm))


# ---------------------------------------------------------------- adjustment (eq. 12-25)
def conditions(L: np.ndarray, with_jacobian: bool = True):
    """Closing errors Gamma (N, 3) mm^2 of observations L (N, 12) (eq. 12) and C = dGamma/dL (N, 3, 12)."""
    P, d = L[:, :9].reshape(-1, 3, 3), L[:, 9:]
    G = np.empty((len(L), 3))
    C = np.zeros((len(L), 3, 12)) if with_jacobian else None
    for k, (i, j) in enumerate(PAIRS):
        diff = P[:, i] - P[:, j]
        G[:, k] = np.sum(diff**2, axis=1) - d[:, k] ** 2
        if with_jacobian:
            C[:, k, 3 * i:3 * i + 3] = 2 * diff
            C[:, k, 3 * j:3 * j + 3] = -2 * diff
            C[:, k, 9 + k] = -2 * d[:, k]
    return (G, C) if with_jacobian else G


def weight_matrix_inverse(cov_points_mm2: np.ndarray, sigma_d_mm: np.ndarray, sigma0: float = 1.0) -> np.ndarray:
    """P_M^-1 (N, 12, 12) = sigma0^2 blockdiag(D_1, D_2, D_3, D_d) (eq. 16, 18, 19, 20).
    cov_points (N, 3, 3, 3) per point; sigma_d (3,) or (N, 3) mm."""
    N = len(cov_points_mm2)
    Q = np.zeros((N, 12, 12))
    for k in range(3):
        Q[:, 3 * k:3 * k + 3, 3 * k:3 * k + 3] = cov_points_mm2[:, k]
    idx = np.arange(9, 12)
    Q[:, idx, idx] = np.broadcast_to(np.asarray(sigma_d_mm, float) ** 2, (N, 3))
    return sigma0**2 * Q


@dataclass(frozen=True, eq=False)
class Adjustment:
    """Result of the condition adjustment: adjusted points (N, 3, 3) and distances (N, 3), corrections
    Delta_M (N, 12) (eq. 21), a-posteriori variance factor sqrt(Delta^T D^-1 Delta / 3) (N,) (3 redundant
    conditions; about 1 when the a-priori covariances D are right, independent of sigma0),
    iterations used, converged (N,) and the final condition residual |P_i - P_j| - d_ij (N, 3) mm."""
    points_mm: np.ndarray
    distances_mm: np.ndarray
    corrections: np.ndarray
    sigma0_post: np.ndarray
    iterations: int
    converged: np.ndarray
    residual_mm: np.ndarray


def adjust_points(points_mm: np.ndarray, cov_points_mm2: np.ndarray, d_mm: np.ndarray, sigma_d_mm: np.ndarray,
                  sigma0: float = 1.0, tol_mm: float = 1e-10, max_iter: int = 20) -> Adjustment:
    """Least-squares condition adjustment of three points and their three distances (eq. 21-25), iterated.

    At iterate L_k (Delta_k = L_k - L_M) the conditions are linearised, ``Gamma(L_k) + C_k (Delta - Delta_k) = 0``,
    and ``Delta = P^-1 C_k^T lambda`` with ``lambda = (C_k P^-1 C_k^T)^-1 (C_k Delta_k - Gamma(L_k))`` (eq. 24-25;
    the first iteration is exactly the seed's single linearised step). Stops when every distance condition
    holds to ``tol_mm``. points (N, 3, 3), cov (N, 3, 3, 3) mm^2, d (3,) or (N, 3), sigma_d (3,) or (N, 3).
    """
    P0 = np.asarray(points_mm, float)
    N = len(P0)
    L_M = np.concatenate([P0.reshape(N, 9), np.broadcast_to(np.asarray(d_mm, float), (N, 3))], axis=1)
    Qinv = weight_matrix_inverse(np.asarray(cov_points_mm2, float), sigma_d_mm, sigma0)
    delta = np.zeros((N, 12))
    it, done = 0, np.zeros(N, bool)
    for it in range(1, max_iter + 1):
        G, C = conditions(L_M + delta)
        rhs = np.einsum("nij,nj->ni", C, delta) - G
        S = np.einsum("nij,njk,nlk->nil", C, Qinv, C)
        lam = np.linalg.solve(S, rhs[..., None])[..., 0]
        delta = np.einsum("nij,nkj,nk->ni", Qinv, C, lam)
        done = np.max(np.abs(_distance_residual(L_M + delta)), axis=1) < tol_mm
        if done.all():
            break
    L_A = L_M + delta
    Dinv = np.linalg.inv(Qinv / sigma0**2)
    s0 = np.sqrt(np.einsum("ni,nij,nj->n", delta, Dinv, delta) / 3.0)
    return Adjustment(L_A[:, :9].reshape(N, 3, 3), L_A[:, 9:], delta, s0, it, done, _distance_residual(L_A))


def _distance_residual(L: np.ndarray) -> np.ndarray:
    return pair_distances(L[:, :9].reshape(-1, 3, 3)) - L[:, 9:]


# ---------------------------------------------------------------- rigid 3-point pose
def fit_points_pose(p_local_mm: np.ndarray, points_mm: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray:
    """Batched Kabsch: T (N, 4, 4) minimising sum_k w_k |T p_local_k - points_k|^2 for points (N, K, 3) and
    local coordinates p_local (K, 3) (K >= 3 non-collinear)."""
    a = np.asarray(p_local_mm, float)
    b = np.asarray(points_mm, float)
    w = np.ones(len(a)) if weights is None else np.asarray(weights, float)
    w = w / w.sum()
    ca, cb = w @ a, np.einsum("k,nkj->nj", w, b)
    Hm = np.einsum("ki,nkj->nij", (a - ca) * w[:, None], b - cb[:, None])
    U, _, Vt = np.linalg.svd(Hm)
    V = np.swapaxes(Vt, 1, 2)
    d = np.sign(np.linalg.det(V @ np.swapaxes(U, 1, 2)))
    D = np.zeros((len(b), 3, 3))
    D[:, 0, 0], D[:, 1, 1], D[:, 2, 2] = 1.0, 1.0, d
    R = V @ D @ np.swapaxes(U, 1, 2)
    return make_T(R, cb - np.einsum("nij,j->ni", R, ca))


def euler_xyz_deg(R: np.ndarray) -> np.ndarray:
    """(N, 3, 3) -> (N, 3) angles (E_X, E_Y, E_Z) deg with R = Rz(E_Z) Ry(E_Y) Rx(E_X) (fixed axes x, y, z);
    for small rotations these are the rotation-vector components delta_theta of eq. 3."""
    R = np.asarray(R, float)
    ey = np.arcsin(np.clip(-R[:, 2, 0], -1.0, 1.0))
    ex = np.arctan2(R[:, 2, 1], R[:, 2, 2])
    ez = np.arctan2(R[:, 1, 0], R[:, 0, 0])
    return np.degrees(np.stack([ex, ey, ez], axis=1))


def orientation_error_deg(T_est: np.ndarray, T_ref: np.ndarray, R_frame: np.ndarray | None = None) -> np.ndarray:
    """Euler angles (N, 3) deg of R_est R_ref^T, expressed in the axes of R_frame (e.g. R_base_tracker)."""
    E = T_est[:, :3, :3] @ np.swapaxes(T_ref[:, :3, :3], 1, 2)
    if R_frame is not None:
        E = R_frame @ E @ R_frame.T
    return euler_xyz_deg(E)


# ---------------------------------------------------------------- estimator (§2)
@dataclass(frozen=True, eq=False)
class PoseEstimate:
    """Online estimate: flange pose T_tracker_flange (N, 4, 4) from the (adjusted, if requested) points; the
    three points before (N, 3, 3) and after adjustment (or None); GPR standard deviation (N, 2, 3) of SMRs 2, 3."""
    T_tracker_flange: np.ndarray
    points_mm: np.ndarray
    adjusted_mm: np.ndarray | None
    gpr_std_mm: np.ndarray
    adjustment: Adjustment | None


@dataclass(frozen=True, eq=False)
class MultiSMRPoseEstimator:
    """Kinematic model (with T_tracker_base) for P^N, the tool, the GPR models Omega_2 and Omega_3 (tracker-frame
    errors of SMRs 2 and 3 versus joint angles) and the tracker uncertainty for the weights."""
    kinematics: Kinematics
    tool: SMRTool
    omega: tuple[MultiOutputGP, MultiOutputGP]
    tracker: TrackerUncertainty = TrackerUncertainty()

    @classmethod
    def fit(cls, kin: Kinematics, tool: SMRTool, q_rad: np.ndarray, p2_tracker_mm: np.ndarray,
            p3_tracker_mm: np.ndarray, tracker: TrackerUncertainty = TrackerUncertainty(), n_restarts: int = 2,
            seed: int = 0) -> "MultiSMRPoseEstimator":
        """Offline step: errors of SMRs 2 and 3 (eq. 10) at joint angles q (N, n) -> Omega_2, Omega_3."""
        PN = nominal_points(kin, tool, q_rad)
        om = tuple(MultiOutputGP.fit(q_rad, p - PN[:, k], n_restarts=n_restarts, seed=seed + 10 * k)
                   for k, p in ((1, p2_tracker_mm), (2, p3_tracker_mm)))
        return cls(kin, tool, om, tracker)

    def predict(self, q_rad: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Predicted SMRs 2, 3 (N, 2, 3) in the tracker frame (eq. 11) and their GPR std (N, 2, 3) (eq. 8)."""
        PN = nominal_points(self.kinematics, self.tool, q_rad)
        out = [om.predict_std(q_rad) for om in self.omega]
        return PN[:, 1:] + np.stack([m for m, _ in out], 1), np.stack([s for _, s in out], 1)

    def covariances(self, points_mm: np.ndarray, gpr_std_mm: np.ndarray) -> np.ndarray:
        """(N, 3, 3, 3): D^M of SMR 1 (eq. 15) and D^Pre of SMRs 2, 3 (eq. 17: diagonal of the tracker's
        covariance at the predicted position + the GPR variance)."""
        N = len(points_mm)
        D = measured_covariance(self.tracker, points_mm.reshape(-1, 3)).reshape(N, 3, 3, 3)
        out = D.copy()
        diag = np.diagonal(D[:, 1:], axis1=2, axis2=3) + gpr_std_mm**2        # (N, 2, 3)
        out[:, 1:] = diag[..., None] * np.eye(3)
        return out

    def estimate(self, q_rad: np.ndarray, p1_tracker_mm: np.ndarray, adjust: bool = True, sigma0: float = 1.0
                 ) -> PoseEstimate:
        """Online step: measured SMR 1 (N, 3) + predicted SMRs 2, 3 -> flange pose (with the adjustment if asked)."""
        pred, std = self.predict(q_rad)
        pts = np.concatenate([np.atleast_2d(p1_tracker_mm)[:, None], pred], axis=1)
        adj = None
        if adjust:
            adj = adjust_points(pts, self.covariances(pts, std), self.tool.d_mm, self.tool.sigma_d_mm(), sigma0)
        T = fit_points_pose(self.tool.p_flange_mm, pts if adj is None else adj.points_mm)
        return PoseEstimate(T, pts, None if adj is None else adj.points_mm, std, adj)


def nominal_points(kin: Kinematics, tool: SMRTool, q_rad: np.ndarray) -> np.ndarray:
    """P^N (N, 3, 3): the three SMRs in the tracker frame from the kinematic model (eq. 10)."""
    T = kin.T_tracker_base @ fk(kin, np.atleast_2d(q_rad))
    return transform_points(T[:, None], tool.p_flange_mm[None])
