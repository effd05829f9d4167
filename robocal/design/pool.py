"""Candidate poses of an optimal calibration plan: orientations around a tool direction, the wrist-flipped IK
branch, and what the tracker can see (range, incidence on the SMR).

Positions mm in the robot base frame; rotations R_base_flange (3, 3); angles rad.
"""
from __future__ import annotations

import numpy as np

from robocal.kinematics.frames import transform_points
from robocal.kinematics.ik import reachable, solve_ik, solve_on_branch
from robocal.kinematics.models import Kinematics, fk, within_limits


def tilted_rotations(R0: np.ndarray, tilt_rad: float, count: int) -> np.ndarray:
    """(1 + count, 3, 3): R0 and R0 with its z-axis tilted by ``tilt_rad`` towards ``count`` azimuths evenly
    spread around it (rotations about axes in R0's x-y plane)."""
    out = [np.asarray(R0, float)]
    for az in np.arange(count) * 2.0 * np.pi / max(count, 1):
        axis = np.cos(az) * R0[:, 0] + np.sin(az) * R0[:, 1]
        K = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
        out.append((np.eye(3) + np.sin(tilt_rad) * K + (1.0 - np.cos(tilt_rad)) * K @ K) @ R0)
    return np.stack(out)[: 1 + count]


def incidence_rad(R_base_flange: np.ndarray, p_smr_base_mm: np.ndarray, p_tracker_base_mm) -> np.ndarray:
    """(N,) angle between the SMR's axis (the flange z-axis of R_base_flange (N, 3, 3)) and its line of sight to
    the tracker at ``p_tracker_base_mm`` (3,)."""
    los = np.asarray(p_tracker_base_mm, float) - np.atleast_2d(p_smr_base_mm)
    los /= np.linalg.norm(los, axis=1, keepdims=True)
    z = np.asarray(R_base_flange, float)[:, :, 2]
    return np.arccos(np.clip(np.sum(z * los, axis=1), -1.0, 1.0))


def wrist_flipped(q_rad: np.ndarray) -> np.ndarray:
    """The other wrist solution of a 6R arm at the same flange pose (exact for a spherical wrist, a seed for
    an offset wrist): q4 + pi, -q5, q6 + pi."""
    q = np.array(q_rad, float)
    q[:, 3] += np.where(q[:, 3] > 0, -np.pi, np.pi)
    q[:, 4] = -q[:, 4]
    q[:, 5] += np.where(q[:, 5] > 0, -np.pi, np.pi)
    return q


def candidate_poses(kin: Kinematics, p_base_mm: np.ndarray, rotations: np.ndarray, q_ref_rad: np.ndarray,
                    wrist_flip: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Joint solutions for every position (M, 3) x rotation (K, 3, 3) x branch (q_ref's, and with ``wrist_flip``
    the flipped wrist): (q_rad (C, n), cell (C,) position index, orientation (C,) index, branch (C,) 0 | 1), only
    converged solutions inside the joint limits. The first rotation is solved on q_ref's branch, the others
    seeded from it (same branch)."""
    p = np.atleast_2d(np.asarray(p_base_mm, float))
    q0, ok0 = solve_on_branch(kin, p, rotations[0], q_ref_rad)
    qs, cells, oris = [q0[ok0]], [np.flatnonzero(ok0)], [np.zeros(ok0.sum(), int)]
    base = np.flatnonzero(ok0)
    for k in range(1, len(rotations)):
        res = solve_ik(kin, p[base], rotations[k], q0[base], max_iter=60)
        ok = reachable(kin, res, q_ref_rad)
        qs.append(res.q_rad[ok]), cells.append(base[ok]), oris.append(np.full(ok.sum(), k))
    q, cell, ori = np.concatenate(qs), np.concatenate(cells), np.concatenate(oris)
    branch = np.zeros(len(q), int)
    if wrist_flip and kin.n == 6 and len(q):
        res = solve_ik(kin, p[cell], rotations[ori], wrist_flipped(q), max_iter=60)
        moved = np.abs(res.q_rad[:, 3] - q[:, 3]) > np.pi / 2           # really the other wrist solution
        ok = res.converged & within_limits(kin, res.q_rad) & moved
        q = np.concatenate([q, res.q_rad[ok]])
        cell, ori = np.concatenate([cell, cell[ok]]), np.concatenate([ori, ori[ok]])
        branch = np.concatenate([branch, np.ones(ok.sum(), int)])
    return q, cell, ori, branch


def smr_base_and_axis(kin: Kinematics, q_rad: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """SMR positions (N, 3) mm and flange rotations (N, 3, 3) in the base frame at q (N, n)."""
    T = fk(kin, q_rad)
    return transform_points(T, kin.p_flange_smr_mm), T[:, :3, :3]
