"""Target correction with a calibrated model (seed 001), write-back files, and closed-loop verification.

``correct_targets``: Cartesian targets (base frame) -> nominal IK on the plan's configuration -> pseudo-target
iteration with AP = the calibrated model -> bounds (joint limits, maximum correction) -> write-back files.
``verify_run``: drive the robot to the corrected test points of a run, measure, and iterate with the measured
position (seed 001 §4.2) where the measured error is significant; report before / after like seed 000 Table 3.
"""
from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path
import warnings

import numpy as np

from campaign.config.cell_model import CellModel
from campaign.config.schema import CampaignConfig
from campaign.errors import DataError
from campaign.plan.poses import unreachable_reasons
from robocal.correct import Correction, correct, matrix_to_quat, tool_transform
from robocal.kinematics.chains import arm_angle_rad, branch_signs, redundant
from robocal.kinematics.ik import branch_signature, solve_on_branch
from robocal.kinematics.models import fk
from robocal.layers.calibrated_model import CalibratedModel

from .accuracy import HeldOut, predicted_errors_mm, rotation_errors_deg
from .bounds import CorrectedTarget, Rejected, check_targets
from .configuration import configuration_reasons


ENSEMBLE = ("multiply", "quaternion")


@dataclass(frozen=True)
class Targets:
    """Cartesian targets in the robot base frame: ids, positions (N, 3) mm, orientations (N, 3, 3), what the
    orientations are (named in the reason of an unreachable target); a robot on a track: the carriage position of
    each (N,) mm, None when the file gives none."""
    ids: tuple[str, ...]
    p_base_mm: np.ndarray
    R_base: np.ndarray
    orientation: str = "the plan's fixed SMR orientation"
    track_mm: np.ndarray | None = None


def read_targets_csv(path: str | Path, default_R: np.ndarray) -> Targets:
    """``target_id,x,y,z[,qw,qx,qy,qz][,track_mm]`` (mm, base frame; unit quaternion w-first; a robot on a track:
    the carriage position). Without a quaternion the plan's fixed SMR orientation is used. Errors name the file,
    line and column."""
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
    track = bool(header) and header[-1] == "track_mm"
    if header[:4] != need or header[4:len(header) - track] not in ([], quat):
        raise DataError(src, f"header must be {','.join(need)}[,{','.join(quat)}][,track_mm], got {','.join(header)}",
                        line=rows[0][0])
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
    travel = v[:, -1] if track else None
    v = v[:, :-1] if track else v
    if v.shape[1] == 7:
        q = v[:, 3:]
        norm = np.linalg.norm(q, axis=1)
        if np.any(np.abs(norm - 1) > 1e-3):
            bad = int(np.argmax(np.abs(norm - 1)))
            raise DataError(src, f"quaternion of {ids[bad]!r} is not unit (norm {norm[bad]:.4f})")
        from robocal.correct import quat_to_matrix
        R, how = quat_to_matrix(q), "the orientation given in the targets file"
    else:
        R, how = np.broadcast_to(default_R, (len(ids), 3, 3)).copy(), "the plan's fixed SMR orientation"
    return Targets(tuple(ids), v[:, :3], R, how, travel)


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


def run_correction(cell: CellModel, ap, T_target: np.ndarray, q_start: np.ndarray, T_tool: np.ndarray) -> Correction:
    """Pseudo-targets of the nominal model that bring the calibrated pose ``ap`` to ``T_target`` (settings of the
    ``correction`` section; ``ensemble``: the smallest converged correction of the generators)."""
    c, kin = cell.config.correction, cell.kinematics
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
    (shoulder: wrist centre in front of axis 1, elbow, sign of axis 5) as in ABB's confdata table. On a track: the
    arm's. A seven-axis arm (ABB numbers a YuMi's joints 1, 2, 7, 3, 4, 5, 6: its axes 1, 4, 6 are joints 1, 5, 7):
    cfx from the chain's branch signs (``robocal.kinematics.chains.branch_signs``). Fewer than six joints: the axes it has."""
    q_rad = np.atleast_2d(q_rad)
    if kin.track is not None:
        return abb_confdata(kin.arm(), q_rad[:, kin.n_track:])
    axes = [0, 4, 6] if kin.n == 7 else [j for j in (0, 3, 5) if j < kin.n]
    quad = np.zeros((len(q_rad), 3), int)
    quad[:, :len(axes)] = np.floor(np.degrees(q_rad[:, axes]) / 90.0).astype(int)
    if kin.n != 6:
        sig = branch_signs(kin, q_rad)
        cfx = sum((2 ** (sig.shape[1] - 1 - i)) * (sig[:, i] < 0) for i in range(sig.shape[1])) if sig.shape[1] else 0
        return np.column_stack([quad, np.zeros(len(q_rad), int) + cfx]).astype(int)
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
        from campaign.run.log_reader import read_log
        start = read_log(log_path).start or {}
    except Exception:                                # noqa: BLE001 - no readable log: nothing recorded
        return None
    found = start.get("robot_identity") or start.get("identity")
    return found if isinstance(found, dict) else None


def correct_targets(cell: CellModel, model: CalibratedModel, targets: Targets,
                    T_tool: np.ndarray | None = None, *, robot_identity: dict | None = None,
                    allow_absacc: bool = False, held_out: HeldOut | None = None,
                    ) -> tuple[list[CorrectedTarget], list[Rejected]]:
    """Corrected joints for Cartesian targets; out-of-bound or unreachable ones are rejected with a reason (an
    unreachable one with the plan's reason: ``campaign.plan.poses.unreachable_reasons``). The tool point (default
    ``T_tool``) is the model's SMR at its identified offset. Each target's predicted error comes from the model's
    ``held_out`` figures (``accuracy.held_out_of``; None: unknown, nan). An Absolute Accuracy robot
    (``robot_identity``, default: ``model.meta``) is refused unless ``allow_absacc``."""
    absacc_guard(robot_identity if robot_identity is not None else recorded_identity(model), allow=allow_absacc)
    cfg, kin = cell.config, cell.kinematics
    T_tool = tool_transform(model.kinematics.p_flange_smr_mm) if T_tool is None else T_tool   # the identified SMR
    R_flange = targets.R_base @ T_tool[:3, :3].T
    q_seed = target_seeds(cfg, kin, targets)
    q_nom, ok = solve_on_branch(kin, targets.p_base_mm, R_flange, q_seed, point_mm=T_tool[:3, 3])
    unreachable = np.flatnonzero(~ok)
    why = unreachable_reasons(kin, targets.p_base_mm[unreachable], R_flange[unreachable],
                              q_seed[unreachable] if np.ndim(q_seed) == 2 else q_seed,
                              orientation=targets.orientation, point_mm=T_tool[:3, 3])
    rejected = [Rejected(targets.ids[i], w) for i, w in zip(unreachable, why)]
    idx = np.flatnonzero(ok)
    accepted: list[CorrectedTarget] = []
    if len(idx):
        T_d = np.zeros((len(idx), 4, 4))
        T_d[:, :3, :3], T_d[:, :3, 3], T_d[:, 3, 3] = targets.R_base[idx], targets.p_base_mm[idx], 1.0
        c = run_correction(cell, model_pose_fn(model, T_tool), T_d, q_nom[idx], T_tool)
        changed = configuration_reasons(kin, c.q_rad, q_nom[idx])
        rejected += [Rejected(targets.ids[i], why) for i, why in zip(idx, changed) if why]
        idx, c = _kept(idx, c, [why is None for why in changed])
        cmd = fk(kin, c.q_rad) @ T_tool
        conf = abb_confdata(kin, c.q_rad)
        std = predictive_std_mm(model, c.q_rad)
        held = held_out if held_out is not None else HeldOut(None, "no held-out figures given")
        err, rot = predicted_errors_mm(held, std, c.pos_err_mm), rotation_errors_deg(held, c.rot_err_rad)
        for j, i in enumerate(idx):
            accepted.append(CorrectedTarget(
                target_id=targets.ids[i], q_nominal_deg=tuple(np.degrees(q_nom[i])),
                q_corrected_deg=tuple(np.degrees(c.q_rad[j])), p_command_base_mm=tuple(cmd[j, :3, 3]),
                quat_command_wxyz=tuple(matrix_to_quat(cmd[j:j + 1, :3, :3])[0]), confdata=tuple(int(v) for v in conf[j]),
                solver_tolerance_mm=float(c.pos_err_mm[j]), predicted_error_mm=float(err[j]),
                predicted_rot_err_deg=float(rot[j]), predicted_std_mm=float(std[j]),
                arm_angle_deg=float(np.degrees(arm_angle_rad(kin, c.q_rad[j:j + 1])[0])) if redundant(kin) else np.nan))
    lim = limits_deg(cfg)
    ok_targets, bad = check_targets(accepted, *lim, cfg.correction.max_joint_correction_deg,
                                    cfg.correction.max_position_correction_mm,
                                    {t: tuple(p) for t, p in zip(targets.ids, targets.p_base_mm)})
    return ok_targets, rejected + bad


def target_seeds(cfg: CampaignConfig, kin, targets: Targets) -> np.ndarray:
    """(N, n) rad: ``plan.q_ref_deg`` per target; a robot on a track with the carriage at the target's
    ``track_mm``, else where the target sits in front of the arm as the plan's grid centre does (within the
    travel). The corrected target keeps that carriage position."""
    q = np.tile(np.radians(cfg.plan.q_ref_deg), (len(targets.ids), 1))
    if kin.track is None:
        return q
    tr = cfg.robot.track
    u = kin.track / np.linalg.norm(kin.track)
    s = targets.track_mm if targets.track_mm is not None else \
        (targets.p_base_mm - np.asarray(cfg.plan.grid.center_mm)) @ u
    q[:, 0] = np.radians(np.clip(s, tr.q_min_deg, tr.q_max_deg))
    return q


def _kept(idx: np.ndarray, c: Correction, keep) -> tuple[np.ndarray, Correction]:
    """The targets ``idx`` and their correction where ``keep``."""
    k = np.asarray(keep, bool)
    return idx[k], Correction(c.q_rad[k], c.pos_err_mm[k], c.rot_err_rad[k], c.error[k], c.iterations[k],
                              c.generator[k])


def predictive_std_mm(model: CalibratedModel, q_rad: np.ndarray) -> np.ndarray:
    """3-D predictive standard deviation (N,) mm of the residual layer at q (GPR), nan without one."""
    fn = getattr(model.residual, "predict_std", None)
    if fn is None:
        return np.full(len(q_rad), np.nan)
    return np.linalg.norm(fn(q_rad, None, include_noise=False), axis=1)


def limits_deg(cfg: CampaignConfig):
    return [j.q_min_deg for j in cfg.robot.joints], [j.q_max_deg for j in cfg.robot.joints]


def check_model_fits(cell: CellModel, model: CalibratedModel, source: str, *, force: bool = False) -> None:
    """The model must describe the config's robot: same joint count and convention (DataError otherwise), and
    identified deltas from the nominal model within physical bounds (``force``: overridden)."""
    cfg = cell.config
    kin, n = model.kinematics, len(cfg.robot.joints)
    if kin.n != n:
        raise DataError(source, f"the model has {kin.n} joints but the config's robot has {n}: not a model of this robot")
    if kin.convention != cfg.robot.convention:
        raise DataError(source, f"the model uses {kin.convention!r} parameters but the config {cfg.robot.convention!r}: "
                                "not a model of this robot")
    from campaign.calibrate.plausibility import Plausibility, check_deltas

    check_deltas(cell.kinematics, kin, source, Plausibility(), force=force)   # a model of another robot: exit 2
