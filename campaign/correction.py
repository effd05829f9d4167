"""Target correction with a calibrated model (seed 001), write-back files, and closed-loop verification.

``correct_targets``: Cartesian targets (base frame) -> nominal IK on the plan's configuration -> pseudo-target
iteration with AP = the calibrated model -> bounds (joint limits, maximum correction) -> write-back files.
``verify_run``: drive the robot to the corrected test points of a run, measure, and iterate with the measured
position (seed 001 §4.2) where the measured error is significant; report before / after like seed 000 Table 3.
"""
from __future__ import annotations

import csv
import warnings
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from robocal.correct import Correction, closed_loop_step, correct, matrix_to_quat, tool_transform
from robocal.frames import transform_points
from robocal.ik import branch_signature, solve_on_branch
from robocal.kinematics import fk
from robocal.model import CalibratedModel
from robocal.stats import error_stats

from .cell import measurement_covariance, nominal_kinematics
from .csv_cells import restore
from .config import CampaignConfig
from .errors import DataError
from .plan import PlanPoint
from .records import PointRecord, VerifyReport
from .fsutil import write_json
from .multi_smr import angle_stats, measured_flange_poses, tool_orientation_errors_arcsec
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
        with open(path, newline="", encoding="utf-8-sig") as fh:
            rows = list(csv.reader(fh))
    except OSError as exc:
        raise DataError(src, f"cannot read: {exc.strerror or exc}") from None
    except (UnicodeDecodeError, csv.Error) as exc:
        raise DataError(src, f"not a readable CSV text file ({exc})") from None
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
        return smallest_converged(ensemble_generators(c.error), q_start, c.threshold_mm,
                                  lambda g: correct(T_target, q_start, ap, kin, T_tool, generator=g, **kw))
    return correct(T_target, q_start, ap, kin, T_tool, generator=c.generator, **kw)


def smallest_converged(generators, q_start: np.ndarray, threshold: float, run) -> Correction:
    """Seed 001 §3 ensemble with a safety-minded tie-break: per target, among the generators that reached the
    threshold the one with the smallest joint change (the bound is on joint changes), else the smallest error."""
    results = [run(g) for g in generators]
    errors = np.stack([r.error for r in results])                                   # (G, N)
    change = np.stack([np.max(np.abs(r.q_rad - q_start), axis=1) for r in results])  # (G, N) rad
    converged = errors < threshold
    key = np.where(converged, change, np.inf)
    best = np.where(converged.any(axis=0), np.argmin(key, axis=0), np.argmin(errors, axis=0))
    cols = np.arange(errors.shape[1])
    pick = lambda attr: np.stack([getattr(r, attr) for r in results])[best, cols]  # noqa: E731
    return Correction(pick("q_rad"), pick("pos_err_mm"), pick("rot_err_rad"), pick("error"), pick("iterations"),
                      np.array([generators[b] for b in best], dtype=object))


def ensemble_generators(error: str) -> tuple[str, ...]:
    """Generators of the ensemble. With a position-only error the tool orientation is neither measured nor
    judged, so ``fixed`` (eq. 15: keep the target orientation, update the position) comes first and wins ties:
    the other generators also chase the model's orientation error, which near the wrist singularity turns into
    large J4/J6 changes that the correction bound then rejects (issue 12: 18/50 and 55/94 points held)."""
    return (("fixed",) + ENSEMBLE) if error == "position" else ENSEMBLE


def abb_confdata(kin, q_rad: np.ndarray) -> np.ndarray:
    """(N, 4) ABB confdata [cf1, cf4, cf6, cfx]: quadrants of axes 1, 4, 6 and cfx from the branch
    (shoulder: wrist centre in front of axis 1, elbow, sign of axis 5) as in ABB's confdata table."""
    quad = np.floor(np.degrees(q_rad[:, [0, 3, 5]]) / 90.0).astype(int)
    sig = branch_signature(kin, q_rad)
    cfx = 4 * (sig[:, 0] < 0) + 2 * (sig[:, 1] < 0) + (q_rad[:, 4] < 0)
    return np.column_stack([quad, cfx]).astype(int)


class AbsAccRobot(DataError):
    """The measured robot runs ABB Absolute Accuracy: corrected Cartesian targets would be corrected twice."""


def absacc_guard(identity: dict | None, *, allow: bool = False, where: str = "model") -> str | None:
    """Refuse (``AbsAccRobot``, exit 2) or, with ``allow``, warn when the controller identity recorded for the run
    (``absacc: yes``, read by the ABB driver from the controller's options) says Absolute Accuracy is active. The
    controller applies its own compensation to every Cartesian target, so robtargets corrected here would be
    corrected twice; joint targets (``MoveAbsJ``) are not affected. Returns the warning text, or None."""
    if not identity or str(identity.get("absacc", "")).strip().lower() not in ("yes", "true", "1", "on"):
        return None
    robot = f"{identity.get('model', 'robot')} (serial {identity.get('serial', '?')})"
    message = (f"{robot} has ABB Absolute Accuracy active: the controller compensates Cartesian targets itself, so "
               "targets corrected with this model would be corrected twice")
    if not allow:
        raise AbsAccRobot(where, message + "; deactivate AbsAcc for the corrected program or use the joint targets")
    warnings.warn(message + "; use the joint targets (MoveAbsJ) only", stacklevel=2)
    return message


def recorded_identity(model: CalibratedModel, model_path: str | Path | None = None) -> dict | None:
    """The robot identity recorded for a model: ``model.meta["robot_identity"]``, else the start record of the run
    log beside ``model_path`` (``robot_identity`` or ``identity``); None when nothing was recorded."""
    meta = model.meta or {}
    if isinstance(meta.get("robot_identity"), dict):
        return meta["robot_identity"]
    if model_path is None:
        return None
    log_path = Path(model_path).parent / "log.jsonl"
    try:
        from .runlog import read_log
        start = read_log(log_path).start or {}
    except Exception:                                # noqa: BLE001 - no readable log: nothing recorded
        return None
    found = start.get("robot_identity") or start.get("identity")
    return found if isinstance(found, dict) else None


def correct_targets(cfg: CampaignConfig, model: CalibratedModel, targets: Targets,
                    T_tool: np.ndarray | None = None, *, robot_identity: dict | None = None,
                    allow_absacc: bool = False) -> tuple[list[CorrectedTarget], list[Rejected]]:
    """Corrected joints for Cartesian targets; out-of-bound or unreachable ones are rejected with a reason.
    The tool point (default ``T_tool``) is the model's SMR at its identified offset. An Absolute Accuracy robot
    (``robot_identity``, default: ``model.meta``) is refused unless ``allow_absacc``."""
    absacc_guard(robot_identity if robot_identity is not None else recorded_identity(model), allow=allow_absacc)
    kin = nominal_kinematics(cfg)
    T_tool = tool_transform(model.kinematics.p_flange_smr_mm) if T_tool is None else T_tool   # the identified SMR
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


FORMATS = {"rapid": ("CalTargets.mod",), "ur": ("targets_ur.json", "targets_ur.script"), "csv": ("targets.csv",)}


def controller_formats(cfg: CampaignConfig) -> tuple[str, ...]:
    """Write-back formats that fit the configured controller: the robot url's driver, else the robot model's
    vendor (a mock cell of an ABB or UR arm); the CSV always."""
    import re

    scheme = cfg.robot.url.split("://", 1)[0]
    model = cfg.robot.model.lower()
    if scheme == "abb-rws" or (scheme == "mock" and ("abb" in model or re.search(r"\birb", model))):
        return ("rapid", "csv")
    if scheme == "ur-rtde" or (scheme == "mock" and ("universal robots" in model or re.match(r"ur\d", model))):
        return ("ur", "csv")
    return ("csv",)


def _format_rejections(accepted, formats) -> tuple[list, list[Rejected]]:
    """Targets a chosen format cannot hold (RAPID: ids over 80 characters or not ISO 8859-1) -> rejected."""
    if "rapid" not in formats:
        return list(accepted), []
    from drivers.rapid.literals import _rapid_string

    ok, bad = [], []
    for t in accepted:
        try:
            _rapid_string(t.target_id)
            ok.append(t)
        except ValueError as exc:
            bad.append(Rejected(t.target_id, f"cannot be written to RAPID: {' '.join(str(exc).split())}"))
    return ok, bad


def write_corrected(cfg: CampaignConfig, accepted, rejected, out_dir: str | Path,
                    formats: tuple[str, ...] | None = None) -> list[Path]:
    """The write-back files of ``formats`` (default: those of the configured controller, see
    ``controller_formats``) and ``rejected.csv``. Every file is rendered in memory first, so a target no format
    can hold writes nothing; ``CampaignError`` when no target is left to write (rejected.csv is still written)."""
    from .errors import CampaignError
    from .fsutil import atomic_write
    from .writeback import render_rapid_module, render_targets_csv, render_ur_json, render_urscript

    formats = controller_formats(cfg) if not formats else tuple(formats)
    accepted, unfit = _format_rejections(accepted, formats)
    rejected = list(rejected) + unfit
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    lo, hi = _limits_deg(cfg)
    limits = dict(q_min_deg=lo, q_max_deg=hi)
    rejected_path = write_rejected_csv(out / "rejected.csv", rejected)
    if not accepted:
        first = f"; first reason: {rejected[0].target_id}: {rejected[0].reason}" if rejected else ""
        raise CampaignError(f"{out}: nothing to write: all {len(rejected)} targets rejected (reasons in "
                            f"{rejected_path}){first}")
    renderers = {"CalTargets.mod": render_rapid_module, "targets_ur.json": render_ur_json,
                 "targets_ur.script": render_urscript, "targets.csv": render_targets_csv}
    texts = {}
    for fmt in formats:
        for name in FORMATS[fmt]:
            try:
                texts[name] = renderers[name](accepted, **limits)
            except ValueError as exc:
                raise CampaignError(f"{out / name}: not written: {' '.join(str(exc).split())}") from None
    paths = [atomic_write(out / name, text.encode("utf-8")) for name, text in texts.items()]
    return paths + [rejected_path]


# ---------------------------------------------------------------- closed-loop verification
UNCORRECTED = "uncorrected (planned joints)"
POOLED = "after correction (all passes pooled)"


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


def pass_summary(stage: str, err: np.ndarray, safe: np.ndarray, held: list[str | None]) -> dict:
    """One verify pass: counts of corrected and held points, held reasons, stats over all and corrected points."""
    reasons: dict[str, int] = {}
    for h in held:
        if h is not None:
            reasons[h] = reasons.get(h, 0) + 1
    return {"stage": stage, "n_corrected": int(safe.sum()), "n_held": int((~safe).sum()), "held": reasons,
            "all": error_stats(err).to_dict(), "corrected": error_stats(err[safe]).to_dict() if safe.any() else None}




@dataclass(frozen=True)
class VerifyResult:
    report: VerifyReport
    out_dir: Path
    exit_status: str
    reason: str


class VerifyPasses:
    """The passes of closed-loop verification, a plan the runner executes: the model-corrected pass, then up to
    ``closed_loop_iterations`` passes re-solved from the previous pass's measurements (seed 001 §4.2). Every pass
    holds a correction beyond a bound at the planned joints (``held_reasons``). ``results``: (stage, err (N, 3)
    mm tracker frame, safe (N,), held) per measured pass."""

    def __init__(self, cfg: CampaignConfig, kin, T_tool: np.ndarray, ids: list[str], p_d: np.ndarray,
                 q0: np.ndarray, q: np.ndarray, R_d: np.ndarray, T_tb: np.ndarray, target_tracker: np.ndarray,
                 estimator=None):
        self.cfg, self.kin, self.T_tool, self.ids, self.p_d, self.q0, self.q = cfg, kin, T_tool, ids, p_d, q0, q
        self.R_d, self.T_tb, self.target_tracker = R_d, T_tb, target_tracker
        self.estimator = estimator                   # three SMRs: seed 003's 6D pose from the measured SMR 1
        self.R_planned = fk(kin, q0)[:, :3, :3] @ T_tool[:3, :3]     # each point's planned tool orientation
        self.orientation: dict[str, np.ndarray] = {}     # stage -> tool orientation errors (arc seconds)
        self.limit = np.radians(cfg.correction.max_joint_correction_deg)
        self.lo, self.hi = np.radians(_limits_deg(cfg)[0]), np.radians(_limits_deg(cfg)[1])
        self.p_pseudo = (fk(kin, q) @ T_tool)[:, :3, 3]
        self.k, self.stage = 0, "model-corrected"
        self.safe, self.held = np.ones(len(ids), bool), [None] * len(ids)
        self.results: list[tuple[str, np.ndarray, np.ndarray, list[str | None]]] = []

    def first(self) -> list[PlanPoint]:
        return self._points()

    def _points(self) -> list[PlanPoint]:
        """This pass's commands: the current joints, or the planned ones where a bound holds the correction."""
        moved = np.linalg.norm((fk(self.kin, self.q) @ self.T_tool)[:, :3, 3] - self.p_d, axis=1)
        self.held = held_reasons(self.q, self.q0, self.limit, self.lo, self.hi,
                                 self.cfg.correction.max_joint_correction_deg, moved,
                                 self.cfg.correction.max_position_correction_mm)
        self.safe = np.array([h is None for h in self.held])
        self.q = np.where(self.safe[:, None], self.q, self.q0)    # an unsafe correction is never commanded
        return [PlanPoint(f"{i}.v{self.k}", "verify", tuple(np.degrees(qq)), tuple(pd))
                for i, qq, pd in zip(self.ids, self.q, self.p_d)]

    def next(self, p_meas: np.ndarray) -> list[PlanPoint] | None:
        """Record the pass measured at ``p_meas`` (N, 3) mm tracker frame; the next pass's points, or None."""
        err = p_meas - self.target_tracker
        self.results.append((self.stage, err, self.safe, self.held))
        if self.estimator is not None:
            pose = self.estimator.estimate(self.q, p_meas).T_tracker_flange
            self.orientation[self.stage] = tool_orientation_errors_arcsec(pose, self.T_tb, self.R_planned,
                                                                          self.T_tool[:3, :3])
        if self.k == self.cfg.correction.closed_loop_iterations:
            return None
        sigma = np.sqrt(np.trace(measurement_covariance(self.cfg, p_meas), axis1=1, axis2=2))
        significant = np.linalg.norm(err, axis=1) > self.cfg.correction.significance * sigma
        R_flange = np.broadcast_to(self.R_d[0] @ self.T_tool[:3, :3].T, (len(self.ids), 3, 3))
        self.q, self.p_pseudo = closed_loop_step(self.kin, self.T_tool, self.q, self.p_pseudo,
                                                 err @ self.T_tb[:3, :3], significant, R_flange)   # err in base
        self.k += 1
        self.stage = f"closed loop {self.k}"
        return self._points()


def verify_run(run_dir: Path, execute_passes, cfg: CampaignConfig, model: CalibratedModel,
               test_points: list[PointRecord], out_dir: Path, estimator=None) -> VerifyResult:
    """Closed-loop verification on a run's test points. ``execute_passes(plan: VerifyPasses) -> RunOutcome``
    drives the robot through the plan's passes and measures (durably logged by the caller). The tool point is
    the model's SMR (its identified offset). With a three-SMR ``estimator`` (``multi_smr.pose_estimator``) every
    pass also reports the tool orientation error against each point's planned orientation (nominal model at the
    planned joints): measured from the three SMRs of the run before correction, estimated from SMR 1 + the two
    predicted SMRs (seed 003) after."""
    kin = nominal_kinematics(cfg)
    T_tool = tool_transform(model.kinematics.p_flange_smr_mm)
    ids = [p.point_id for p in test_points]
    p_d = np.array([p.p_target_base_mm for p in test_points], float)
    q0 = np.radians([p.q_cmd_deg for p in test_points])
    T_tb = model.kinematics.T_tracker_base
    target_tracker = transform_points(T_tb, p_d)
    before = np.array([p.p_tracker_mm for p in test_points]) - target_tracker
    floor = float(np.sqrt(np.mean(np.trace(measurement_covariance(cfg, target_tracker), axis1=1, axis2=2))))
    rows = {UNCORRECTED: error_stats(before).to_dict()}
    passes = [{"stage": UNCORRECTED, "n_corrected": 0, "n_held": len(ids), "held": {},
               "all": rows[UNCORRECTED], "corrected": None}]
    R_d = np.broadcast_to(fk(kin, q0[:1])[0, :3, :3] @ T_tool[:3, :3], (len(ids), 3, 3))
    T_d = np.zeros((len(ids), 4, 4))
    T_d[:, :3, :3], T_d[:, :3, 3], T_d[:, 3, 3] = R_d, p_d, 1.0
    c = run_correction(cfg, model_pose_fn(model, T_tool), T_d, q0, T_tool)
    plan = VerifyPasses(cfg, kin, T_tool, ids, p_d, q0, c.q_rad, R_d, T_tb, target_tracker, estimator)
    if estimator is not None:
        poses = measured_flange_poses(estimator.tool.p_flange_mm, test_points)
        if poses is not None:
            passes[0]["orientation_error_arcsec"] = angle_stats(tool_orientation_errors_arcsec(
                poses, T_tb, plan.R_planned, T_tool[:3, :3]), "measured: the three SMRs of the run")
    outcome = execute_passes(plan)
    status, reason, safe = outcome.exit_status, outcome.reason, plan.safe
    corrected, corrected_only = [], []                    # every measurement; those of corrected points
    for stage, err, safe_k, held in plan.results:
        rows[stage] = error_stats(err).to_dict()
        passes.append(pass_summary(stage, err, safe_k, held))
        if stage in plan.orientation:
            passes[-1]["orientation_error_arcsec"] = angle_stats(plan.orientation[stage], "estimated (seed 003): "
                                                                 "SMR 1 measured, SMRs 2-3 predicted, adjusted")
        corrected.append(err)
        corrected_only.append(err[safe_k])
    if corrected:
        pooled = np.concatenate(corrected_only)
        rows[POOLED] = error_stats(np.concatenate(corrected)).to_dict()
        passes.append({"stage": POOLED, "n_corrected": int(len(pooled)),
                       "n_held": int(sum(len(e) for e in corrected) - len(pooled)), "held": {},
                       "all": rows[POOLED], "corrected": error_stats(pooled).to_dict() if len(pooled) else None})
    report = VerifyReport(
        "campaign-verify/2", str(run_dir), len(ids), floor, int(np.sum(~safe)) if corrected else None,
        rows, passes, status, reason,
        definitions={UNCORRECTED: "the test points commanded at their planned (nominal-IK) joints, "
                                  "measured against the targets through the calibrated registration",
                     "held": "points commanded at their planned joints in a corrected pass because the "
                             "correction would exceed a bound (reason per point count)",
                     "corrected": "figures over the points whose correction was commanded"},
        created_utc=datetime.now(timezone.utc).isoformat())
    out_dir.mkdir(parents=True, exist_ok=True)
    write_json(out_dir / "verify.json", report.to_dict())
    return VerifyResult(report, out_dir, status, reason)


def read_rejected(out_dir: str | Path) -> list[tuple[str, str]]:
    """(target_id, reason) rows of OUT_DIR/rejected.csv (empty when the file is absent)."""
    try:
        with open(Path(out_dir) / "rejected.csv", newline="", encoding="utf-8") as fh:
            return [(restore(row[0]), restore(row[1]) if len(row) > 1 else "") for row in list(csv.reader(fh))[1:]
                    if row]
    except OSError:
        return []


def check_model_fits(cfg: CampaignConfig, model: CalibratedModel, source: str) -> None:
    """The model must describe the config's robot: same joint count and convention (DataError otherwise)."""
    kin, n = model.kinematics, len(cfg.robot.joints)
    if kin.n != n:
        raise DataError(source, f"the model has {kin.n} joints but the config's robot has {n}: not a model of this robot")
    if kin.convention != cfg.robot.convention:
        raise DataError(source, f"the model uses {kin.convention!r} parameters but the config {cfg.robot.convention!r}: "
                                "not a model of this robot")
    from .plausibility import Plausibility, check_deltas

    check_deltas(nominal_kinematics(cfg), kin, source, Plausibility())   # a model of another robot: exit 2
