"""Optimal plans (``plan.kind: optimal``): ``plan.points`` calibration poses chosen from a candidate pool.

The pool: positions every ``plan.pool.step_mm`` in the grid box x the configured tool direction and directions
tilted around it x q_ref's IK branch and the flipped wrist; kept when the IK converges inside the joint limits,
off the wrist singularity, outside keep-out boxes / inside the envelope, within the tracker's range and with
the SMR facing the tracker (``tracker.max_incidence_deg``, or no worse than the configured direction does).
The choice: ``robocal.design`` (D-optimal on the whitened identification Jacobian with the pose-dependent effects
of ``calibration.effects: auto``, every prefix spreading the major joints over their ranges). The order: a short
tour from ``q_ref_deg``; with ``plan.stop: auto``, block after block (each block a short tour), the test set last.
The test set is the grid plan's: random in the box, configured orientation, measured after its nearest
calibration point (``stop: off``) or at the end (``stop: auto``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from robocal.design.optimal import Criterion, Forecast, criterion, d_optimal, forecast, short_tour
from robocal.kinematics.chains import alignment_margin_rad
from robocal.kinematics.models import Kinematics
from robocal.design.pool import candidate_poses, incidence_rad, smr_base_and_axis, tilted_rotations

from campaign.config.cell_model import CellModel
from campaign.config.schema import CampaignConfig
from campaign.errors import ConfigError
from .motion_safety import PathGuard
from .poses import (WRIST_MARGIN_DEG, finish_plan, grid_points, interleave_tests, solve_targets, test_targets,
                    tool_rotation)
from .points import Plan, PlanPoint


@dataclass(frozen=True, eq=False)
class Pool:
    """Candidate poses: joints (M, n) rad, SMR targets (M, 3) mm base frame, ids, and the selection criterion."""
    q_rad: np.ndarray
    p_base_mm: np.ndarray
    ids: tuple[str, ...]
    criterion: Criterion


def tracker_kinematics(cell: CellModel) -> Kinematics:
    """The nominal model with the tracker frame parallel to the base frame at ``tracker.position_in_base_mm`` (the base
    origin when unknown): the frame the measurement covariance of a planned pose is computed in."""
    T = np.eye(4)
    T[:3, 3] = -np.asarray(cell.config.tracker.position_in_base_mm or (0.0, 0.0, 0.0), float)
    return cell.kinematics.with_(T_tracker_base=T)


def pose_covariance(cell: CellModel, kin_t: Kinematics, q_rad: np.ndarray) -> np.ndarray:
    """(N, 3, 3) mm^2: the calibration weights of planned poses (tracker model at the predicted SMR position)."""
    p_base, _ = smr_base_and_axis(kin_t, q_rad)
    return cell.covariance(p_base + kin_t.T_tracker_base[:3, 3])


def candidate_pool(cell: CellModel, guard: PathGuard | None) -> Pool:
    """The candidate poses of an optimal plan with their criterion; ConfigError when none is left."""
    cfg, kin = cell.config, cell.kinematics
    pl, tr = cfg.plan, cfg.tracker
    step = pl.pool.step_mm or pl.grid.step_mm / 2
    cells, idx = grid_points(pl.grid.center_mm, pl.grid.size_mm, step)
    R0 = tool_rotation(pl.tool_direction)
    tilts = pl.pool.tilts if tr.position_in_base_mm is not None and pl.pool.tilt_deg > 0 else 0
    rotations = tilted_rotations(R0, math.radians(pl.pool.tilt_deg), tilts)
    q, at, ori, branch = candidate_poses(kin, cells, rotations, np.radians(pl.q_ref_deg), pl.pool.wrist_flip)
    n_solved = len(q)
    keep = np.degrees(alignment_margin_rad(kin, q)[0]) >= WRIST_MARGIN_DEG
    if tr.position_in_base_mm is not None:
        p_smr, R = smr_base_and_axis(kin, q)
        seen = incidence_rad(R, p_smr, tr.position_in_base_mm)
        as_configured = incidence_rad(np.broadcast_to(R0, R.shape), p_smr, tr.position_in_base_mm)
        keep &= seen <= np.maximum(math.radians(tr.max_incidence_deg), as_configured + 1e-9)
        if tr.max_range_mm is not None:
            keep &= np.linalg.norm(p_smr - np.asarray(tr.position_in_base_mm), axis=1) <= tr.max_range_mm
    n_visible = int(keep.sum())
    if guard is not None and keep.any():
        blocked = np.array([w is not None for w in guard.pose_reasons(np.degrees(q[keep]))])
        keep[np.flatnonzero(keep)[blocked]] = False
    if not keep.any():
        if guard is not None and n_visible:
            raise ConfigError(cfg.source_path, "plan.keep_out", f"all {n_visible} candidate poses of the optimal "
                              "plan stop inside a keep-out box or outside the envelope: no pose left to choose from")
        raise ConfigError(cfg.source_path, "plan.grid", f"no candidate pose of the optimal plan is usable "
                          f"({len(cells)} positions, {n_solved} IK solutions, {n_visible} off the wrist singularity "
                          "and visible to the tracker)")
    q, at, ori, branch = q[keep], at[keep], ori[keep], branch[keep]
    ids = tuple(f"O{i:02d}-{j:02d}-{k:02d}-{o}{'w' if b else ''}" for (i, j, k), o, b in zip(idx[at], ori, branch))
    kin_t = tracker_kinematics(cell)
    crit = criterion(kin_t, q, pose_covariance(cell, kin_t, q), cfg.tool.payload_kg)
    return Pool(q, cells[at], ids, crit)


def planned_count(cfg: CampaignConfig) -> tuple[int, str]:
    """(calibration points the plan holds, the key that sets it)."""
    pl = cfg.plan
    if pl.stop == "auto" and pl.max_points is not None:
        return pl.max_points, "plan.max_points"
    return int(pl.points), "plan.points"


def check_count(cfg: CampaignConfig, n: int, key: str, pool_size: int, identifiable: int) -> None:
    """ConfigError unless identifiable + 10 % <= n <= pool_size."""
    need = math.ceil(1.1 * identifiable)
    if n > pool_size:
        raise ConfigError(cfg.source_path, key, f"{n} calibration points requested but the candidate pool holds "
                          f"only {pool_size} poses")
    if n < need:
        raise ConfigError(cfg.source_path, key, f"{n} calibration points cannot identify the {identifiable} "
                          f"parameters the candidate poses determine: at least {need} (identifiable + 10 %)")


def block_ends(cfg: CampaignConfig, n: int, identifiable: int) -> tuple[int, ...]:
    """Calibration-point counts at which a ``stop: auto`` run refits: the first block holds at least the
    identifiable parameters + 10 %, then every ``plan.block_points``, the last at ``n``."""
    first = min(n, max(cfg.plan.block_points, math.ceil(1.1 * identifiable)))
    return tuple(range(first, n, cfg.plan.block_points)) + (n,)


def test_set(cell: CellModel, R0: np.ndarray, guard: PathGuard | None):
    """The grid plan's test set exactly: its targets solved in one batch with the grid vertices (the IK re-seeds
    a failed target from its nearest solved neighbour). (p (T, 3) mm, ids, q (T, n) rad, plannable indices,
    skipped)."""
    cfg = cell.config
    g = cfg.plan.grid
    p_grid, _ = grid_points(g.center_mm, g.size_mm, g.step_mm)
    p_test, test_ids = test_targets(cfg)
    ids = [""] * len(p_grid) + test_ids
    q, ok, skipped = solve_targets(cfg, cell.kinematics, np.vstack([p_grid, p_test]), ids,
                                   ["calib"] * len(p_grid) + ["test"] * len(p_test), R0, guard)
    k = len(p_grid)
    return p_test, test_ids, q[k:], np.flatnonzero(ok[k:]), [s for s in skipped if s.set == "test"]


def optimal_plan(cell: CellModel) -> Plan:
    """The optimal plan of the cell's config for its nominal model (ConfigError on bad counts, nothing moves)."""
    cfg = cell.config
    pl = cfg.plan
    guard = PathGuard.for_cell(cell)
    pool = candidate_pool(cell, guard)
    n, key = planned_count(cfg)
    check_count(cfg, n, key, len(pool.q_rad), pool.criterion.identifiable)
    chosen = d_optimal(pool.criterion.A, n, pool.criterion.spread).chosen
    q_ref = np.radians(pl.q_ref_deg)
    R0 = tool_rotation(pl.tool_direction)
    p_test, test_ids, q_test, test_ok, skipped = test_set(cell, R0, guard)
    blocks = block_ends(cfg, n, pool.criterion.identifiable) if pl.stop == "auto" else (n,)
    order, start = [], q_ref
    for lo, hi in zip((0,) + blocks[:-1], blocks):        # each block a short tour from where the last ended
        part = chosen[lo:hi]
        part = part[short_tour(pool.q_rad[part], start)]
        order += [int(i) for i in part]
        start = pool.q_rad[part[-1]]
    calib = [PlanPoint(pool.ids[i], "calib", tuple(np.degrees(pool.q_rad[i]).round(6)), tuple(pool.p_base_mm[i]))
             for i in order]
    tests = [PlanPoint(test_ids[i], "test", tuple(np.degrees(q_test[i]).round(6)), tuple(p_test[i])) for i in test_ok]
    if pl.stop == "auto":                              # the test set after the stop, in a short tour
        points = calib + [tests[i] for i in short_tour(q_test[test_ok], pool.q_rad[order[-1]])] if tests else calib
    else:                                              # each test point after its nearest calibration point
        p_all = np.vstack([pool.p_base_mm[order], p_test[test_ok]]) if len(test_ok) else pool.p_base_mm[order]
        seq = interleave_tests(p_all, np.arange(len(order)), len(order) + np.arange(len(test_ok)))
        points = [(calib + tests)[i] for i in seq]
    return finish_plan(cfg, guard, points, pool.q_rad[order], pool.p_base_mm[order], [pool.ids[i] for i in order],
                       skipped, blocks if pl.stop == "auto" else ())


def plan_forecast(cell: CellModel, plan: Plan) -> Forecast:
    """What a plan's calibration points should achieve before any is measured (``robocal.design.optimal.forecast``):
    parameter std, the calibrated model's own RMS error at the test poses (AP(theta)) and the noise floor there."""
    kin_t = tracker_kinematics(cell)
    q_cal = np.radians([p.q_deg for p in plan.points if p.set == "calib"])
    q_test = np.radians([p.q_deg for p in plan.points if p.set == "test"]).reshape(-1, kin_t.n)
    if not len(q_test):
        q_test = q_cal
    return forecast(kin_t, q_cal, pose_covariance(cell, kin_t, q_cal), q_test, pose_covariance(cell, kin_t, q_test),
                    cell.config.tool.payload_kg)
