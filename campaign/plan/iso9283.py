"""The ISO 9283 acceptance-test plan (``plan.kind: iso9283``): the largest cube inside the plan's box (or
``plan.iso9283.edge_mm``), shrunk in 5 % steps until P1..P5 are reachable on the plan's robot configuration with the
fixed SMR orientation, and ``cycles`` cycles P1 -> P5 -> P4 -> P3 -> P2, so each pose is always approached from the
same neighbour (ids ``N:Pk.cNN`` nominal, ``C:Pk.cNN`` corrected)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from campaign.config.cell_model import CellModel
from campaign.errors import CampaignError, ConfigError
from robocal.kinematics.ik import solve_on_branch
from robocal.iso9283 import CYCLE_ORDER, POSE_NAMES, cube_poses, largest_cube

from .points import Plan, PlanPoint
from .poses import tool_rotation


SHRINK = 0.95


@dataclass(frozen=True)
class IsoCube:
    """The test cube actually used: centre (3,) and edge (mm), poses P1..P5 (5, 3) mm in the base frame, their
    nominal joints (5, n) deg, and why the edge is smaller than the largest cube (empty when it is not)."""
    center_mm: np.ndarray
    edge_mm: float
    p_base_mm: np.ndarray
    q_deg: np.ndarray
    note: str


def iso_cube(cell: CellModel) -> IsoCube:
    """The largest cube inside the plan's box whose P1..P5 are reachable on the plan's configuration (nominal
    model)."""
    from .motion_safety import PathGuard

    cfg, kin = cell.config, cell.kinematics
    g, pl = cfg.plan.grid, cfg.plan
    lo = np.asarray(g.center_mm, float) - np.asarray(g.size_mm, float) / 2
    hi = np.asarray(g.center_mm, float) + np.asarray(g.size_mm, float) / 2
    if pl.envelope is not None:                           # inside the plan's envelope, with the clearance
        lo = np.maximum(lo, np.asarray(pl.envelope.min_mm, float) + pl.clearance_mm)
        hi = np.minimum(hi, np.asarray(pl.envelope.max_mm, float) - pl.clearance_mm)
        if np.any(hi <= lo):
            raise CampaignError(f"{cfg.source_path}: plan.grid and plan.envelope do not overlap: no ISO 9283 cube")
    center, edge = largest_cube((lo + hi) / 2, hi - lo)
    if pl.iso9283.edge_mm > 0:
        edge = min(edge, pl.iso9283.edge_mm)
    R = tool_rotation(pl.tool_direction)
    guard = PathGuard.for_cell(cell)
    start = edge
    for _ in range(60):
        p = cube_poses(center, edge)
        q, ok = solve_on_branch(kin, p, R, np.radians(pl.q_ref_deg))
        if ok.all() and guard is not None:                # stops inside keep-out boxes / outside the envelope
            ok &= np.array([w is None for w in guard.pose_reasons(np.degrees(q))])
        if ok.all():
            note = "" if edge == start else (f"shrunk from {start:.0f} mm: poses outside the joint limits, "
                                             "unreachable on the plan's configuration or in a keep-out box")
            return IsoCube(center, float(edge), p, np.degrees(q), note)
        edge *= SHRINK
    raise CampaignError(f"{cfg.source_path}: no ISO 9283 cube inside the plan's box is reachable on the plan's "
                        "robot configuration (plan.grid, plan.q_ref_deg)")


def cycle_points(q_by_pose_deg: np.ndarray, p_base_mm: np.ndarray, cycles: int, prefix: str) -> list[PlanPoint]:
    """``cycles`` x (P1, P5, P4, P3, P2) as plan points (set ``check``), ids ``PREFIX:Pk.cNN``."""
    return [PlanPoint(f"{prefix}:{POSE_NAMES[j]}.c{c + 1:02d}", "check", tuple(np.round(q_by_pose_deg[j], 6)),
                      tuple(p_base_mm[j])) for c in range(cycles) for j in CYCLE_ORDER]


def iso_plan(cell: CellModel, corrected_q_deg: np.ndarray | None = None) -> Plan:
    """The ISO 9283 plan: nominal-target cycles, then (given corrected joints (5, n) deg) corrected ones."""
    import hashlib
    import json

    from .motion_safety import PathGuard
    from .motion_safety import with_vias

    cfg = cell.config
    cube = iso_cube(cell)
    points = cycle_points(cube.q_deg, cube.p_base_mm, cfg.plan.iso9283.cycles, "N")
    if corrected_q_deg is not None:
        points += cycle_points(corrected_q_deg, cube.p_base_mm, cfg.plan.iso9283.cycles, "C")
    guard = PathGuard.for_cell(cell)
    if guard is not None:                                 # swept path: via poses, never a changed cycle order
        ids = [p.point_id for p in points]
        points = with_vias(cfg, guard, points)
        if [p.point_id for p in points] != ids:
            raise ConfigError(cfg.source_path, "plan.keep_out", "a keep-out box blocks the ISO 9283 cycle between two "
                              "poses and no via pose keeps the standard's order; move the box or plan.grid")
    digest = hashlib.sha256(json.dumps([[p.point_id, p.set, p.q_deg] + ([p.via_deg] if p.via_deg else [])
                                        for p in points]).encode()).hexdigest()
    return Plan(tuple(points), (), digest)


def is_iso_plan(plan: Plan) -> bool:
    """True for a plan built by :func:`iso_plan` (every id ``N:Pk.cNN`` or ``C:Pk.cNN``)."""
    return bool(plan.points) and all(p.point_id[:2] in ("N:", "C:") for p in plan.points)
