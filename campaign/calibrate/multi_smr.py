"""Two or three SMRs on one tool in a campaign: the rigid-tool screen and the per-SMR identification.

``screen_smrs``: the inter-SMR distances must stay constant (one rigid tool); a pose whose distances differ from
their medians is a measurement fault whatever its set (calib, test, check: the test is model-free) and is set
aside with its reason; distances that are not constant at all are bad input (DataError, exit 2).
``multi_smr_report``: one robot, one flange offset per SMR, identified on the kept calibration rows, with the
test figures per SMR and, with three SMRs, the flange orientation error (arc seconds).
``pose_estimator`` / ``tool_orientation_errors_arcsec``: the 6D pose of the tool during ``verify`` (seed 003):
SMR 1 measured, SMRs 2 and 3 predicted by GPR models trained on the run's calibration stops (where all three
were measured) at the identified offsets, the three points adjusted to the tool's rigid triangle, then the
flange pose fitted to them.
"""
from __future__ import annotations

import numpy as np

from robocal.kinematics.frames import inv_T, matrix_to_rotvec
from robocal.identify.identification import IdentificationError
from robocal.multi_smr.calibration import calibrate_multi_smr, orientation_errors_arcsec
from robocal.multi_smr.three_smr_pose import MultiSMRPoseEstimator, SMRTool, fit_points_pose
from robocal.identify.screening import smr_triangle
from robocal.measure.stats import error_stats

from campaign.config.cell_model import CellModel
from campaign.errors import DataError
from campaign.data.dataset import Dataset
from campaign.run.log_records import PointRecord

from .report_sections import AngleStats, ErrorFigures, ExcludedPoint, MultiSmrReport

MIN_TRAINING_STOPS = 20           # calibration stops with all three SMRs needed to train the SMR 2/3 predictors


def smr_clouds(ds: Dataset) -> list[np.ndarray]:
    """The measured SMR centres of every row: [p, p2] or [p, p2, p3] (N, 3) mm; [p] with one SMR."""
    return [c for c in (ds.p_tracker_mm, ds.p2_tracker_mm, ds.p3_tracker_mm) if c is not None]


def screen_smrs(ds: Dataset, cell: CellModel) -> tuple[np.ndarray, list[ExcludedPoint]]:
    """(keep (N,) bool, excluded points) of the SMR-triangle screen (all True and [] with one
    SMR; the tracker's uncertainty model weighs each distance); DataError when the SMR distances are not those
    of one rigid tool."""
    clouds = smr_clouds(ds)
    if len(clouds) < 2:
        return np.ones(len(ds), bool), []
    tri = smr_triangle(np.stack(clouds), np.stack([cell.covariance(c) for c in clouds]))
    if not tri.rigid:
        raise DataError(ds.source, f"{tri.why} (x..z{len(clouds)} columns from another target, or in another "
                                   "order?)")
    return tri.keep, [ExcludedPoint(ds.point_id[e.index], ds.set[e.index], e.reason) for e in tri.excluded]


def multi_smr_report(ds: Dataset, cell: CellModel, kin0, kept_rows: np.ndarray, test: np.ndarray,
                     offsets0=None) -> MultiSmrReport:
    """Multi-SMR identification (one robot, one flange offset per SMR, from ``offsets0``: the registered ones, by
    default the configured ones) on the kept calib rows and its test figures per SMR; with three SMRs, the flange
    orientation error on the test set (arc seconds)."""
    clouds = smr_clouds(ds)
    offsets0 = cell.config.tool.smrs_mm if offsets0 is None else offsets0
    if len(offsets0) < len(clouds):
        return MultiSmrReport(len(clouds), skipped=f"the data has {len(clouds)} SMRs but the config's tool names "
                              f"{len(offsets0)} (tool.p_flange_smr2_mm / p_flange_smr3_mm give the nominal offsets)")
    P = np.stack(clouds)
    q = np.radians(ds.q_deg)
    cov = np.stack([cell.covariance(c[kept_rows]) for c in clouds])
    try:
        res = calibrate_multi_smr(kin0, q[kept_rows], P[:, kept_rows], np.array(offsets0[:len(clouds)]), cov,
                                  cell.options)
    except (IdentificationError, np.linalg.LinAlgError) as exc:
        raise DataError(ds.source, f"multi-SMR calibration failed: {exc}") from None
    test_figures, orientation = {}, None
    if test.any():
        pred = res.predict_tracker(q[test])
        test_figures = {f"smr{s + 1}": ErrorFigures.of(error_stats(P[s, test] - pred[s])) for s in range(len(clouds))}
        if len(clouds) == 3:
            orientation = angle_stats(orientation_errors_arcsec(res.kinematics, res.p_flange_smr_mm, q[test],
                                                                P[:, test]))
    return MultiSmrReport(len(clouds), None, res.p_flange_smr_mm.tolist(), res.sigma0, res.converged,
                          tuple(res.unidentifiable), test_figures, orientation)


def identified_offsets(model) -> np.ndarray | None:
    """The per-SMR flange offsets (3, 3) mm a three-SMR calibration stored in the model, else None."""
    offsets = (model.meta or {}).get("p_flange_smrs_mm")
    return np.asarray(offsets, float) if offsets is not None and len(offsets) == 3 else None


def pose_estimator(cell: CellModel, model, records) -> MultiSMRPoseEstimator | None:
    """Seed 003's 6D pose estimator for a three-SMR run (None otherwise): the model's kinematics, the tool at the
    identified offsets, GPR predictors of SMRs 2 and 3 trained on the run's calibration stops (commanded joints)."""
    offsets = identified_offsets(model)
    stops = [r for r in records if isinstance(r, PointRecord) and r.set == "calib" and len(r.smrs) == 2]
    if offsets is None or len(stops) < MIN_TRAINING_STOPS:
        return None
    q = np.radians([r.q_cmd_deg for r in stops])
    p2, p3 = (np.array([next(s.p_tracker_mm for s in r.smrs if s.k == k) for r in stops]) for k in (2, 3))
    return MultiSMRPoseEstimator.fit(model.kinematics, SMRTool(offsets), q, p2, p3, cell.tracker,
                                     n_restarts=1)


def tool_orientation_errors_arcsec(T_tracker_flange: np.ndarray, T_tracker_base: np.ndarray,
                                   R_target_base: np.ndarray, R_flange_tool: np.ndarray) -> np.ndarray:
    """Angle (N,) arc seconds between the tool orientation of flange poses T_tracker_flange (N, 4, 4) and the
    target orientations R_target_base (N, 3, 3) (base frame; tool = flange x R_flange_tool)."""
    R = (inv_T(T_tracker_base)[None, :3, :3] @ T_tracker_flange[:, :3, :3]) @ R_flange_tool
    return np.degrees(np.linalg.norm(matrix_to_rotvec(R @ np.swapaxes(R_target_base, 1, 2)), axis=1)) * 3600.0


def measured_flange_poses(offsets_mm: np.ndarray, points: list[PointRecord]) -> np.ndarray | None:
    """Flange poses (N, 4, 4) fitted to the three measured SMRs of each record, None unless all have three."""
    if not points or any(len(r.smrs) != 2 for r in points):
        return None
    P = np.array([[r.p_tracker_mm] + [s.p_tracker_mm for s in sorted(r.smrs, key=lambda s: s.k)] for r in points])
    return fit_points_pose(offsets_mm, P)


def angle_stats(a_arcsec: np.ndarray, source: str | None = None) -> AngleStats:
    """mean / rms / max / n of orientation errors (arc seconds) and how the poses were obtained."""
    return AngleStats(float(a_arcsec.mean()), float(np.sqrt(np.mean(a_arcsec**2))), float(a_arcsec.max()),
                      int(len(a_arcsec)), source)
