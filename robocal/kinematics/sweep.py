"""Swept joint-interpolated paths: sampled positions of flange-fixed points, box tests and speed profiles.

A joint move from ``q_a`` to ``q_b`` follows ``q(s) = q_a + s (q_b - q_a)``, s in [0, 1] (what ``MoveAbsJ`` and
``movej`` do). A point fixed to the flange moves at most ``sum_i |dq_i| R_i`` along it, where ``R_i`` bounds
its distance from joint i's axis (the link lengths sqrt(a^2 + d^2) from joint i on plus the point's offset
from the flange).
So along a stretch where that bound is L, a point whose clearance at the two ends adds up to more than L
cannot reach an obstacle in between: ``check_segments`` halves the stretches that fail this test until they
pass or become shorter than a resolution, which proves the continuous path clear, not only samples of it.

Everything is batched over segments and samples (no Python loop over poses). Angles in rad, lengths in mm,
positions in the robot base frame.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .models import Kinematics, fk


def lever_arms_mm(kin: Kinematics, p_flange_points_mm: np.ndarray) -> np.ndarray:
    """(n,) upper bound (mm) of the distance from each joint axis to any of the points (P, 3) in the flange frame."""
    link = np.hypot(np.asarray(kin.a_mm), np.asarray(kin.d_mm))
    after = np.cumsum(link[::-1])[::-1]                    # sum over links i..n (triangle inequality)
    reach = float(np.max(np.linalg.norm(np.atleast_2d(p_flange_points_mm), axis=1), initial=0.0))
    return after + reach


def sample_segments(q_a_rad: np.ndarray, q_b_rad: np.ndarray, counts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Samples of M joint segments: (S, n) rad (both ends included) and the segment index of each (S,)."""
    q_a, q_b = np.atleast_2d(q_a_rad), np.atleast_2d(q_b_rad)
    counts = np.asarray(counts, int)
    seg = np.repeat(np.arange(len(counts)), counts + 1)
    start = np.concatenate([[0], np.cumsum(counts + 1)[:-1]])
    k = np.arange(len(seg)) - start[seg]
    s = (k / counts[seg])[:, None]
    return q_a[seg] + s * (q_b[seg] - q_a[seg]), seg


def flange_points_base(kin: Kinematics, q_rad: np.ndarray, p_flange_points_mm: np.ndarray) -> np.ndarray:
    """(S, P, 3) mm: the points (P, 3) given in the flange frame, in the base frame at poses (S, n)."""
    T = fk(kin, q_rad)
    p = np.atleast_2d(p_flange_points_mm)
    return np.einsum("sij,pj->spi", T[:, :3, :3], p) + T[:, None, :3, 3]


class Boxes(NamedTuple):
    """Axis-aligned boxes (B, 3) lower and upper corners, mm, base frame."""
    lo: np.ndarray
    hi: np.ndarray

    def grown(self, margin_mm: float) -> "Boxes":
        return Boxes(self.lo - margin_mm, self.hi + margin_mm)


class Violation(NamedTuple):
    """Per segment (M,): blocked?, the box index hit (-1 = left the envelope, -2 = none), the path parameter s."""
    blocked: np.ndarray
    box: np.ndarray
    s: np.ndarray


def clearances_mm(points: np.ndarray, keep_out: Boxes, envelope: Boxes | None) -> tuple[np.ndarray, np.ndarray]:
    """Distance (mm) of each point (S, P, 3) to the nearest keep-out box (0 inside) or to the envelope's faces
    (0 outside), minimised over the points: (S,) distance and (S,) the limiting box (-1 = envelope)."""
    S = points.shape[0]
    d, which = np.full(S, np.inf), np.full(S, -1)
    if len(keep_out.lo):
        gap = np.maximum(np.maximum(keep_out.lo - points[..., None, :], points[..., None, :] - keep_out.hi), 0.0)
        dist = np.linalg.norm(gap, axis=-1).min(axis=1)                   # (S, B) over the points
        which, d = np.argmin(dist, axis=1), dist.min(axis=1)
    if envelope is not None:
        inner = np.minimum(points - envelope.lo[0], envelope.hi[0] - points).min(axis=(1, 2))
        inner = np.maximum(inner, 0.0)
        which = np.where(inner < d, -1, which)
        d = np.minimum(d, inner)
    return d, which


def check_segments(kin: Kinematics, q_a_rad: np.ndarray, q_b_rad: np.ndarray, p_flange_points_mm: np.ndarray,
                   keep_out: Boxes, envelope: Boxes | None, clearance_mm: float, resolution_mm: float = 2.0,
                   initial: int = 8) -> Violation:
    """Does the swept path of each segment (M, n) -> (M, n) bring a flange point within ``clearance_mm`` of a
    keep-out box, or within ``clearance_mm`` of the envelope's faces?

    Conservative advancement: an interval [s0, s1] along which no point moves more than L (the lever-arm bound)
    is clear when the clearances at its ends add up to more than L (every point between is within L of the
    two ends together); otherwise it is halved, down to ``resolution_mm``, below which it counts as blocked.
    Proven on the continuous path, not only at samples; batched over all open intervals."""
    q_a, q_b = np.atleast_2d(q_a_rad).astype(float), np.atleast_2d(q_b_rad).astype(float)
    M = len(q_a)
    bound = np.abs(q_b - q_a) @ lever_arms_mm(kin, p_flange_points_mm)     # (M,) mm over the whole segment
    grown = keep_out.grown(clearance_mm)
    env = None if envelope is None else envelope.grown(-clearance_mm)
    blocked, box, s_hit = np.zeros(M, bool), np.full(M, -2), np.full(M, np.nan)
    seg = np.repeat(np.arange(M), initial)
    s0 = np.tile(np.arange(initial) / initial, M)
    width = np.full(len(seg), 1.0 / initial)
    while len(seg):
        s_ends = np.concatenate([s0, s0 + width])
        q = q_a[np.tile(seg, 2)] + s_ends[:, None] * (q_b - q_a)[np.tile(seg, 2)]
        d, which = clearances_mm(flange_points_base(kin, q, p_flange_points_mm), grown, env)
        n = len(seg)
        d0, d1 = d[:n], d[n:]
        length = bound[seg] * width
        hit = (d0 <= 0) | (d1 <= 0) | ((d0 + d1 <= length) & (length < resolution_mm))
        new = hit & ~blocked[seg]
        for k in np.flatnonzero(new):                                     # first report per segment only
            if not blocked[seg[k]]:
                blocked[seg[k]] = True
                box[seg[k]] = which[k] if d0[k] <= d1[k] else which[n + k]
                s_hit[seg[k]] = s0[k]
        split = ~hit & (d0 + d1 <= length) & ~blocked[seg]
        seg, s0, width = (np.repeat(seg[split], 2), np.repeat(s0[split], 2) + np.tile([0.0, 0.5], split.sum())
                          * np.repeat(width[split], 2), np.repeat(width[split], 2) / 2)
    return Violation(blocked, box, s_hit)


def peak_speed_per_unit_s(kin: Kinematics, q_a_rad: np.ndarray, q_b_rad: np.ndarray,
                          p_flange_points_mm: np.ndarray, samples: int = 64) -> np.ndarray:
    """(M,) largest |dp/ds| (mm per unit path parameter) of any of the points over each segment, from
    ``samples`` equal steps: a move of duration T has peak Cartesian speed about this / T (mm/s)."""
    q_a, q_b = np.atleast_2d(q_a_rad).astype(float), np.atleast_2d(q_b_rad).astype(float)
    q, seg = sample_segments(q_a, q_b, np.full(len(q_a), samples))
    pts = flange_points_base(kin, q, p_flange_points_mm).reshape(len(q_a), samples + 1, -1, 3)
    step = np.linalg.norm(np.diff(pts, axis=1), axis=-1)                 # (M, samples, P)
    return step.max(axis=(1, 2)) * samples


def move_durations_s(kin: Kinematics, q_a_rad: np.ndarray, q_b_rad: np.ndarray, p_flange_points_mm: np.ndarray,
                     joint_speed_rad_s: float, tcp_speed_mm_s: float, samples: int = 64) -> np.ndarray:
    """(M,) shortest duration (s) of each joint-interpolated move with no joint faster than
    ``joint_speed_rad_s`` and none of the points faster than ``tcp_speed_mm_s`` (constant-rate profile,
    acceleration ignored)."""
    dq = np.abs(np.atleast_2d(q_b_rad) - np.atleast_2d(q_a_rad)).max(axis=1)
    t_joint = dq / joint_speed_rad_s
    t_tcp = peak_speed_per_unit_s(kin, q_a_rad, q_b_rad, p_flange_points_mm, samples) / tcp_speed_mm_s
    return np.maximum(t_joint, t_tcp)
