"""Swept joint-interpolated paths: sampled positions of flange-fixed points, box tests and speed profiles.

A joint move from ``q_a`` to ``q_b`` follows ``q(s) = q_a + s (q_b - q_a)``, s in [0, 1] (what ``MoveAbsJ`` and
``movej`` do). A point fixed to the flange moves at most ``sum_i |dq_i| R_i`` along it, where ``R_i`` bounds
its distance from joint i's axis (the link lengths after joint i plus the point's offset from the flange).
Sampling the path so that consecutive samples are at most ``step_mm`` apart by that bound puts every point of
the continuous path within ``step_mm / 2`` of a sample: checking the samples against boxes grown by
``step_mm / 2`` (and an envelope shrunk by it) proves the continuous path clear, not only the samples.

Everything is batched over segments and samples (no Python loop over poses). Angles in rad, lengths in mm,
positions in the robot base frame.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .kinematics import Kinematics, fk


def lever_arms_mm(kin: Kinematics, p_flange_points_mm: np.ndarray) -> np.ndarray:
    """(n,) upper bound (mm) of the distance from each joint axis to any of the points (P, 3) in the flange frame."""
    link = np.abs(np.asarray(kin.a_mm)) + np.abs(np.asarray(kin.d_mm))
    after = np.cumsum(link[::-1])[::-1]                    # sum over links i..n
    reach = float(np.max(np.linalg.norm(np.atleast_2d(p_flange_points_mm), axis=1), initial=0.0))
    return after + reach


def sample_counts(q_a_rad: np.ndarray, q_b_rad: np.ndarray, arms_mm: np.ndarray, step_mm: float) -> np.ndarray:
    """(M,) number of intervals per segment so that no point moves more than ``step_mm`` between samples."""
    bound_mm = np.abs(np.atleast_2d(q_b_rad) - np.atleast_2d(q_a_rad)) @ arms_mm
    return np.maximum(1, np.ceil(bound_mm / step_mm)).astype(int)


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


def inside(points: np.ndarray, boxes: Boxes) -> np.ndarray:
    """(..., B) bool: point (..., 3) strictly inside box b."""
    p = points[..., None, :]
    return np.all((p > boxes.lo) & (p < boxes.hi), axis=-1)


class Violation(NamedTuple):
    """Per segment (M,): blocked?, the box index hit (-1 = left the envelope, -2 = none), the path parameter s."""
    blocked: np.ndarray
    box: np.ndarray
    s: np.ndarray


def check_segments(kin: Kinematics, q_a_rad: np.ndarray, q_b_rad: np.ndarray, p_flange_points_mm: np.ndarray,
                   keep_out: Boxes, envelope: Boxes | None, clearance_mm: float, step_mm: float = 10.0) -> Violation:
    """Does the swept path of each segment (M, n) -> (M, n) bring a flange point within ``clearance_mm`` of a
    keep-out box, or closer than ``clearance_mm`` to the envelope's faces? Proven on the continuous path (see
    the module docstring)."""
    q_a, q_b = np.atleast_2d(q_a_rad).astype(float), np.atleast_2d(q_b_rad).astype(float)
    counts = sample_counts(q_a, q_b, lever_arms_mm(kin, p_flange_points_mm), step_mm)
    q, seg = sample_segments(q_a, q_b, counts)
    s = (np.arange(len(seg)) - np.concatenate([[0], np.cumsum(counts + 1)[:-1]])[seg]) / counts[seg]
    pts = flange_points_base(kin, q, p_flange_points_mm)                  # (S, P, 3)
    margin = clearance_mm + step_mm / 2
    hit = np.full(len(seg), -2)
    if len(keep_out.lo):
        in_box = inside(pts, keep_out.grown(margin)).any(axis=1)         # (S, B)
        any_box = in_box.any(axis=1)
        hit = np.where(any_box, np.argmax(in_box, axis=1), hit)
    if envelope is not None:
        out = ~inside(pts, envelope.grown(-margin))[..., 0].all(axis=1)   # (S,)
        hit = np.where(out & (hit == -2), -1, hit)
    bad = hit != -2
    M = len(q_a)
    blocked = np.zeros(M, bool)
    np.logical_or.at(blocked, seg, bad)
    first = np.full(M, len(seg))
    np.minimum.at(first, seg[bad], np.flatnonzero(bad))
    idx = np.minimum(first, len(seg) - 1)
    return Violation(blocked, np.where(blocked, hit[idx], -2), np.where(blocked, s[idx], np.nan))


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
