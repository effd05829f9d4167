"""What the structure of a serial chain implies, for any joint count (docs/chains.md).

* ``spherical_joints``: joints j whose neighbours j-1 and j+1 meet axis j in one point (a spherical shoulder, elbow
  or wrist). The property is fixed by the links, so it is read at zero joints.
* ``alignments``: the axis pairs whose parallelism is a singularity or a branch boundary: J4 || J6 on a 6-axis arm
  (as the 6R planner always had it); the neighbours of every spherical joint on other chains (J1 || J3, J3 || J5
  and J5 || J7 on a KUKA LBR iiwa).
* ``branch_signs``: the configuration of a chain other than 6R: the side of each such alignment (the sign of
  (a_{j-1} x a_{j+1}) . a_j), KUKA's status bits of A2, A4 and A6 on an iiwa.
* ``arm_angle_rad``: the redundancy of a seven-axis arm, the shoulder-elbow-wrist angle.
* ``wrist_joints``: the last three joints when they form a spherical wrist (where wrist coupling applies).

Shapes: q (N, n) rad; axes and points (N, 3) in the base frame, mm.
"""
from __future__ import annotations

import numpy as np

from .models import Kinematics, chain

MEET_TOL_MM = 1.0          # axes closer than this meet (a calibrated chain is a fraction of a mm off its nominal)


def _nearest_on(o1, a1, o2, a2) -> np.ndarray | None:
    """The point of line (o1, a1) nearest to line (o2, a2); None when the lines are parallel."""
    n = np.cross(a1, a2)
    nn = float(n @ n)
    if nn < 1e-12:
        return None
    t = float(np.cross(o2 - o1, a2) @ n) / nn
    return o1 + t * a1


def _off_line(p, o, a) -> float:
    """Distance (mm) of point p from the line (o, a)."""
    v = p - o
    return float(np.linalg.norm(v - (v @ a) * a))


def redundant(kin: Kinematics) -> bool:
    """A seven-axis arm (on a track or not): one degree of freedom more than a pose needs."""
    return kin.n - kin.n_track == 7


def spherical_joints(kin: Kinematics, tol_mm: float = MEET_TOL_MM) -> tuple[int, ...]:
    """0-based joints j (1 <= j <= n - 2) whose axes j-1 and j+1 both meet axis j in the same point (the arm's
    joints only: a track translates, it has no axis to meet)."""
    if kin.track is not None:
        return tuple(j + 1 for j in spherical_joints(kin.arm(), tol_mm))
    c = chain(kin, np.zeros((1, kin.n)), full=False)
    A, O = c.axis[0], c.origin[0]
    out = []
    for j in range(1, kin.n - 1):
        p = _nearest_on(O[j], A[j], O[j - 1], A[j - 1])
        s = _nearest_on(O[j], A[j], O[j + 1], A[j + 1])
        if p is None or s is None:
            continue
        if (_off_line(p, O[j - 1], A[j - 1]) < tol_mm and _off_line(s, O[j + 1], A[j + 1]) < tol_mm
                and np.linalg.norm(p - s) < tol_mm):
            out.append(j)
    return tuple(out)


def wrist_joints(kin: Kinematics) -> tuple[int, ...]:
    """1-based joints of a spherical wrist (the last three axes meeting in one point), () when the chain has none."""
    return (kin.n - 2, kin.n - 1, kin.n) if kin.n >= 4 and (kin.n - 2) in spherical_joints(kin) else ()


def alignments(kin: Kinematics) -> tuple[tuple[int, int], ...]:
    """0-based axis pairs (i, k) whose parallelism is a singularity or a branch boundary of the chain."""
    t = kin.n_track
    if kin.n - t == 6:
        return ((3 + t, 5 + t),)
    return tuple((j - 1, j + 1) for j in spherical_joints(kin))


def alignment_label(pair: tuple[int, int]) -> str:
    """'J4 || J6' for the 0-based pair (3, 5)."""
    return f"J{pair[0] + 1} || J{pair[1] + 1}"


def alignment_angles_rad(kin: Kinematics, q_rad: np.ndarray) -> np.ndarray:
    """(N, k) angle (rad, 0..pi/2) between the axes of each pair of ``alignments``: 0 when they are parallel."""
    pairs = alignments(kin)
    q = np.atleast_2d(q_rad)
    if not pairs:
        return np.zeros((len(q), 0))
    ax = chain(kin, q, full=False).axis
    s = np.stack([np.linalg.norm(np.cross(ax[:, i], ax[:, k]), axis=1) for i, k in pairs], axis=1)
    return np.arcsin(np.clip(s, 0.0, 1.0))


def branch_signs(kin: Kinematics, q_rad: np.ndarray) -> np.ndarray:
    """(N, k) signs (+1/-1, 0 exactly on the boundary) of (a_{j-1} x a_{j+1}) . a_j at each spherical joint j."""
    q = np.atleast_2d(q_rad)
    ax = chain(kin, q, full=False).axis
    cols = [np.einsum("ni,ni->n", np.cross(ax[:, j - 1], ax[:, j + 1]), ax[:, j]) for j in spherical_joints(kin)]
    return np.sign(np.stack(cols, axis=1)) if cols else np.zeros((len(q), 0))


def arm_angle_rad(kin: Kinematics, q_rad: np.ndarray) -> np.ndarray:
    """(N,) arm angle of a seven-axis arm (rad, -pi..pi): the angle about the shoulder-wrist line from the plane
    that holds that line and the first joint's axis to the plane shoulder-elbow-wrist. Shoulder, elbow and wrist are
    the points of axes 2, 4 and 6 the chain places (the centres of a spherical shoulder, elbow and wrist). 0: the
    elbow in the reference plane, on the side the first axis points to. Undefined (an algorithmic singularity) when
    the shoulder-wrist line is along the first axis or the arm is stretched."""
    if not redundant(kin):
        raise ValueError(f"the arm angle is defined for seven-axis arms, this arm has {kin.n - kin.n_track} joints")
    t = kin.n_track
    c = chain(kin, np.atleast_2d(q_rad), full=False)
    S, E, W, r = c.origin[:, 1 + t], c.origin[:, 3 + t], c.origin[:, 5 + t], c.axis[:, t]
    u = W - S
    u = u / np.linalg.norm(u, axis=1, keepdims=True)
    rp = r - np.einsum("ni,ni->n", r, u)[:, None] * u
    e = E - S
    ep = e - np.einsum("ni,ni->n", e, u)[:, None] * u
    return np.arctan2(np.einsum("ni,ni->n", u, np.cross(rp, ep)), np.einsum("ni,ni->n", rp, ep))


def arm_angle_jacobian(kin: Kinematics, q_rad: np.ndarray, h: float = 1e-7) -> tuple[np.ndarray, np.ndarray]:
    """(psi (N,), d psi / d q (N, n)) by forward differences (one batched chain per joint)."""
    q = np.atleast_2d(np.asarray(q_rad, float))
    N, n = q.shape
    psi = arm_angle_rad(kin, q)
    steps = np.repeat(q[None], n, axis=0) + h * np.eye(n)[:, None, :]            # (n, N, n)
    moved = arm_angle_rad(kin, steps.reshape(n * N, n)).reshape(n, N)
    return psi, (wrap_rad(moved - psi[None]) / h).T


def wrap_rad(x: np.ndarray) -> np.ndarray:
    """Angles wrapped to (-pi, pi]."""
    return np.pi - np.mod(np.pi - np.asarray(x, float), 2 * np.pi)


def alignment_margin_rad(kin: Kinematics, q_rad: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """((N,) angle of the nearest alignment (rad; pi/2 when the chain has none), (N,) its index in ``alignments``)."""
    a = alignment_angles_rad(kin, q_rad)
    if a.shape[1] == 0:
        return np.full(len(a), np.pi / 2), np.zeros(len(a), int)
    k = np.argmin(a, axis=1)
    return a[np.arange(len(a)), k], k
