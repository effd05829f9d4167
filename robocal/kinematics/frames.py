"""Rigid transforms on numpy arrays.

Naming: ``T_a_b`` is the pose of frame b expressed in frame a, so ``T_a_c = T_a_b @ T_b_c``
and ``p_a = T_a_b @ p_b``. Translations are in mm, angles in radians. Every function accepts
a single object or a batch with leading dimensions.
"""
from __future__ import annotations

import numpy as np


def skew(v: np.ndarray) -> np.ndarray:
    """(..., 3) -> (..., 3, 3) cross-product matrix: skew(v) @ w == cross(v, w)."""
    v = np.asarray(v, dtype=float)
    S = np.zeros(v.shape[:-1] + (3, 3))
    S[..., 0, 1], S[..., 0, 2] = -v[..., 2], v[..., 1]
    S[..., 1, 0], S[..., 1, 2] = v[..., 2], -v[..., 0]
    S[..., 2, 0], S[..., 2, 1] = -v[..., 1], v[..., 0]
    return S


def rotvec_to_matrix(w_rad: np.ndarray) -> np.ndarray:
    """Rodrigues: rotation vector (..., 3) rad -> rotation matrix (..., 3, 3)."""
    w = np.asarray(w_rad, dtype=float)
    angle = np.linalg.norm(w, axis=-1)[..., None, None]
    K = skew(w)
    small = angle < 1e-8
    safe = np.where(small, 1.0, angle)
    A = np.where(small, 1.0 - angle**2 / 6.0, np.sin(safe) / safe)
    B = np.where(small, 0.5 - angle**2 / 24.0, (1.0 - np.cos(safe)) / safe**2)
    return np.eye(3) + A * K + B * (K @ K)


def matrix_to_rotvec(R: np.ndarray) -> np.ndarray:
    """Rotation matrix (..., 3, 3) -> rotation vector (..., 3) rad (angle in [0, pi])."""
    R = np.asarray(R, dtype=float)
    cos = np.clip((np.trace(R, axis1=-2, axis2=-1) - 1.0) / 2.0, -1.0, 1.0)
    angle = np.arccos(cos)
    v = np.stack([R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0], R[..., 1, 0] - R[..., 0, 1]], -1)
    s = np.sin(angle)
    factor = np.where(s > 1e-8, angle / np.where(s > 1e-8, 2 * s, 1.0), 0.5)
    out = v * factor[..., None]
    # near pi: use the symmetric part
    near_pi = angle > np.pi - 1e-4
    if np.any(near_pi):
        Rn = R[near_pi]
        B = (Rn + np.eye(3)) / 2.0
        idx = np.argmax(np.diagonal(B, axis1=-2, axis2=-1), axis=-1)
        axis = B[np.arange(len(idx)), :, idx]
        axis /= np.linalg.norm(axis, axis=-1, keepdims=True)
        sign = np.sign(np.einsum("...i,...i->...", axis, v[near_pi]) + 1e-300)
        out[near_pi] = axis * (angle[near_pi] * np.where(sign == 0, 1, sign))[..., None]
    return out


def make_T(R: np.ndarray, t_mm: np.ndarray) -> np.ndarray:
    """Rotation (..., 3, 3) and translation (..., 3) mm -> homogeneous (..., 4, 4)."""
    R = np.asarray(R, dtype=float)
    t = np.asarray(t_mm, dtype=float)
    shape = np.broadcast_shapes(R.shape[:-2], t.shape[:-1])
    T = np.zeros(shape + (4, 4))
    T[..., :3, :3] = R
    T[..., :3, 3] = t
    T[..., 3, 3] = 1.0
    return T


def inv_T(T: np.ndarray) -> np.ndarray:
    """Inverse of rigid transforms (..., 4, 4)."""
    R = T[..., :3, :3]
    Rt = np.swapaxes(R, -1, -2)
    return make_T(Rt, -np.einsum("...ij,...j->...i", Rt, T[..., :3, 3]))


def transform_points(T: np.ndarray, p_mm: np.ndarray) -> np.ndarray:
    """Apply T (..., 4, 4) to points (..., 3) -> (..., 3)."""
    return np.einsum("...ij,...j->...i", T[..., :3, :3], p_mm) + T[..., :3, 3]


def exp_se3_left(delta: np.ndarray, T: np.ndarray) -> np.ndarray:
    """Left update ``T <- [R(w) | v] @ T`` with delta = (v_mm (3), w_rad (3)) in the outer frame."""
    delta = np.asarray(delta, dtype=float)
    D = make_T(rotvec_to_matrix(delta[3:6]), delta[:3])
    return D @ T


def fit_rigid(p_from_mm: np.ndarray, p_to_mm: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray:
    """Closed-form least-squares rigid transform (Kabsch/Umeyama, no scale).

    Returns T (4, 4) minimising sum w_i |T @ p_from_i - p_to_i|^2. Points (N, 3) mm, N >= 3 not collinear.
    Works for any rotation and any distance between the frames.
    """
    a = np.asarray(p_from_mm, dtype=float)
    b = np.asarray(p_to_mm, dtype=float)
    w = np.ones(len(a)) if weights is None else np.asarray(weights, dtype=float)
    w = w / w.sum()
    ca, cb = w @ a, w @ b
    H = (a - ca).T @ ((b - cb) * w[:, None])
    U, _, Vt = np.linalg.svd(H)
    d = np.sign(np.linalg.det(Vt.T @ U.T))
    R = Vt.T @ np.diag([1.0, 1.0, d]) @ U.T
    return make_T(R, cb - R @ ca)
