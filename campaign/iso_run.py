"""ISO 9283 acceptance test on the cell: the standard cube, its cycles through the runner and the durable log,
and AP / RP / AD / RD (``robocal.iso9283``) with nominal and, given a calibrated model, corrected targets.

Plan (``plan.kind: iso9283``): the largest cube inside the grid box (or ``plan.iso9283.edge_mm``), shrunk in 5 %
steps until P1..P5 are reachable on the plan's robot configuration with the fixed SMR orientation; ``cycles``
cycles P1 -> P5 -> P4 -> P3 -> P2, so each pose is always approached from the same neighbour. Rows are logged
as set ``check`` (repeated poses) with ids ``N:P3.c07`` (nominal targets) or ``C:P3.c07`` (corrected targets).

Frame: the attained positions are measured in the tracker frame. With a calibrated model its registration
``T_tracker_base`` maps them into the robot base frame (the certificate). Without one, the base frame is the
least-squares rigid fit of the five barycentres onto the commanded poses: RP, RD and AD are unaffected, but AP
then excludes the part of the error a rigid frame absorbs (the report says so).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from robocal.frames import fit_rigid, inv_T, transform_points
from robocal.ik import solve_on_branch
from robocal.iso9283 import CYCLE_ORDER, POSE_NAMES, characteristics, cube_poses, largest_cube
from robocal.kinematics import Kinematics
from robocal.model import CalibratedModel
from robocal.noise import noise_floor_mm

from .cell import tracker_uncertainty
from .config import CampaignConfig
from .errors import CampaignError, ConfigError, DataError
from .plan import Plan, PlanPoint, tool_rotation
from .records import PointRecord

REPORT_FORMAT = "campaign-iso9283/1"
SHRINK = 0.95
FRAME_MODEL = "registration of the calibrated model (T_tracker_base)"
FRAME_FIT = ("least-squares rigid fit of the five barycentres to the commanded poses (no model given): AP excludes "
             "the part of the error a rigid frame absorbs; RP, AD and RD are frame-independent")


@dataclass(frozen=True)
class IsoCube:
    """The test cube actually used: centre (3,) and edge (mm), poses P1..P5 (5, 3) mm in the base frame, their
    nominal joints (5, n) deg, and why the edge is smaller than the largest cube (empty when it is not)."""
    center_mm: np.ndarray
    edge_mm: float
    p_base_mm: np.ndarray
    q_deg: np.ndarray
    note: str


def iso_cube(cfg: CampaignConfig, kin: Kinematics) -> IsoCube:
    """The largest cube inside the plan's box whose P1..P5 are reachable on the plan's configuration."""
    from .motion_safety import PathGuard

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
    guard = PathGuard.from_config(cfg, kin)
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


def iso_plan(cfg: CampaignConfig, kin: Kinematics, corrected_q_deg: np.ndarray | None = None) -> Plan:
    """The ISO 9283 plan: nominal-target cycles, then (given corrected joints (5, n) deg) corrected ones."""
    import hashlib
    import json

    from .motion_safety import PathGuard
    from .plan import _with_vias

    cube = iso_cube(cfg, kin)
    points = cycle_points(cube.q_deg, cube.p_base_mm, cfg.plan.iso9283.cycles, "N")
    if corrected_q_deg is not None:
        points += cycle_points(corrected_q_deg, cube.p_base_mm, cfg.plan.iso9283.cycles, "C")
    guard = PathGuard.from_config(cfg, kin)
    if guard is not None:                                 # swept path: via poses, never a changed cycle order
        ids = [p.point_id for p in points]
        points = _with_vias(cfg, guard, points)
        if [p.point_id for p in points] != ids:
            raise ConfigError(cfg.source_path, "plan.keep_out", "a keep-out box blocks the ISO 9283 cycle between two "
                              "poses and no via pose keeps the standard's order; move the box or plan.grid")
    digest = hashlib.sha256(json.dumps([[p.point_id, p.set, p.q_deg] + ([p.via_deg] if p.via_deg else [])
                                        for p in points]).encode()).hexdigest()
    return Plan(tuple(points), (), digest)


def corrected_joints(cfg: CampaignConfig, model: CalibratedModel, cube: IsoCube) -> np.ndarray:
    """Corrected joints (5, n) deg for P1..P5 with the calibrated model; every pose must pass the bounds."""
    from .correction import Targets, correct_targets

    R = tool_rotation(cfg.plan.tool_direction)
    accepted, rejected = correct_targets(cfg, model, Targets(POSE_NAMES, cube.p_base_mm, np.repeat(R[None], 5, 0)))
    if rejected:
        raise CampaignError(f"ISO 9283 pose {rejected[0].target_id} cannot be corrected: {rejected[0].reason}")
    by_id = {t.target_id: t for t in accepted}
    return np.array([by_id[name].q_corrected_deg for name in POSE_NAMES])


def iso_report(cfg: CampaignConfig, records: list[PointRecord], cube: IsoCube, model: CalibratedModel | None) -> dict:
    """AP/RP per pose and AD/RD (P2-P4) of every target kind in the log records (``N:`` and ``C:`` ids)."""
    by_kind: dict[str, dict[str, list]] = {}
    for rec in records:
        kind, rest = rec.point_id.split(":", 1)
        by_kind.setdefault(kind, {}).setdefault(rest.split(".")[0], []).append(rec.p_tracker_mm)
    if "N" not in by_kind:
        raise DataError("iso9283", "the log has no ISO 9283 cycles (point ids N:Pk.cNN)")
    p_cmd = cube.p_base_mm
    if model is not None:
        T_base_tracker, frame = inv_T(model.kinematics.T_tracker_base), FRAME_MODEL
    else:
        bary = np.array([np.mean(by_kind["N"][name], axis=0) for name in POSE_NAMES])
        T_base_tracker, frame = fit_rigid(bary, p_cmd), FRAME_FIT
    runs = []
    for kind, label in (("N", "nominal"), ("C", "corrected")):
        if kind not in by_kind:
            continue
        n = min(len(by_kind[kind][name]) for name in POSE_NAMES)
        p = np.array([transform_points(T_base_tracker, np.array(by_kind[kind][name][:n])) for name in POSE_NAMES])
        poses, dist = characteristics(p, p_cmd)
        dev = {name: np.round((p[j] - p[j].mean(axis=0))[:, :2] * 1000.0, 2).tolist()
               for j, name in enumerate(POSE_NAMES)}
        runs.append({"targets": label, "cycles": n, "poses": [pc.to_dict() for pc in poses],
                     "distance": dist.to_dict(), "max_ap_mm": max(pc.ap_mm for pc in poses),
                     "max_rp_mm": max(pc.rp_mm for pc in poses), "deviation_um": dev})
    T_tb = inv_T(T_base_tracker)
    floor = noise_floor_mm(transform_points(T_tb, p_cmd), tracker_uncertainty(cfg), cfg.robot.repeatability_mm)
    return {"format": REPORT_FORMAT, "config": cfg.name, "frame": frame,
            "cube": {"center_mm": cube.center_mm.tolist(), "edge_mm": cube.edge_mm, "note": cube.note,
                     "poses_base_mm": p_cmd.tolist()},
            "cycles": cfg.plan.iso9283.cycles, "payload_kg": cfg.tool.payload_kg,
            "noise_floor_mm": floor, "repeatability_spec_mm": cfg.robot.repeatability_mm, "runs": runs}


def render_iso(console, report: dict) -> None:
    """Rich table per target kind: AP, APx/y/z, RP per pose, and AD/RD."""
    from rich.table import Table

    for run in report["runs"]:
        t = Table(title=f"ISO 9283 ({run['targets']} targets, {run['cycles']} cycles, cube edge "
                        f"{report['cube']['edge_mm']:.0f} mm), mm")
        for col in ("pose", "AP", "APx", "APy", "APz", "RP"):
            t.add_column(col, justify="left" if col == "pose" else "right")
        for pc in run["poses"]:
            t.add_row(pc["pose"], f"{pc['ap_mm']:.4f}", f"{pc['apx_mm']:+.4f}", f"{pc['apy_mm']:+.4f}",
                      f"{pc['apz_mm']:+.4f}", f"{pc['rp_mm']:.4f}")
        console.print(t)
        d = run["distance"]
        console.print(f"{run['targets']}: AP max {run['max_ap_mm']:.4f} mm, RP max {run['max_rp_mm']:.4f} mm; "
                      f"distance {'-'.join(d['poses'])} {d['distance_cmd_mm']:.1f} mm: AD {d['ad_mm']:+.4f} mm, "
                      f"RD +-{d['rd_mm']:.4f} mm", highlight=False)
    console.print(f"frame: {report['frame']}; noise floor {report['noise_floor_mm']:.4f} mm", highlight=False)
    if report["cube"]["note"]:
        console.print(f"cube: {report['cube']['note']}", highlight=False)


def finish(cfg: CampaignConfig, run_dir, model: CalibratedModel | None = None) -> dict:
    """After the cycles are measured: the ISO report from the run's log, written as report.json (+ HTML)."""
    from pathlib import Path

    from .cell import nominal_kinematics
    from .fsutil import write_json
    from .runlog import read_log

    records = [p for p in read_log(Path(run_dir)).records() if ":" in p.point_id]
    report = iso_report(cfg, records, iso_cube(cfg, nominal_kinematics(cfg)), model)
    write_json(Path(run_dir) / "report.json", report)
    return report


def run_iso9283(cfg: CampaignConfig, model: CalibratedModel | None, run_dir=None, console=None,
                overwrite: bool = False):
    """``campaign iso9283``: nominal cycles, then (with a model) corrected cycles, through ``run_campaign`` (same
    safety, log and lifecycle); returns (RunResult, report or None)."""
    from dataclasses import replace

    from .cell import nominal_kinematics
    from .html_report import write_report
    from .pipeline import run_campaign

    kin = nominal_kinematics(cfg)
    cube = iso_cube(cfg, kin)
    plan = iso_plan(cfg, kin, None if model is None else corrected_joints(cfg, model, cube))
    result = run_campaign(cfg, run_dir, None, console, plan=plan, overwrite=overwrite)
    if result.iso9283 is None:
        return result, None
    report = finish(cfg, result.run_dir, model)            # again with the model's registration as the frame
    write_report(result.run_dir)
    return replace(result, iso9283=report), report


def is_iso_plan(plan: Plan) -> bool:
    """True for a plan built by :func:`iso_plan` (every id ``N:Pk.cNN`` or ``C:Pk.cNN``)."""
    return bool(plan.points) and all(p.point_id[:2] in ("N:", "C:") for p in plan.points)
