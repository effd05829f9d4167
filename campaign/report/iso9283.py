"""ISO 9283 characteristics of an acceptance run: AP / RP / AD / RD (``robocal.iso9283``) of the logged cycles,
with nominal and, given a calibrated model, corrected targets, as the run's ``report.json``
(``campaign-iso9283/1``). The cube and its plan are in :mod:`campaign.plan.iso9283`; the run itself is
``campaign.workflows.run_iso9283``.

Rows are logged as set ``check`` (repeated poses) with ids ``N:P3.c07`` (nominal targets) or ``C:P3.c07``
(corrected targets).

Frame: the attained positions are measured in the tracker frame. With a calibrated model its registration
``T_tracker_base`` maps them into the robot base frame (the certificate). Without one, the base frame is the
least-squares rigid fit of the five barycentres onto the commanded poses: RP, RD and AD are unaffected, but AP
then excludes the part of the error a rigid frame absorbs (the report says so).
"""
from __future__ import annotations

import numpy as np

from campaign.config.cell_model import CellModel
from campaign.errors import DataError
from campaign.plan.iso9283 import IsoCube, iso_cube
from campaign.run.log_records import PointRecord
from robocal.frames import fit_rigid, inv_T, transform_points
from robocal.iso9283 import POSE_NAMES, characteristics
from robocal.model import CalibratedModel


REPORT_FORMAT = "campaign-iso9283/1"


FRAME_MODEL = "registration of the calibrated model (T_tracker_base)"
FRAME_FIT = ("least-squares rigid fit of the five barycentres to the commanded poses (no model given): AP excludes "
             "the part of the error a rigid frame absorbs; RP, AD and RD are frame-independent")


def iso_report(cell: CellModel, records: list[PointRecord], cube: IsoCube, model: CalibratedModel | None) -> dict:
    """AP/RP per pose and AD/RD (P2-P4) of every target kind in the log records (``N:`` and ``C:`` ids)."""
    cfg = cell.config
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
    floor = cell.noise_floor_mm(transform_points(T_tb, p_cmd))
    return {"format": REPORT_FORMAT, "config": cfg.name, "frame": frame,
            "cube": {"center_mm": cube.center_mm.tolist(), "edge_mm": cube.edge_mm, "note": cube.note,
                     "poses_base_mm": p_cmd.tolist()},
            "cycles": cfg.plan.iso9283.cycles, "payload_kg": cfg.tool.payload_kg,
            "noise_floor_mm": floor, "repeatability_spec_mm": cfg.robot.repeatability_mm, "runs": runs}


def finish(cell: CellModel, run_dir, model: CalibratedModel | None = None) -> dict:
    """After the cycles are measured: the ISO report from the run's log, written as report.json (+ HTML)."""
    from pathlib import Path

    from campaign.io.durable import write_json
    from campaign.run.log_reader import read_log

    records = [p for p in read_log(Path(run_dir)).records() if ":" in p.point_id]
    report = iso_report(cell, records, iso_cube(cell), model)
    write_json(Path(run_dir) / "report.json", report)
    return report
