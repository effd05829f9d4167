"""Target correction with a calibrated model (seed 001), write-back files, and closed-loop verification.

``correct_targets``: Cartesian targets (base frame) -> nominal IK on the plan's configuration -> pseudo-target
iteration with AP = the calibrated model -> bounds (joint limits, maximum correction) -> write-back files.
``verify_run``: drive the robot to the corrected test points of a run, measure, and iterate with the measured
position (seed 001 §4.2) where the measured error is significant; report before / after like seed 000 Table 3.
"""
from __future__ import annotations

import csv
import json
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from robocal.correct import Correction, correct, correct_ensemble, matrix_to_quat, tool_transform
from robocal.frames import transform_points
from robocal.ik import branch_signature, solve_ik, solve_on_branch
from robocal.kinematics import fk
from robocal.model import CalibratedModel
from robocal.stats import error_stats

from .cell import measurement_covariance, nominal_kinematics
from .config import CampaignConfig
from .errors import DataError
from .plan import PlanPoint
from .writeback import (CorrectedTarget, Rejected, check_targets, write_rapid_module, write_rejected_csv,
                        write_targets_csv, write_ur_json, write_urscript)

ENSEMBLE = ("multiply", "quaternion")


@dataclass(frozen=True)
class Targets:
    """Cartesian targets in the robot base frame: ids, positions (N, 3) mm, orientations (N, 3, 3)."""
    ids: tuple[str, ...]
    p_base_mm: np.ndarray
    R_base: np.ndarray


def read_targets_csv(path: str | Path, default_R: np.ndarray) -> Targets:
    """``target_id,x,y,z[,qw,qx,qy,qz]`` (mm, base frame; unit quaternion w-first). Without a quaternion
    the plan's fixed SMR orientation is used. Errors name the file, line and column."""
    src = str(path)
    try:
        rows = list(csv.reader(open(path, newline="", encoding="utf-8-sig")))
    except OSError as exc:
        raise DataError(src, f"cannot read: {exc.strerror or exc}") from None
    rows = [(i + 1, r) for i, r in enumerate(rows) if r and not r[0].lstrip().startswith("#")]
    if not rows:
        raise DataError(src, "empty file")
    header = [h.strip().lower() for h in rows[0][1]]
    need, quat = ["target_id", "x", "y", "z"], ["qw", "qx", "qy", "qz"]
    if header[:4] != need or header[4:] not in ([], quat):
        raise DataError(src, f"header must be {','.join(need)}[,{','.join(quat)}], got {','.join(header)}", line=rows[0][0])
    ids, values = [], []
    for line, r in rows[1:]:
        if len(r) != len(header):
            raise DataError(src, f"expected {len(header)} fields, got {len(r)}", line=line)
        try:
            v = [float(x) for x in r[1:]]
        except ValueError:
            col = next(h for h, x in zip(header[1:], r[1:]) if not _is_float(x))
            raise DataError(src, f"expected a number, got {r[header.index(col)]!r}", line=line, column=f"'{col}'") from None
        if not np.all(np.isfinite(v)):
            raise DataError(src, "non-finite value", line=line)
        if r[0].strip() in ids:
            raise DataError(src, f"duplicate target_id {r[0].strip()!r}", line=line)
        ids.append(r[0].strip())
        values.append(v)
    if not ids:
        raise DataError(src, "no targets")
    v = np.array(values)
    if v.shape[1] == 7:
        q = v[:, 3:]
        norm = np.linalg.norm(q, axis=1)
        if np.any(np.abs(norm - 1) > 1e-3):
            bad = int(np.argmax(np.abs(norm - 1)))
            raise DataError(src, f"quaternion of {ids[bad]!r} is not unit (norm {norm[bad]:.4f})")
        from robocal.correct import quat_to_matrix
        R = quat_to_matrix(q)
    else:
        R = np.broadcast_to(default_R, (len(ids), 3, 3)).copy()
    return Targets(tuple(ids), v[:, :3], R)


def _is_float(x: str) -> bool:
    try:
        float(x)
        return True
    except ValueError:
        return False


def model_pose_fn(model: CalibratedModel, T_flange_tool: np.ndarray):
    """AP(q): calibrated tool pose in the base frame (kinematic layer + the residual layer's position)."""
    def ap(q):
        T = model.flange_pose(q) @ T_flange_tool
        if model.residual is not None:
            T[:, :3, 3] += model.residual_base(q, T[:, :3, 3])
        return T
    return ap


def run_correction(cfg: CampaignConfig, ap, T_target: np.ndarray, q_start: np.ndarray, T_tool: np.ndarray) -> Correction:
    c, kin = cfg.correction, nominal_kinematics(cfg)
    kw = dict(error=c.error, threshold=c.threshold_mm, max_iter=c.max_iterations)
    if c.generator == "ensemble":
        return correct_ensemble(T_target, q_start, ap, kin, T_tool, generators=ENSEMBLE, **kw)
    return correct(T_target, q_start, ap, kin, T_tool, generator=c.generator, **kw)


def abb_confdata(kin, q_rad: np.ndarray) -> np.ndarray:
    """(N, 4) ABB confdata [cf1, cf4, cf6, cfx]: quadrants of axes 1, 4, 6 and cfx from the branch
    (shoulder: wrist centre in front of axis 1, elbow, sign of axis 5) as in ABB's confdata table."""
    quad = np.floor(np.degrees(q_rad[:, [0, 3, 5]]) / 90.0).astype(int)
    sig = branch_signature(kin, q_rad)
    cfx = 4 * (sig[:, 0] < 0) + 2 * (sig[:, 1] < 0) + (q_rad[:, 4] < 0)
    return np.column_stack([quad, cfx]).astype(int)


def correct_targets(cfg: CampaignConfig, model: CalibratedModel, targets: Targets,
                    T_tool: np.ndarray | None = None) -> tuple[list[CorrectedTarget], list[Rejected]]:
    """Corrected joints for Cartesian targets; out-of-bound or unreachable ones are rejected with a reason."""
    kin = nominal_kinematics(cfg)
    T_tool = tool_transform(cfg.tool.p_flange_smr_mm) if T_tool is None else T_tool
    R_flange = targets.R_base @ T_tool[:3, :3].T
    q_nom, ok = solve_on_branch(kin, targets.p_base_mm, R_flange, np.radians(cfg.plan.q_ref_deg),
                                point_mm=T_tool[:3, 3])
    rejected = [Rejected(targets.ids[i], "unreachable on the plan's robot configuration with the nominal model")
                for i in np.flatnonzero(~ok)]
    idx = np.flatnonzero(ok)
    accepted: list[CorrectedTarget] = []
    if len(idx):
        T_d = np.zeros((len(idx), 4, 4))
        T_d[:, :3, :3], T_d[:, :3, 3], T_d[:, 3, 3] = targets.R_base[idx], targets.p_base_mm[idx], 1.0
        c = run_correction(cfg, model_pose_fn(model, T_tool), T_d, q_nom[idx], T_tool)
        cmd = fk(kin, c.q_rad) @ T_tool
        conf = abb_confdata(kin, c.q_rad)
        std = predictive_std_mm(model, c.q_rad)
        for j, i in enumerate(idx):
            accepted.append(CorrectedTarget(
                target_id=targets.ids[i], q_nominal_deg=tuple(np.degrees(q_nom[i])),
                q_corrected_deg=tuple(np.degrees(c.q_rad[j])), p_command_base_mm=tuple(cmd[j, :3, 3]),
                quat_command_wxyz=tuple(matrix_to_quat(cmd[j:j + 1, :3, :3])[0]), confdata=tuple(int(v) for v in conf[j]),
                predicted_residual_mm=float(c.pos_err_mm[j]),
                predicted_rot_err_deg=float(np.degrees(c.rot_err_rad[j])), predicted_std_mm=float(std[j])))
    lim = _limits_deg(cfg)
    ok_targets, bad = check_targets(accepted, *lim, cfg.correction.max_joint_correction_deg,
                                    cfg.correction.max_position_correction_mm,
                                    {t: tuple(p) for t, p in zip(targets.ids, targets.p_base_mm)})
    return ok_targets, rejected + bad


def predictive_std_mm(model: CalibratedModel, q_rad: np.ndarray) -> np.ndarray:
    """3-D predictive standard deviation (N,) mm of the residual layer at q (GPR), nan without one."""
    fn = getattr(model.residual, "predict_std", None)
    if fn is None:
        return np.full(len(q_rad), np.nan)
    return np.linalg.norm(fn(q_rad, None, include_noise=False), axis=1)


def _limits_deg(cfg: CampaignConfig):
    return [j.q_min_deg for j in cfg.robot.joints], [j.q_max_deg for j in cfg.robot.joints]


def write_corrected(cfg: CampaignConfig, accepted, rejected, out_dir: str | Path) -> list[Path]:
    """Every write-back form: RAPID module, UR JSON + URScript, CSV; rejected targets in their own CSV."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    lo, hi = _limits_deg(cfg)
    paths = [out / "CalTargets.mod", out / "targets_ur.json", out / "targets_ur.script", out / "targets.csv",
             out / "rejected.csv"]
    limits = dict(q_min_deg=lo, q_max_deg=hi)
    write_rapid_module(paths[0], accepted, **limits)
    write_ur_json(paths[1], accepted, **limits)
    write_urscript(paths[2], accepted, **limits)
    write_targets_csv(paths[3], accepted, **limits)
    write_rejected_csv(paths[4], rejected)
    return paths


# ---------------------------------------------------------------- closed-loop verification
@dataclass(frozen=True)
class VerifyResult:
    report: dict
    out_dir: Path
    exit_status: str
    reason: str


def verify_run(run_dir: Path, measure_fn, cfg: CampaignConfig, model: CalibratedModel, test_points: list[dict],
               out_dir: Path) -> VerifyResult:
    """Closed-loop verification on a run's test points. ``measure_fn(points: list[PlanPoint]) ->
    (p_tracker_mm (N, 3), status, reason)`` drives the robot and measures (durably logged by the caller)."""
    kin = nominal_kinematics(cfg)
    T_tool = tool_transform(cfg.tool.p_flange_smr_mm)
    ids = [p["point_id"] for p in test_points]
    p_d = np.array([p["p_target_base_mm"] for p in test_points], float)
    q0 = np.radians([p["q_cmd_deg"] for p in test_points])
    T_tb = model.kinematics.T_tracker_base
    target_tracker = transform_points(T_tb, p_d)
    before = np.array([p["p_tracker_mm"] for p in test_points]) - target_tracker
    floor = float(np.sqrt(np.mean(np.trace(measurement_covariance(cfg, target_tracker), axis1=1, axis2=2))))
    rows = {"nominal (no correction)": error_stats(before).to_dict()}
    R_d = np.broadcast_to(fk(kin, q0[:1])[0, :3, :3] @ T_tool[:3, :3], (len(ids), 3, 3))
    T_d = np.zeros((len(ids), 4, 4))
    T_d[:, :3, :3], T_d[:, :3, 3], T_d[:, 3, 3] = R_d, p_d, 1.0
    c = run_correction(cfg, model_pose_fn(model, T_tool), T_d, q0, T_tool)
    q = c.q_rad
    limit = np.radians(cfg.correction.max_joint_correction_deg)
    lo, hi = np.radians(_limits_deg(cfg)[0]), np.radians(_limits_deg(cfg)[1])
    p_pseudo = (fk(kin, q) @ T_tool)[:, :3, 3]
    stage, status, reason = "model-corrected", "success", ""
    corrected = []                                        # every measurement of the corrected points
    for k in range(cfg.correction.closed_loop_iterations + 1):
        safe = np.all((np.abs(q - q0) <= limit) & (q >= lo) & (q <= hi), axis=1)
        q = np.where(safe[:, None], q, q0)                # an unsafe correction is never commanded
        points = [PlanPoint(f"{i}.v{k}", "verify", tuple(np.degrees(qq)), tuple(pd)) for i, qq, pd in zip(ids, q, p_d)]
        p_meas, status, reason = measure_fn(points)
        if status != "success":
            break
        err = p_meas - target_tracker
        rows[stage] = error_stats(err).to_dict()
        corrected.append(err)
        if k == cfg.correction.closed_loop_iterations:
            break
        sigma = np.sqrt(np.trace(measurement_covariance(cfg, p_meas), axis1=1, axis2=2))
        significant = np.linalg.norm(err, axis=1) > cfg.correction.significance * sigma
        err_base = err @ T_tb[:3, :3]                     # rotate into the base frame
        p_pseudo = np.where(significant[:, None], p_pseudo - err_base, p_pseudo)
        R_flange = np.broadcast_to(R_d[0] @ T_tool[:3, :3].T, (len(ids), 3, 3))
        q = np.where(significant[:, None],
                     solve_ik(kin, p_pseudo, R_flange, q, point_mm=T_tool[:3, 3]).q_rad, q)
        stage = f"closed loop {k + 1}"
    if corrected:
        rows["after correction (all passes pooled)"] = error_stats(np.concatenate(corrected)).to_dict()
    report = {"format": "campaign-verify/1", "run": str(run_dir), "n": len(ids), "noise_floor_mm": floor,
              "n_uncorrected": int(np.sum(~safe)) if corrected else None,
              "stages": rows, "exit_status": status, "reason": reason,
              "created_utc": datetime.now(timezone.utc).isoformat()}
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "verify.json").write_text(json.dumps(report, indent=1))
    return VerifyResult(report, out_dir, status, reason)
