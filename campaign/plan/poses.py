"""The measurement plan: data, not a generator (bluesky-style), so it can be summarised, hashed and dry-run.

Seed 000's grid (box centre/size/step in the robot base frame) + a seeded random test set in the same
box, one fixed SMR orientation and ONE robot configuration for every point (the IK branch of
``q_ref``), unreachable points reported and skipped, a serpentine motion order with each test point
measured next to its nearest grid point (or ``plan.order: random``: a seeded shuffle, so that approach
directions and move sizes vary), repeated check poses through the run, and rounds of reference-nest
readings (``plan.nests``; set ``nest``; the robot waits, the tracker aims at the nest) at the start, every
``every_n_points`` points and at the end.
"""
from __future__ import annotations

import hashlib
import json

import numpy as np

from campaign.config.schema import CampaignConfig
from robocal.kinematics.chains import alignment_label, alignment_margin_rad, alignments
from robocal.kinematics.ik import solve_ik, solve_on_branch
from robocal.kinematics.models import Kinematics

from .motion_safety import PathGuard, with_vias
from .points import Plan, PlanPoint, Skipped, nest_point_id


WRIST_MARGIN_DEG = 10.0    # points closer than this to the wrist singularity (J4 || J6 on a 6-axis arm; the
                           # alignments of robocal.kinematics.chains on other chains) are not planned


def tool_rotation(direction, down=(0.0, 0.0, -1.0)) -> np.ndarray:
    """Fixed flange orientation R_base_flange (3, 3): z along ``direction``, x as close as possible to ``down``
    (+x of the base if the direction is vertical)."""
    z = np.asarray(direction, float) / np.linalg.norm(direction)
    x = np.asarray(down, float) - z * (z @ np.asarray(down, float))
    if np.linalg.norm(x) < 1e-6:
        x = np.array([1.0, 0.0, 0.0]) - z * z[0]
    x /= np.linalg.norm(x)
    return np.stack([x, np.cross(z, x), z], axis=1)


def grid_points(center, size, step) -> tuple[np.ndarray, np.ndarray]:
    """Grid vertices (M, 3) mm and their integer indices (M, 3), in serpentine order (x fastest)."""
    counts = [int(np.floor(s / step + 1e-9)) + 1 for s in size]
    lo = np.asarray(center, float) - np.asarray(size, float) / 2
    idx = []
    for k in range(counts[2]):
        ys = range(counts[1]) if k % 2 == 0 else reversed(range(counts[1]))
        for n, j in enumerate(ys):
            xs = range(counts[0]) if (n + k * counts[1]) % 2 == 0 else reversed(range(counts[0]))
            idx += [(i, j, k) for i in xs]
    idx = np.array(idx)
    return lo + idx * step, idx


def unreachable_reasons(kin: Kinematics, p: np.ndarray, R, q_ref, *, orientation: str = "the fixed SMR orientation",
                        point_mm=None) -> list[str]:
    """Why each of the targets p (M, 3) mm is not reachable on q_ref's branch (one batched IK from q_ref, flange
    orientation R, flange point ``point_mm`` (default the SMR); ``orientation`` names R in the reason): the plan's
    skipped points and ``correct``'s rejected targets."""
    if len(p) == 0:
        return []
    res = solve_ik(kin, p, R, q_ref, point_mm=point_mm)
    reasons = []
    for q, conv in zip(res.q_rad, res.converged):
        bad = np.flatnonzero((q < kin.q_min_rad) | (q > kin.q_max_rad))
        if not conv:
            reasons.append(f"unreachable with {orientation}")
        elif len(bad):
            j = bad[0]
            reasons.append(f"joint {j + 1} would be at {np.degrees(q[j]):.1f} deg, outside "
                           f"[{np.degrees(kin.q_min_rad[j]):.0f}, {np.degrees(kin.q_max_rad[j]):.0f}]")
        else:
            reasons.append("reachable only in another robot configuration")
    return reasons


def _check_poses(q: np.ndarray, p: np.ndarray, count: int) -> list[int]:
    """Indices of ``count`` reachable grid points spread over the box (farthest-point sampling)."""
    if count <= 0 or len(p) == 0:
        return []
    chosen = [int(np.argmin(np.linalg.norm(p - p.mean(axis=0), axis=1)))]
    while len(chosen) < min(count, len(p)):
        d = np.min(np.linalg.norm(p[:, None] - p[chosen][None], axis=2), axis=1)
        chosen.append(int(np.argmax(d)))
    return chosen


def test_targets(cfg: CampaignConfig) -> tuple[np.ndarray, list[str]]:
    """The seeded random test positions (N, 3) mm in the grid box and their ids."""
    g, t = cfg.plan.grid, cfg.plan.test
    rng = np.random.default_rng(t.seed)
    c, s = np.asarray(g.center_mm), np.asarray(g.size_mm)
    return rng.uniform(c - s / 2, c + s / 2, (t.count, 3)), [f"T{i + 1:03d}" for i in range(t.count)]


def solve_targets(cfg: CampaignConfig, kin: Kinematics, p: np.ndarray, ids, sets, R, guard: PathGuard | None,
                  q_seed: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, list[Skipped]]:
    """Joints (N, n) rad of the targets p (N, 3) with the flange orientation R on ``q_ref_deg``'s branch, which are
    plannable (N,) bool (reachable, off the wrist singularity, outside keep-out boxes), and the skipped ones.
    ``q_seed`` (N, n) rad: per-target references (a track's carriage position: kept by the IK)."""
    q_ref = np.radians(cfg.plan.q_ref_deg) if q_seed is None else q_seed
    q_all, ok = solve_on_branch(kin, p, R, q_ref)
    bad = np.flatnonzero(~ok)
    reasons = unreachable_reasons(kin, p[bad], R if np.ndim(R) == 2 else R[bad],
                                  q_ref if q_seed is None else q_seed[bad])
    skipped = [Skipped(ids[i], sets[i], tuple(p[i]), w) for i, w in zip(bad, reasons)]
    margin, which = alignment_margin_rad(kin, q_all)
    wrist = np.degrees(margin)
    near = ok & (wrist < WRIST_MARGIN_DEG)
    words = [f"wrist singularity ({alignment_label(a)}" if kin.n - kin.n_track == 6 else
             f"{alignment_label(a)} alignment (a singularity or branch boundary" for a in alignments(kin)]
    skipped += [Skipped(ids[i], sets[i], tuple(p[i]), f"{wrist[i]:.1f} deg from the {words[which[i]]}; margin "
                        f"{WRIST_MARGIN_DEG:.0f} deg)") for i in np.flatnonzero(near)]
    ok &= ~near
    if guard is not None:                                   # stops inside keep-out boxes / outside the envelope
        why = guard.pose_reasons(np.degrees(q_all[ok]))
        blocked = np.flatnonzero(ok)[[w is not None for w in why]]
        skipped += [Skipped(ids[i], sets[i], tuple(p[i]), w) for i, w in zip(np.flatnonzero(ok), why) if w]
        ok[blocked] = False
    return q_all, ok, skipped


def finish_plan(cfg: CampaignConfig, guard: PathGuard | None, points: list[PlanPoint], q_calib: np.ndarray,
                p_calib: np.ndarray, calib_ids: list[str], skipped: list[Skipped],
                blocks: tuple[int, ...] = (), candidates: tuple[PlanPoint, ...] = ()) -> Plan:
    """The measurement sequence ``points`` with check-pose repeats (chosen among the calibration points q_calib
    rad, p_calib mm), nest rounds and via poses, hashed (with an adaptive plan's ``candidates``)."""
    points = _with_check_poses(points, q_calib, p_calib, calib_ids, cfg.plan.check_poses)
    points = with_nest_rounds(points, cfg.plan.nests)
    if guard is not None:
        points = with_vias(cfg, guard, points)
    rows = [[p.point_id, p.set, p.q_deg] + ([p.via_deg] if p.via_deg else []) for p in points]
    if candidates:
        rows.append(["candidates", [[p.point_id, p.q_deg] for p in candidates]])
    digest = hashlib.sha256(json.dumps(rows).encode()).hexdigest()
    return Plan(tuple(points), tuple(skipped), digest, blocks, tuple(candidates))


def interleave_tests(p, grid_ok, test_ok) -> list[int]:
    """The calibration points ``grid_ok`` in the given order (a grid's serpentine, an optimal plan's tour), each
    test point of ``test_ok`` right after its nearest calibration point (positions p, mm)."""
    if len(grid_ok) == 0:
        return list(test_ok)
    nearest = np.argmin(np.linalg.norm(p[test_ok][:, None] - p[grid_ok][None], axis=2), axis=1) if len(test_ok) else []
    after = {}
    for t, n in zip(test_ok, nearest):
        after.setdefault(int(n), []).append(int(t))
    order = []
    for n, gi in enumerate(grid_ok):
        order.append(int(gi))
        order += after.get(n, [])
    return order


def _with_check_poses(points, q_grid, p_grid, grid_ids, cfg_check) -> list[PlanPoint]:
    """Insert repeats of the check poses at the start, every ``every_n_points`` and at the end."""
    chosen = _check_poses(q_grid, p_grid, cfg_check.count)
    if not chosen:
        return points
    every = max(1, cfg_check.every_n_points)
    out, rep = [], 0

    def repeat():
        nonlocal rep
        rep += 1
        for k, c in enumerate(chosen):
            out.append(PlanPoint(f"K{k + 1}.{rep:03d}", "check", tuple(np.degrees(q_grid[c]).round(6)),
                                 tuple(p_grid[c])))
    repeat()
    for n, pt in enumerate(points):
        out.append(pt)
        if (n + 1) % every == 0 and n + 1 < len(points):
            repeat()
    repeat()
    return out


def with_nest_rounds(points: list[PlanPoint], nests, rounds: int = 0, start: bool = True) -> list[PlanPoint]:
    """Insert a round of every nest (``NestsConfig``) at the start (unless not ``start``), after every
    ``every_n_points`` points and at the end, numbered on from ``rounds`` rounds already read; nest points have set
    ``nest``, the nest's approximate base-frame position and, as joints, where the robot waits (the previous
    point's; the first point's for the start round)."""
    if not nests.points or not points:
        return points
    out: list[PlanPoint] = []

    def one_round():
        nonlocal rounds
        rounds += 1
        q = out[-1].q_deg if out else points[0].q_deg
        out.extend(PlanPoint(nest_point_id(n.id, rounds), "nest", q, tuple(n.p_base_mm)) for n in nests.points)
    if start:
        one_round()
    for k, pt in enumerate(points):
        out.append(pt)
        if (k + 1) % nests.every_n_points == 0 and k + 1 < len(points):
            one_round()
    one_round()
    return out
