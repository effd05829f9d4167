"""Batched iterative inverse kinematics (Levenberg-Marquardt with Sugihara's damping).

Damping ``lambda = E + w_bar`` with ``E = 1/2 e^T W e`` (Sugihara 2011); the convergence test is on the
pose error itself (mm and rad, never on a squared error) and every solution is checked by a final FK.
Orientation errors are weighted by ``length_mm`` so that 1 rad counts like that many mm.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .chains import arm_angle_jacobian, branch_signs, redundant, wrap_rad
from .frames import matrix_to_rotvec, transform_points
from .models import Kinematics, chain, motion_columns, within_limits

NULL_STEP_RAD = 0.2       # largest self-motion step of one round towards the rest pose
NULL_ROUNDS = 12


@dataclass(frozen=True, eq=False)
class IKResult:
    """q_rad (N, n); converged (N,) bool; pos_err_mm, rot_err_rad (N,) from the final FK; iterations."""
    q_rad: np.ndarray
    converged: np.ndarray
    pos_err_mm: np.ndarray
    rot_err_rad: np.ndarray
    iterations: int


def pose_error(kin: Kinematics, q_rad, p_target_base_mm, R_target_base, point_mm) -> tuple[np.ndarray, np.ndarray]:
    """(e_pos (N, 3) mm, e_rot (N, 3) rad) from current to target; point_mm is fixed in the flange frame. An arm
    of fewer than six joints: the rotation error about the target's z axis (the tool's roll) is not an error."""
    T = chain(kin, q_rad, full=False).T_base_flange
    e_p = p_target_base_mm - transform_points(T, point_mm)
    if R_target_base is None:
        return e_p, np.zeros_like(e_p)
    return e_p, _rotation_error(kin, R_target_base, T)


def _rotation_error(kin: Kinematics, R_t: np.ndarray, T: np.ndarray) -> np.ndarray:
    """(N, 3) rad: the rotation from the flange frames T to the targets R_t; for an arm of fewer than six axes the
    rotation that turns its tool direction (flange z) onto the target's (the roll is not an error)."""
    if kin.n - kin.n_track >= 6:
        return matrix_to_rotvec(R_t @ np.swapaxes(T[:, :3, :3], 1, 2))
    z_t = np.broadcast_to(R_t, (len(T), 3, 3))[:, :, 2]
    c = np.cross(T[:, :3, 2], z_t)
    s = np.linalg.norm(c, axis=1, keepdims=True)
    angle = np.arctan2(s, np.einsum("ni,ni->n", T[:, :3, 2], z_t)[:, None])
    return np.where(s > 1e-15, c * angle / np.maximum(s, 1e-300), 0.0)


def _off_roll(kin: Kinematics, R_t: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotation vectors (N, 3) or Jacobian rows (N, 3, n) without their component about the target's z axis when
    the arm has fewer than six joints (it holds the tool's direction, not its roll); unchanged otherwise."""
    if kin.n - kin.n_track >= 6:
        return v
    z = np.broadcast_to(R_t, (len(v), 3, 3))[:, :, 2]
    P = np.eye(3) - z[:, :, None] * z[:, None, :]
    return np.einsum("nij,nj...->ni...", P, v)


def _evaluate(kin, q, p_t, R_t, point, rows, w, psi_t=None):
    """Weighted pose error e (N, m) and Jacobian J (N, m, n) at q from ONE chain evaluation; with arm-angle targets
    psi_t (N,) rad one more row, the arm-angle error weighted as an orientation."""
    c = chain(kin, q, full=False)
    T = c.T_base_flange
    p = transform_points(T, point)
    e_p = p_t - p
    e_r = np.zeros_like(e_p) if R_t is None else _rotation_error(kin, R_t, T)
    e = np.concatenate([e_p, e_r], axis=1)[:, rows] * w
    J = motion_columns(kin, c, p)
    if R_t is not None:
        J[:, 3:] = _off_roll(kin, R_t, J[:, 3:])
    J = J[:, rows] * w[None, :, None]
    J[:, :, :kin.n_track] = 0.0                            # the carriage stays where the seed puts it
    if psi_t is None:
        return e, J
    psi, J_psi = arm_angle_jacobian(kin, q)
    return (np.concatenate([e, w[-1] * wrap_rad(psi_t - psi)[:, None]], axis=1),
            np.concatenate([J, w[-1] * J_psi[:, None, :]], axis=1))


def solve_ik(kin: Kinematics, p_target_base_mm: np.ndarray, R_target_base: np.ndarray | None, q_seed_rad: np.ndarray,
             *, point_mm=None, tol_mm: float = 1e-6, tol_rad: float = 1e-9, max_iter: int = 200,
             length_mm: float = 1000.0, w_bar: float = 1e-6, arm_angle_rad=None, q_rest_rad=None) -> IKResult:
    """Joint angles placing a flange-fixed point (default the SMR) at p_target (N, 3) mm in the base frame
    with flange orientation R_target (N, 3, 3) (None = position only). q_seed (n,) or (N, n) rad.

    The redundancy of a seven-axis arm (docs/chains.md): ``arm_angle_rad`` (N,) or scalar holds each solution at
    that arm angle (``robocal.kinematics.chains.arm_angle_rad``); else ``q_rest_rad`` (n,) takes the solution nearest that
    joint-space pose along the arm's self-motion; neither: the solution the iteration reaches from the seed."""
    p_t = np.atleast_2d(np.asarray(p_target_base_mm, float))
    N = len(p_t)
    point = kin.p_flange_smr_mm if point_mm is None else np.asarray(point_mm, float)
    q = np.broadcast_to(np.asarray(q_seed_rad, float), (N, kin.n)).copy()
    R_t = None if R_target_base is None else np.broadcast_to(R_target_base, (N, 3, 3))
    rows = slice(0, 6) if R_t is not None else slice(0, 3)
    w = np.array([1.0, 1.0, 1.0, length_mm, length_mm, length_mm])[rows]
    psi_t = None if arm_angle_rad is None else np.broadcast_to(np.asarray(arm_angle_rad, float), (N,))
    if psi_t is not None and R_t is None:
        raise ValueError("an arm angle is held only with a target orientation")
    sub = lambda idx: (p_t[idx], None if R_t is None else R_t[idx], None if psi_t is None else psi_t[idx])

    active = np.arange(N)
    e, J = _evaluate(kin, q, p_t, R_t, point, rows, w, psi_t)
    mu = np.ones(N)                     # per-target damping multiplier, raised after a failed step
    it = 0
    for it in range(1, max_iter + 1):
        done = _converged(e, w, tol_mm, tol_rad)
        active, e, J = active[~done], e[~done], J[~done]
        if len(active) == 0:
            break
        E = 0.5 * np.einsum("ni,ni->n", e, e)
        lam = (mu[active] * (E / length_mm**2 + w_bar))[:, None, None] * np.eye(kin.n)
        H = np.einsum("nij,nik->njk", J, J) + lam
        dq = np.linalg.solve(H, np.einsum("nij,ni->nj", J, e)[..., None])[..., 0]
        q_new = q[active] + dq
        p_a, R_a, psi_a = sub(active)
        e_new, J_new = _evaluate(kin, q_new, p_a, R_a, point, rows, w, psi_a)
        better = np.einsum("ni,ni->n", e_new, e_new) < 2.0 * E
        q[active[better]] = q_new[better]
        e = np.where(better[:, None], e_new, e)
        J = np.where(better[:, None, None], J_new, J)
        mu[active] = np.where(better, np.maximum(mu[active] / 10.0, 1.0), mu[active] * 10.0)
    e_p, e_r = pose_error(kin, q, p_t, R_t, point)
    pos, rot = np.linalg.norm(e_p, axis=1), np.linalg.norm(e_r, axis=1)
    ok = (pos < tol_mm * 10) & (rot < max(tol_rad * 10, 1e-8))
    if psi_t is not None:
        ok &= np.abs(wrap_rad(psi_t - arm_angle_jacobian(kin, q)[0])) < max(tol_rad * 10, 1e-8)
    res = IKResult(q, ok, pos, rot, it)
    if q_rest_rad is not None and psi_t is None and R_t is not None and redundant(kin):
        return _nearest_rest(kin, res, p_t, R_t, np.asarray(q_rest_rad, float), point_mm=point, tol_mm=tol_mm,
                             tol_rad=tol_rad, max_iter=max_iter, length_mm=length_mm, w_bar=w_bar)
    return res


def _nearest_rest(kin: Kinematics, res: IKResult, p_t, R_t, q_rest, **kw) -> IKResult:
    """Move each converged solution along the arm's self-motion (the null space of its 6 x n Jacobian) to the
    solution nearest ``q_rest`` (joint-space distance, local), re-converging the pose after every step."""
    for _ in range(NULL_ROUNDS):
        q = res.q_rad
        c = chain(kin, q, full=False)
        J = motion_columns(kin, c, transform_points(c.T_base_flange, kw["point_mm"]))
        J[:, :3] /= kw["length_mm"]
        J[:, :, :kin.n_track] = 0.0
        null = np.eye(kin.n) - np.linalg.pinv(J) @ J                          # (N, n, n) projector
        null[:, :kin.n_track] = 0.0
        step = np.einsum("nij,nj->ni", null, q_rest - q)
        size = np.linalg.norm(step, axis=1)
        step *= np.minimum(1.0, NULL_STEP_RAD / np.maximum(size, 1e-300))[:, None]
        step[~res.converged] = 0.0
        if np.max(size[res.converged], initial=0.0) < 1e-9:
            break
        moved = solve_ik(kin, p_t, R_t, q + step, **kw)
        keep = moved.converged | ~res.converged
        res = IKResult(np.where(keep[:, None], moved.q_rad, q), res.converged, np.where(keep, moved.pos_err_mm,
                       res.pos_err_mm), np.where(keep, moved.rot_err_rad, res.rot_err_rad), res.iterations)
    return res


def _converged(e, w, tol_mm, tol_rad):
    pos = np.linalg.norm(e[:, :3], axis=1)
    if e.shape[1] == 3:
        return pos < tol_mm
    return (pos < tol_mm) & (np.linalg.norm(e[:, 3:] / w[3], axis=1) < tol_rad)


def branch_signature(kin: Kinematics, q_rad: np.ndarray) -> np.ndarray:
    """(N, 3) signs (shoulder, elbow, wrist) of a 6R arm's IK branch, computed geometrically:
    wrist centre in front of/behind J2, forearm turning +/- about J2, and the sign of J5 bending. Another chain:
    ``robocal.kinematics.chains.branch_signs`` (the side of each alignment of its spherical joints). On a track: the arm's."""
    if kin.track is not None:
        return branch_signature(kin.arm(), np.atleast_2d(q_rad)[:, 1:])
    if kin.n != 6:
        return branch_signs(kin, q_rad)
    c = chain(kin, q_rad)
    o2, o3, w = c.origin[:, 1], c.origin[:, 2], c.origin[:, 4]
    forward = c.dirs[2][0]                          # x axis after joint 1 (the arm's plane direction)
    shoulder = np.sign(np.einsum("ni,ni->n", w - o2, forward))
    elbow = np.sign(np.einsum("ni,ni->n", np.cross(o3 - o2, w - o3), c.axis[:, 1]))
    wrist = np.sign(np.einsum("ni,ni->n", np.cross(c.axis[:, 3], c.axis[:, 5]), c.axis[:, 4]))
    return np.stack([shoulder, elbow, wrist], axis=1)


def same_branch(kin: Kinematics, q_rad: np.ndarray, q_ref_rad: np.ndarray) -> np.ndarray:
    """(N,) bool: same branch signature as q_ref and joints within +/-180 deg of q_ref (same turn; a track's
    travel is no turn)."""
    sig = branch_signature(kin, q_rad)
    ref = branch_signature(kin, np.atleast_2d(q_ref_rad))
    turns = np.all(np.abs(np.atleast_2d(q_rad) - q_ref_rad)[:, kin.n_track:] < np.pi, axis=1)
    return np.all(sig == ref, axis=1) & turns


def reachable(kin: Kinematics, result: IKResult, q_ref_rad: np.ndarray) -> np.ndarray:
    """(N,) bool: IK converged, inside the joint limits and on q_ref's branch."""
    return result.converged & within_limits(kin, result.q_rad) & same_branch(kin, result.q_rad, q_ref_rad)


def solve_on_branch(kin: Kinematics, p_target_base_mm: np.ndarray, R_target_base: np.ndarray | None,
                    q_ref_rad: np.ndarray, rounds: int = 4, **kw) -> tuple[np.ndarray, np.ndarray]:
    """IK for many targets on q_ref's branch: solve from q_ref, then re-seed each failed target from the
    solution of its nearest solved neighbour (Cartesian distance), a few rounds.

    Returns (q_rad (N, n), ok (N,) bool: converged, inside the limits, on q_ref's branch). A seven-axis arm
    takes, along its self-motion, the solution nearest q_ref (unless ``arm_angle_rad`` is given)."""
    p_t = np.atleast_2d(np.asarray(p_target_base_mm, float))
    R_t = None if R_target_base is None else np.broadcast_to(R_target_base, (len(p_t), 3, 3))
    q_ref = np.broadcast_to(np.asarray(q_ref_rad, float), (len(p_t), kin.n))     # per target (a track's travel)
    if redundant(kin) and "arm_angle_rad" not in kw:
        kw = {**kw, "q_rest_rad": q_ref}
    res = solve_ik(kin, p_t, R_t, q_ref, **kw)
    q, ok = res.q_rad.copy(), reachable(kin, res, q_ref)
    for _ in range(rounds):
        bad = np.flatnonzero(~ok)
        if len(bad) == 0 or not ok.any():
            break
        good = np.flatnonzero(ok)
        d = np.linalg.norm(p_t[bad, None, :] - p_t[None, good, :], axis=2)
        seeds = q[good[np.argmin(d, axis=1)]]
        seeds[:, :kin.n_track] = q_ref[bad, :kin.n_track]              # the carriage stays at the target's
        retry = solve_ik(kin, p_t[bad], None if R_t is None else R_t[bad], seeds, **_rows(kw, bad, len(p_t)))
        fixed = reachable(kin, retry, q_ref[bad])
        if not fixed.any():
            break
        q[bad[fixed]], ok[bad[fixed]] = retry.q_rad[fixed], True
    return q, ok


PER_TARGET = ("arm_angle_rad", "q_rest_rad")     # solve_ik options that may hold one row per target


def _rows(kw: dict, idx: np.ndarray, N: int) -> dict:
    """The keyword options with every per-target array (``PER_TARGET``, leading dimension N) taken at rows idx (the
    flange point ``point_mm`` (3,) is one for all targets, also when there are three of them)."""
    return {k: (v[idx] if k in PER_TARGET and isinstance(v, np.ndarray) and v.ndim and len(v) == N else v)
            for k, v in kw.items()}


def wrist_angle_rad(kin: Kinematics, q_rad: np.ndarray) -> np.ndarray:
    """(N,) angle between the J4 and J6 axes (rad): 0 at the wrist singularity of a 6R arm (J4 || J6)."""
    c = chain(kin, q_rad, full=False)
    s = np.linalg.norm(np.cross(c.axis[:, 3], c.axis[:, 5]), axis=1)
    return np.arcsin(np.clip(s, 0.0, 1.0))
