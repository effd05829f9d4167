"""Closed-loop verification: the run's test points measured at their corrected joints, pass after pass
(``VerifyPasses``), and ``verify.json``."""
from __future__ import annotations

from dataclasses import dataclass, replace
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from campaign.calibrate.multi_smr import angle_stats, measured_flange_poses, tool_orientation_errors_arcsec
from campaign.calibrate.report_sections import ErrorFigures, VerifyPass
from campaign.config.cell_model import CellModel
from campaign.io.durable import write_json
from campaign.plan.points import PlanPoint
from campaign.run.log_records import PointRecord
from robocal.correct import closed_loop_step, tool_transform
from robocal.kinematics.frames import transform_points
from robocal.kinematics.models import fk
from robocal.layers.calibrated_model import CalibratedModel
from robocal.measure.stats import error_stats

from .configuration import configuration_reasons
from .targets import limits_deg, model_pose_fn, run_correction
from .verify_drift import VerifyDrift
from .verify_report import POOLED, UNCORRECTED, VERIFY_FORMAT, VerifyReport


# ---------------------------------------------------------------- closed-loop verification


def held_reasons(q: np.ndarray, q0: np.ndarray, limit_rad: float, lo: np.ndarray, hi: np.ndarray,
                 limit_deg: float, moved_mm: np.ndarray | None = None, limit_mm: float = np.inf) -> list[str | None]:
    """Per point: None when the corrected joints q (N, n) rad may be commanded, else why it is held at q0.
    ``moved_mm`` (N,): how far the corrected command moves the nominal tool point from the target (mm), held above
    ``limit_mm`` (the same bounds as ``check_targets``)."""
    step = np.abs(q - q0)
    moved = np.zeros(len(q)) if moved_mm is None else np.asarray(moved_mm, float)
    out: list[str | None] = []
    for i in range(len(q)):
        over = np.flatnonzero(step[i] > limit_rad)
        outside = np.flatnonzero((q[i] < lo) | (q[i] > hi))
        if len(outside):
            out.append(f"corrected joint {outside[0] + 1} outside its limits")
        elif len(over):
            out.append(f"correction of joint {over[0] + 1} > max_joint_correction_deg {limit_deg:g}")
        elif moved[i] > limit_mm:
            out.append(f"command moves the tool > max_position_correction_mm {limit_mm:g} from the target")
        else:
            out.append(None)
    return out


def pass_summary(stage: str, err: np.ndarray, safe: np.ndarray, held: list[str | None]) -> VerifyPass:
    """One verify pass: counts of corrected and held points, held reasons, stats over all and corrected points."""
    reasons: dict[str, int] = {}
    for h in held:
        if h is not None:
            reasons[h] = reasons.get(h, 0) + 1
    return VerifyPass(stage, int(safe.sum()), int((~safe).sum()), reasons, _figures(err),
                      _figures(err[safe]) if safe.any() else None)


def _figures(err_mm: np.ndarray) -> ErrorFigures:
    return ErrorFigures.of(error_stats(err_mm))


@dataclass(frozen=True)
class VerifyResult:
    report: VerifyReport
    out_dir: Path
    exit_status: str
    reason: str


class VerifyPasses:
    """The passes of closed-loop verification, a plan the runner executes: the model-corrected pass, then up to
    ``closed_loop_iterations`` passes re-solved from the previous pass's measurements (seed 001 §4.2). Every pass
    holds a correction beyond a bound at the planned joints (``held_reasons``). With reference nests (``drift``)
    rounds of nest readings open the first pass, follow every ``every_n_points`` points and close every pass, and
    each pass's readings are moved into the calibration's tracker frame before anything is computed from them.
    ``results``: (stage, err (N, 3) mm tracker frame, safe (N,), held) per measured pass."""

    def __init__(self, cell: CellModel, T_tool: np.ndarray, ids: list[str], p_d: np.ndarray,
                 q0: np.ndarray, q: np.ndarray, R_d: np.ndarray, T_tb: np.ndarray, target_tracker: np.ndarray,
                 estimator=None, drift: VerifyDrift | None = None):
        cfg, kin = cell.config, cell.kinematics                  # the nominal model commands the joints
        self.cell, self.cfg, self.kin = cell, cfg, kin
        self.T_tool, self.ids, self.p_d, self.q0, self.q = T_tool, ids, p_d, q0, q
        self.R_d, self.T_tb, self.target_tracker = R_d, T_tb, target_tracker
        self.estimator = estimator                   # three SMRs: seed 003's 6D pose from the measured SMR 1
        self.drift = drift
        self.R_planned = fk(kin, q0)[:, :3, :3] @ T_tool[:3, :3]     # each point's planned tool orientation
        self.orientation: dict[str, np.ndarray] = {}     # stage -> tool orientation errors (arc seconds)
        self.limit = np.radians(cfg.correction.max_joint_correction_deg)
        self.lo, self.hi = np.radians(limits_deg(cfg)[0]), np.radians(limits_deg(cfg)[1])
        self.p_pseudo = (fk(kin, q) @ T_tool)[:, :3, 3]
        self.k, self.stage = 0, "model-corrected"
        self.safe, self.held = np.ones(len(ids), bool), [None] * len(ids)
        self.results: list[tuple[str, np.ndarray, np.ndarray, list[str | None]]] = []

    def first(self) -> list[PlanPoint]:
        return self._points(start=True)

    def observe(self, point: PlanPoint, record) -> None:
        """The runner's ``on_point``: a record on disk (nest readings and the points' times, for the drift)."""
        if self.drift is not None:
            self.drift.observe(record)

    def _points(self, start: bool = False) -> list[PlanPoint]:
        """This pass's commands with rounds of nest readings (``VerifyDrift.with_rounds``)."""
        points = self._commands()
        return points if self.drift is None else self.drift.with_rounds(points, start)

    def _commands(self) -> list[PlanPoint]:
        """This pass's commands: the current joints, or the planned ones where a bound holds the correction."""
        moved = np.linalg.norm((fk(self.kin, self.q) @ self.T_tool)[:, :3, 3] - self.p_d, axis=1)
        self.held = held_reasons(self.q, self.q0, self.limit, self.lo, self.hi,
                                 self.cfg.correction.max_joint_correction_deg, moved,
                                 self.cfg.correction.max_position_correction_mm)
        self.held = [h or c for h, c in zip(self.held, configuration_reasons(self.kin, self.q, self.q0))]
        self.safe = np.array([h is None for h in self.held])
        self.q = np.where(self.safe[:, None], self.q, self.q0)    # an unsafe correction is never commanded
        return [PlanPoint(f"{i}.v{self.k}", "verify", tuple(np.degrees(qq)), tuple(pd))
                for i, qq, pd in zip(self.ids, self.q, self.p_d)]

    def next(self, p_meas: np.ndarray) -> list[PlanPoint] | None:
        """Record the pass measured at ``p_meas`` (N, 3) mm tracker frame; the next pass's points, or None."""
        if self.drift is not None:
            p_meas = self.drift.pass_frame(p_meas, self.stage)       # the calibration's frame
        err = p_meas - self.target_tracker
        self.results.append((self.stage, err, self.safe, self.held))
        if self.estimator is not None:
            pose = self.estimator.estimate(self.q, p_meas).T_tracker_flange
            self.orientation[self.stage] = tool_orientation_errors_arcsec(pose, self.T_tb, self.R_planned,
                                                                          self.T_tool[:3, :3])
        if self.k == self.cfg.correction.closed_loop_iterations:
            return None
        sigma = np.sqrt(np.trace(self.cell.covariance(p_meas), axis1=1, axis2=2))
        significant = np.linalg.norm(err, axis=1) > self.cfg.correction.significance * sigma
        R_flange = self.R_d @ self.T_tool[:3, :3].T                       # each point's planned orientation
        self.q, self.p_pseudo = closed_loop_step(self.kin, self.T_tool, self.q, self.p_pseudo,
                                                 err @ self.T_tb[:3, :3], significant, R_flange)   # err in base
        self.k += 1
        self.stage = f"closed loop {self.k}"
        return self._points()


def _translation(drift: VerifyDrift, stage: str) -> tuple[float, float, float] | None:
    """The mean drift translation (mm) removed from a pass's readings, None when nothing was fitted for it."""
    removed = drift.passes.get(stage)
    return None if removed is None else tuple(removed["translation_mm"])


def verify_run(run_dir: Path, execute_passes, cell: CellModel, model: CalibratedModel,
               test_points: list[PointRecord], out_dir: Path, estimator=None,
               drift: VerifyDrift | None = None) -> VerifyResult:
    """Closed-loop verification on a run's test points. ``execute_passes(plan: VerifyPasses) -> RunOutcome``
    drives the robot through the plan's passes and measures (durably logged by the caller). The tool point is
    the model's SMR (its identified offset). With a three-SMR ``estimator`` (``multi_smr.pose_estimator``) every
    pass also reports the tool orientation error against each point's planned orientation (nominal model at the
    planned joints): measured from the three SMRs of the run before correction, estimated from SMR 1 + the two
    predicted SMRs (seed 003) after. With reference nests (``drift``, :mod:`campaign.correct.verify_drift`) every
    measurement, the run's included, is compared in the calibration's tracker frame."""
    kin = cell.kinematics
    T_tool = tool_transform(model.kinematics.p_flange_smr_mm)
    ids = [p.point_id for p in test_points]
    p_d = np.array([p.p_target_base_mm for p in test_points], float)
    q0 = np.radians([p.q_cmd_deg for p in test_points])
    T_tb = model.kinematics.T_tracker_base
    target_tracker = transform_points(T_tb, p_d)
    p_run = np.array([p.p_tracker_mm for p in test_points], float) if drift is None else \
        drift.run_frame(test_points, UNCORRECTED)
    before = p_run - target_tracker
    floor = float(np.sqrt(np.mean(np.trace(cell.covariance(target_tracker), axis1=1, axis2=2))))
    rows = {UNCORRECTED: _figures(before)}
    passes = [VerifyPass(UNCORRECTED, 0, len(ids), {}, rows[UNCORRECTED], None)]
    R_d = fk(kin, q0)[:, :3, :3] @ T_tool[:3, :3]        # an arm of < 6 axes turns its tool with it (the plan)
    if kin.n - kin.n_track >= 6:                          # the plan's one fixed orientation
        R_d = np.broadcast_to(R_d[0], (len(ids), 3, 3))
    T_d = np.zeros((len(ids), 4, 4))
    T_d[:, :3, :3], T_d[:, :3, 3], T_d[:, 3, 3] = R_d, p_d, 1.0
    c = run_correction(cell, model_pose_fn(model, T_tool), T_d, q0, T_tool)
    plan = VerifyPasses(cell, T_tool, ids, p_d, q0, c.q_rad, R_d, T_tb, target_tracker, estimator, drift)
    if estimator is not None:
        poses = measured_flange_poses(estimator.tool.p_flange_mm, test_points)
        if poses is not None:
            passes[0] = replace(passes[0], orientation_error_arcsec=angle_stats(tool_orientation_errors_arcsec(
                poses, T_tb, plan.R_planned, T_tool[:3, :3]), "measured: the three SMRs of the run"))
    outcome = execute_passes(plan)
    status, reason, safe = outcome.exit_status, outcome.reason, plan.safe
    corrected, corrected_only = [], []                    # every measurement; those of corrected points
    for stage, err, safe_k, held in plan.results:
        rows[stage] = _figures(err)
        passes.append(pass_summary(stage, err, safe_k, held))
        if stage in plan.orientation:
            passes[-1] = replace(passes[-1], orientation_error_arcsec=angle_stats(
                plan.orientation[stage], "estimated (seed 003): SMR 1 measured, SMRs 2-3 predicted, adjusted"))
        corrected.append(err)
        corrected_only.append(err[safe_k])
    if drift is not None:
        passes = [replace(p, drift_translation_mm=_translation(drift, p.stage)) for p in passes]
    if corrected:
        pooled = np.concatenate(corrected_only)
        rows[POOLED] = _figures(np.concatenate(corrected))
        passes.append(VerifyPass(POOLED, int(len(pooled)), int(sum(len(e) for e in corrected) - len(pooled)), {},
                                 rows[POOLED], _figures(pooled) if len(pooled) else None))
    report = VerifyReport(
        VERIFY_FORMAT, str(run_dir), len(ids), floor, int(np.sum(~safe)) if corrected else None,
        rows, tuple(passes), status, reason,
        definitions={UNCORRECTED: "the test points commanded at their planned (nominal-IK) joints, "
                                  "measured against the targets through the calibrated registration",
                     "held": "points commanded at their planned joints in a corrected pass because the "
                             "correction would exceed a bound (reason per point count)",
                     "corrected": "figures over the points whose correction was commanded"}
        | ({"drift_translation_mm": "the tracker drift removed from the pass's readings (mean translation over its "
                                    "points, mm, tracker frame) to refer them to the calibration's frame"}
           if drift is not None and drift.active else {}),
        created_utc=datetime.now(timezone.utc).isoformat(), drift=None if drift is None else drift.section())
    out_dir.mkdir(parents=True, exist_ok=True)
    write_json(out_dir / "verify.json", report.to_dict())
    return VerifyResult(report, out_dir, status, reason)
