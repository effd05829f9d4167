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
    if cfg.plan.kind == "adaptive":                     # a D-optimal seed; the rounds choose while measuring
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
    q_all, ok, skipped = solve_targets(cfg, kin, p_all, ids, sets, R, guard)
    grid_ok = np.flatnonzero(ok[: len(p_grid)])
    test_ok = len(p_grid) + np.flatnonzero(ok[len(p_grid):])
    order = interleave_tests(p_all, grid_ok, test_ok)
    if pl.order == "random":
        order = [order[i] for i in np.random.default_rng(pl.order_seed).permutation(len(order))]
    points = [PlanPoint(ids[i], sets[i], tuple(np.degrees(q_all[i]).round(6)), tuple(p_all[i])) for i in order]
    return finish_plan(cfg, guard, points, q_all[grid_ok], p_all[grid_ok], [ids[i] for i in grid_ok], skipped)
