"""Target correction by pseudo-target iteration (seed 001 §1-3), batched over targets.

For target tool poses ``T_d`` (N, 4, 4) in the base frame and an actual-pose predictor ``AP(q) -> T_a``
(a calibrated model, a simulated truth, or the measurement itself), find joint angles ``q_a`` whose actual
pose is ``T_d``. Each iteration k (seed 001 steps 2-7):

    T_a = AP(q_a);  E = err(T_a, T_d);  keep (E_best, q_best);  stop when E_best < threshold or k = k_max
    T_p <- PT(T_p, T_a, T_d);  q_a <- IIK(T_p, warm start q_a)

with the nominal model's iterative IK (Sugihara LM, ``robocal.kinematics.ik``). Pseudo-target generators PT:
``yin`` (eq. 12, T_p T_a^-1 T_d), and the position update of eq. 14 combined with the orientation updates
``fixed`` (eq. 15), ``add`` (eq. 16), ``multiply`` (eq. 17), ``euler_zyz`` / ``euler_xyz`` (eq. 18),
``quaternion`` (eq. 19). The ensemble (§3) runs several generators and keeps the best result per target.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np
from scipy.spatial.transform import Rotation

from robocal.kinematics.chains import arm_angle_rad, redundant
from robocal.kinematics.frames import inv_T, make_T, matrix_to_rotvec
from robocal.kinematics.ik import solve_ik
from robocal.kinematics.models import Kinematics, fk, within_limits

__all__ = ["GENERATORS", "Correction", "closed_loop_step", "correct", "correct_ensemble", "matrix_to_quat",
           "quat_to_matrix", "tool_transform"]
PoseFn = Callable[[np.ndarray], np.ndarray]
GENERATORS = ("yin", "fixed", "add", "multiply", "euler_zyz", "euler_xyz", "quaternion")


# ---------------------------------------------------------------- orientation helpers
def project_so3(R: np.ndarray) -> np.ndarray:
    """Nearest rotation (polar decomposition) of (N, 3, 3) matrices (eq. 16 can leave SO(3))."""
    U, _, Vt = np.linalg.svd(R)
    d = np.sign(np.linalg.det(U @ Vt))
    U[..., :, 2] *= d[..., None]
    return U @ Vt


def quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product of quaternions (..., 4) in (w, x, y, z) order."""
    w1, x1, y1, z1 = np.moveaxis(a, -1, 0)
    w2, x2, y2, z2 = np.moveaxis(b, -1, 0)
    return np.stack([w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2, w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                     w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2, w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2], axis=-1)


def matrix_to_quat(R: np.ndarray) -> np.ndarray:
    """(N, 3, 3) -> (N, 4) unit quaternions (w, x, y, z), w >= 0."""
    q = Rotation.from_matrix(R).as_quat()                # scipy: (x, y, z, w)
    q = np.concatenate([q[..., 3:], q[..., :3]], axis=-1)
    return q * np.where(q[..., :1] < 0, -1.0, 1.0)


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    return Rotation.from_quat(np.concatenate([q[..., 1:], q[..., :1]], axis=-1)).as_matrix()


# ---------------------------------------------------------------- generators
def _position(Tp, Ta, Td):
    return Tp[:, :3, 3] + Td[:, :3, 3] - Ta[:, :3, 3]                       # eq. 14


def _euler(seq):
    def orient(Rp, Ra, Rd):
        E = lambda R: Rotation.from_matrix(project_so3(R)).as_euler(seq)
        return Rotation.from_euler(seq, E(Rp) + E(Rd) - E(Ra)).as_matrix()   # eq. 18
    return orient


def _quaternion(Rp, Ra, Rd):
    qp, qa, qd = matrix_to_quat(project_so3(Rp)), matrix_to_quat(Ra), matrix_to_quat(Rd)
    conj = qa * np.array([1.0, -1.0, -1.0, -1.0])
    return quat_to_matrix(quat_mul(quat_mul(qp, conj), qd))                 # eq. 19


ORIENTATION_UPDATES = {
    "fixed": lambda Rp, Ra, Rd: Rd,                                          # eq. 15
    "add": lambda Rp, Ra, Rd: Rp + Rd - Ra,                                  # eq. 16 (may leave SO(3))
    "multiply": lambda Rp, Ra, Rd: Rd @ np.swapaxes(Ra, 1, 2) @ Rp,          # eq. 17
    "euler_zyz": _euler("ZYZ"),
    "euler_xyz": _euler("xyz"),
    "quaternion": _quaternion,
}


def next_pseudo_target(generator: str, Tp: np.ndarray, Ta: np.ndarray, Td: np.ndarray) -> np.ndarray:
    """PT(T_p^(k-1), T_a^(k-1), T_d) for a batch (N, 4, 4); the rotation block may be off SO(3) for 'add'."""
    if generator == "yin":
        return Tp @ inv_T(Ta) @ Td                                          # eq. 12
    if generator not in ORIENTATION_UPDATES:
        raise ValueError(f"unknown pseudo-target generator {generator!r} (expected one of {', '.join(GENERATORS)})")
    out = np.zeros_like(Tp)
    out[:, :3, :3] = ORIENTATION_UPDATES[generator](Tp[:, :3, :3], Ta[:, :3, :3], Td[:, :3, :3])
    out[:, :3, 3] = _position(Tp, Ta, Td)
    out[:, 3, 3] = 1.0
    return out


# ---------------------------------------------------------------- errors
def pose_errors(Ta: np.ndarray, Td: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(position error mm (N,), orientation error rad (N,)) between actual and target poses."""
    dp = np.linalg.norm(Ta[:, :3, 3] - Td[:, :3, 3], axis=1)
    dr = np.linalg.norm(matrix_to_rotvec(Td[:, :3, :3] @ np.swapaxes(Ta[:, :3, :3], 1, 2)), axis=1)
    return dp, dr


def error_function(kind: str, length_mm: float = 100.0) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
    """``position``: |P_a - P_d| (eq. 7); ``pose``: sqrt(|dP|^2 + (length_mm * |d_rot|)^2) in mm (eq. 8 role)."""
    if kind == "position":
        return lambda Ta, Td: pose_errors(Ta, Td)[0]
    if kind == "pose":
        def pose(Ta, Td):
            dp, dr = pose_errors(Ta, Td)
            return np.hypot(dp, length_mm * dr)
        return pose
    raise ValueError(f"unknown error function {kind!r} (expected position or pose)")


# ---------------------------------------------------------------- pose predictors
def tool_transform(p_flange_tool_mm, R_flange_tool=None) -> np.ndarray:
    return make_T(np.eye(3) if R_flange_tool is None else R_flange_tool, np.asarray(p_flange_tool_mm, float))


@dataclass(frozen=True, eq=False)
class Correction:
    """q_rad (N, n) corrected joints; predicted errors at them; iterations used; generator per target."""
    q_rad: np.ndarray
    pos_err_mm: np.ndarray
    rot_err_rad: np.ndarray
    error: np.ndarray
    iterations: np.ndarray
    generator: np.ndarray


def held_redundancy(kin: Kinematics, q_rad: np.ndarray) -> np.ndarray | None:
    """The arm angle (N,) rad a seven-axis arm's corrected joints keep (that of the commanded joints q_rad), None
    for a chain without redundancy: corrections never move the arm along its self-motion."""
    return arm_angle_rad(kin, q_rad) if redundant(kin) else None


def _held(psi: np.ndarray | None, idx) -> dict:
    return {} if psi is None else {"arm_angle_rad": psi[idx]}


def _oriented(kin: Kinematics, R: np.ndarray) -> np.ndarray | None:
    """The target orientation the IK holds: none for an arm of fewer than six axes (its tool's direction follows
    from where it reaches; holding it too over-constrains the correction)."""
    return R if kin.n - kin.n_track >= 6 else None


def correct(T_target: np.ndarray, q_start_rad: np.ndarray, actual_pose: PoseFn, ik_kin: Kinematics,
            T_flange_tool: np.ndarray, *, generator: str = "multiply", error: str = "position",
            threshold: float = 1e-4, max_iter: int = 20, length_mm: float = 100.0, ik_max_iter: int = 30) -> Correction:
    """Seed 001 §1 for a batch of targets with one generator. ``threshold`` in the error function's unit (mm).
    A seven-axis arm keeps the arm angle of ``q_start_rad`` (``held_redundancy``)."""
    Td = np.asarray(T_target, float)
    N = len(Td)
    err_fn = error_function(error, length_mm)
    q = np.broadcast_to(np.asarray(q_start_rad, float), (N, ik_kin.n)).copy()
    Tp = fk(ik_kin, q) @ T_flange_tool          # the pseudo-target q_start reaches (= T_d when q_start = IK(T_d))
    psi = held_redundancy(ik_kin, q)
    E_best = np.full(N, np.inf)
    q_best = q.copy()
    iters = np.zeros(N, int)
    active = np.arange(N)
    point, R_tool = T_flange_tool[:3, 3], T_flange_tool[:3, :3]
    for k in range(max_iter + 1):
        Ta = actual_pose(q[active])
        E = err_fn(Ta, Td[active])
        better = (E < E_best[active]) & within_limits(ik_kin, q[active])   # never keep an iterate off limits
        E_best[active[better]], q_best[active[better]] = E[better], q[active[better]]
        iters[active] = k
        done = (E_best[active] < threshold) | (k == max_iter)
        keep = ~done
        active, Ta = active[keep], Ta[keep]
        if len(active) == 0:
            break
        Tp[active] = next_pseudo_target(generator, Tp[active], Ta, Td[active])
        R_flange = project_so3(Tp[active, :3, :3]) @ R_tool.T
        q[active] = solve_ik(ik_kin, Tp[active, :3, 3], _oriented(ik_kin, R_flange), q[active], point_mm=point,
                             tol_mm=threshold / 100, max_iter=ik_max_iter, **_held(psi, active)).q_rad
    dp, dr = pose_errors(actual_pose(q_best), Td)
    return Correction(q_best, dp, dr, E_best, iters, np.full(N, generator, dtype=object))


def correct_ensemble(T_target, q_start_rad, actual_pose: PoseFn, ik_kin: Kinematics, T_flange_tool,
                     generators: Sequence[str] = ("multiply", "quaternion"), **kw) -> Correction:
    """Seed 001 §3: run each generator and keep, per target, the result with the smallest error."""
    results = [correct(T_target, q_start_rad, actual_pose, ik_kin, T_flange_tool, generator=g, **kw)
               for g in generators]
    errors = np.stack([r.error for r in results])
    best = np.argmin(errors, axis=0)
    pick = lambda attr: np.stack([getattr(r, attr) for r in results])[best, np.arange(len(best))]
    return Correction(pick("q_rad"), pick("pos_err_mm"), pick("rot_err_rad"), pick("error"), pick("iterations"),
                      np.array([generators[b] for b in best], dtype=object))


# ---------------------------------------------------------------- closed loop (seed 001 §4.2)
def closed_loop_step(ik_kin: Kinematics, T_flange_tool: np.ndarray, q_rad: np.ndarray, p_pseudo_mm: np.ndarray,
                     err_base_mm: np.ndarray, significant: np.ndarray, R_flange: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray]:
    """One closed-loop correction with the measured error: where ``significant`` (N,) the pseudo-target becomes
    the nominal tool position of the commanded joints ``q_rad`` (N, n) minus the measured error ``err_base_mm``
    (N, 3, base frame), and the joints are re-solved by nominal IK (flange orientation ``R_flange`` (N, 3, 3), warm
    start ``q_rad``, a seven-axis arm at the arm angle of ``q_rad``); elsewhere both stay. Returns (q_rad (N, n),
    p_pseudo_mm (N, 3))."""
    sig = np.asarray(significant, bool)[:, None]
    p_cmd = (fk(ik_kin, q_rad) @ T_flange_tool)[:, :3, 3]     # nominal position of what was commanded
    p_pseudo = np.where(sig, p_cmd - err_base_mm, p_pseudo_mm)
    q_new = solve_ik(ik_kin, p_pseudo, _oriented(ik_kin, R_flange), q_rad, point_mm=T_flange_tool[:3, 3],
                     **_held(held_redundancy(ik_kin, q_rad), slice(None))).q_rad
    return np.where(sig, q_new, q_rad), p_pseudo
