"""``build_plan``: the plan of a config: the calibration grid with its test points (here), ``plan.kind: optimal``
(``optimal``) or ``plan.kind: iso9283`` (``iso9283``)."""
from __future__ import annotations

import numpy as np

from campaign.config.cell_model import CellModel

from .motion_safety import PathGuard
from .points import Plan, PlanPoint
from .poses import finish_plan, grid_points, interleave_tests, solve_targets, test_targets, tool_rotation


def build_plan(cell: CellModel) -> Plan:
    """Plan of a campaign config for its nominal model."""
    cfg, kin = cell.config, cell.kinematics
    if cfg.plan.kind == "iso9283":                      # ISO 9283 acceptance test: the standard's cube and cycles
        from .iso9283 import iso_plan
        return iso_plan(cell)
    if cfg.plan.kind == "optimal":                      # D-optimal poses from a candidate pool
        from .optimal import optimal_plan
        return optimal_plan(cell)
    if cfg.plan.kind == "adaptive":                     # a space-filling seed; the rounds choose while measuring
        from .adaptive import adaptive_plan
        return adaptive_plan(cell)
    g, pl = cfg.plan.grid, cfg.plan
    R = tool_rotation(pl.tool_direction)
    p_grid, idx = grid_points(g.center_mm, g.size_mm, g.step_mm)
    grid_ids = [f"G{i:02d}-{j:02d}-{k:02d}" for i, j, k in idx]
    p_test, test_ids = test_targets(cfg)
    p_all = np.vstack([p_grid, p_test])
    sets = ["calib"] * len(p_grid) + ["test"] * len(p_test)
    ids = grid_ids + test_ids
    guard = PathGuard.for_cell(cell)
    q_seed = None
    if kin.track is not None:                           # the grid rides on the carriage, station by station
        travel = track_positions(cfg, len(p_grid), len(p_test))
        p_all = p_all + travel[:, None] * kin.track
        q_seed = np.tile(np.radians(pl.q_ref_deg), (len(p_all), 1))
        q_seed[:, 0] = np.radians(travel)
    if kin.n - kin.n_track < 6:                         # fewer than 6 axes: the direction turns with the arm
        R = arm_plane_rotations(R, p_all - (0.0 if q_seed is None else np.degrees(q_seed[:, :1]) * kin.track))
    q_all, ok, skipped = solve_targets(cfg, kin, p_all, ids, sets, R, guard, q_seed)
    grid_ok = np.flatnonzero(ok[: len(p_grid)])
    test_ok = len(p_grid) + np.flatnonzero(ok[len(p_grid):])
    if q_seed is not None:                              # station by station: the carriage moves 1 / K of the time
        grid_ok = grid_ok[np.argsort(q_seed[grid_ok, 0], kind="stable")]
    order = interleave_tests(p_all, grid_ok, test_ok)
    if pl.order == "random":
        order = [order[i] for i in np.random.default_rng(pl.order_seed).permutation(len(order))]
    points = [PlanPoint(ids[i], sets[i], tuple(np.degrees(q_all[i]).round(6)), tuple(p_all[i])) for i in order]
    return finish_plan(cfg, guard, points, q_all[grid_ok], p_all[grid_ok], [ids[i] for i in grid_ok], skipped)


def track_positions(cfg, n_grid: int, n_test: int) -> np.ndarray:
    """Carriage positions (mm) of the grid points (dealt in turn to ``plan.track_stations`` stations evenly over
    the travel) and of the test points (seeded uniform over the travel, between the stations too)."""
    tr = cfg.robot.track
    stations = np.linspace(tr.q_min_deg, tr.q_max_deg, cfg.plan.track_stations)
    rng = np.random.default_rng([cfg.plan.test.seed, 1])
    return np.concatenate([stations[np.arange(n_grid) % len(stations)],
                           rng.uniform(tr.q_min_deg, tr.q_max_deg, n_test)])


def arm_plane_rotations(R: np.ndarray, p_arm_mm: np.ndarray) -> np.ndarray:
    """(N, 3, 3) the fixed tool orientation R turned about the base z axis to each target's azimuth (positions
    p_arm_mm (N, 3) relative to the arm's base): an arm of fewer than six axes points its tool in its own vertical
    plane, so ``plan.tool_direction`` is read as seen along +x of that plane."""
    a = np.arctan2(p_arm_mm[:, 1], p_arm_mm[:, 0])
    c, s = np.cos(a), np.sin(a)
    Rz = np.zeros((len(a), 3, 3))
    Rz[:, 0, 0], Rz[:, 0, 1], Rz[:, 1, 0], Rz[:, 1, 1], Rz[:, 2, 2] = c, -s, s, c, 1.0
    return Rz @ R
