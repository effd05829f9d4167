"""Calibrate and evaluate a dataset (live run or interchange CSV): seed 000's two stages, judged on the test set.

Stages (seed 000 Table 3): ``nominal`` (nominal model, closed-form registration on the calibration points),
``kinematic`` (registration + identification) and ``compensated`` (kinematic + the residual layer of
``calibration.residual``: IDW, or GPR of seed 003, whose predictive standard deviation per test point is
reported as ``stages.compensated.test_pred_std_mm``).
Every figure is computed on held-out ``test`` rows; ``check`` rows (repeated poses) give the noise floor.
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from robocal.frames import transform_points
from robocal.gp import GPRResidual, fit_gpr_layer
from robocal.identify import CalibrationResult, IdentificationError, calibrate, register
from robocal.kinematics import smr_tracker
from robocal.model import CalibratedModel, fit_idw_layer
from robocal.noise import noise_floor_mm
from robocal.stats import error_stats

from .cell import calibration_options, measurement_covariance, nominal_kinematics, tracker_uncertainty
from .cell import weights_covariance
from .config import CampaignConfig
from .errors import DataError
from .fsutil import atomic_write
from .interchange import Dataset
from .prepare import prepare

REPORT_FORMAT = "campaign-report/1"


@dataclass(frozen=True, eq=False)
class Processed:
    report: dict
    model: CalibratedModel
    calibration: CalibrationResult


def repeat_groups(q_deg: np.ndarray, decimals: int = 3) -> list[np.ndarray]:
    """Row indices of repeated poses (same commanded joints to 10^-decimals deg), groups of >= 2."""
    keys = np.round(q_deg, decimals)
    _, inverse, counts = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
    return [np.flatnonzero(inverse.ravel() == g) for g in np.flatnonzero(counts >= 2)]


def noise_floor_from_repeats(q_deg: np.ndarray, p_mm: np.ndarray) -> float | None:
    """sqrt of the pooled within-pose variance of the 3-D position (mm), or None without enough repeats."""
    groups = repeat_groups(q_deg)
    dof = sum(len(g) - 1 for g in groups)
    if len(groups) < 2 or dof < 6:
        return None
    ss = sum(np.sum((p_mm[g] - p_mm[g].mean(axis=0)) ** 2) for g in groups)
    return float(np.sqrt(ss / dof))


def _check_dataset(ds: Dataset, cfg: CampaignConfig) -> None:
    n = len(cfg.robot.joints)
    if ds.q_deg.shape[1] != n:
        raise DataError(ds.source, f"has {ds.q_deg.shape[1]} joint columns but the config's robot has {n} joints")
    if ds.mask("calib").sum() < 10:
        raise DataError(ds.source, f"only {int(ds.mask('calib').sum())} calib rows: at least 10 are needed")


def _predict(kin_or_model, q, payload=None) -> np.ndarray:
    """Predicted SMR positions (N, 3) mm in the tracker frame of a kinematic model or a calibrated model."""
    if isinstance(kin_or_model, CalibratedModel) and getattr(kin_or_model.residual, "uses_payload", False):
        p_kin = kin_or_model.kinematic_smr_base(q)                  # per-row payloads as GPR inputs
        return transform_points(kin_or_model.kinematics.T_tracker_base,
                                p_kin + kin_or_model.residual.predict(q, p_kin, payload))
    if isinstance(kin_or_model, CalibratedModel):
        return kin_or_model.smr_tracker(q)
    return smr_tracker(kin_or_model, q)


def _stage(kin_or_model, q, p, payload=None) -> dict:
    if len(q) == 0:
        return {"max_mm": None, "mean_mm": None, "rms_mm": None, "n": 0}
    return error_stats(p - _predict(kin_or_model, q, payload)).to_dict()


def _varying_payload(ds: Dataset, cal: np.ndarray) -> np.ndarray | None:
    """Per-row payloads (kg) when they vary over the calib rows (then a GPR input), else None."""
    if ds.payload_kg is None or np.ptp(ds.payload_kg[cal]) == 0:
        return None
    return np.asarray(ds.payload_kg, float)


def _pred_std(layer: GPRResidual, q: np.ndarray, payload, point_ids) -> dict:
    """GPR predictive standard deviation (eq. 8, 3-D: sqrt(sx^2 + sy^2 + sz^2), mm) of every test point."""
    if len(q) == 0:
        return {"max_mm": None, "mean_mm": None, "rms_mm": None, "n": 0, "per_point_mm": {}}
    s = np.linalg.norm(layer.predict_std(q, None, payload), axis=1)
    return {"max_mm": float(s.max()), "mean_mm": float(s.mean()), "rms_mm": float(np.sqrt(np.mean(s**2))),
            "n": int(len(s)), "per_point_mm": {pid: float(v) for pid, v in zip(point_ids, s)}}


def process(ds: Dataset, cfg: CampaignConfig) -> Processed:
    """Calibrate on the calib rows, evaluate every stage on the test rows, and build the report."""
    prep = prepare(ds, cfg); ds = prep.dataset  # joint set, nest drift (campaign/prepare.py)  # noqa: E702
    _check_dataset(ds, cfg)
    kin0 = nominal_kinematics(cfg)
    q = np.radians(ds.q_deg)
    p = ds.p_tracker_mm
    cal, test, check = ds.mask("calib"), ds.mask("test"), ds.mask("check")
    cov, cov_source = weights_covariance(cfg, ds)
    try:
        result = calibrate(kin0, q[cal], p[cal], cov[cal], calibration_options(cfg))
    except IdentificationError as exc:
        raise DataError(ds.source, f"calibration failed: {exc}") from None
    nominal = register(kin0, q[cal], p[cal])
    payload = _varying_payload(ds, cal) if cfg.calibration.residual == "gpr" else None
    pay_cal = None if payload is None else payload[cal]
    layer = fit_residual_layer(cfg, result.kinematics, q[cal], p[cal], result.point_weights, pay_cal)
    model = CalibratedModel(result.kinematics, layer)
    rows = lambda m: None if payload is None else payload[m]  # noqa: E731
    stages = {name: {"test": _stage(m, q[test], p[test], rows(test)), "calib": _stage(m, q[cal], p[cal], rows(cal))}
              for name, m in (("nominal", nominal), ("kinematic", result.kinematics), ("compensated", model))}
    if isinstance(model.residual, GPRResidual):
        stages["compensated"]["test_pred_std_mm"] = _pred_std(model.residual, q[test], rows(test),
                                                              np.array(ds.point_id)[test].tolist())
    repeats = noise_floor_from_repeats(ds.q_deg[check], p[check]) if check.any() else None
    eval_rows = test if test.any() else cal
    specs = noise_floor_mm(p[eval_rows], tracker_uncertainty(cfg), cfg.robot.repeatability_mm)
    calib_ids = np.array(ds.point_id)[cal]
    report = {
        "format": REPORT_FORMAT, "config": cfg.name, "source": ds.source,
        "n": {"calib": int(cal.sum()), "test": int(test.sum()), "check": int(check.sum()),
              "rejected": int(np.sum(result.point_weights == 0))},
        "stages": stages,
        "noise_floor_mm": repeats if repeats is not None else specs,
        "noise_floor_source": "repeats" if repeats is not None else "specs",
        "noise_floor_specs_mm": specs, "noise_floor_repeats_mm": repeats,
        "parameters": _parameters(result), "unidentifiable": [u.to_dict() for u in result.unidentifiable],
        "condition_number": result.condition_number, "observability": result.observability,
        "sigma0": result.sigma0, "iterations": result.iterations, "converged": result.converged,
        "rejected_points": calib_ids[result.point_weights == 0].tolist(),
        "T_tracker_base": result.kinematics.T_tracker_base.tolist(),
        "method": {"estimator": cfg.calibration.method, "weights": cfg.calibration.weights,
                   "residual": cfg.calibration.residual, "measurement_covariance": cov_source},
        "residual_cv": residual_cv(cfg, result.kinematics, q[cal], p[cal], result.point_weights, pay_cal),
        "preparation": prep.report,
    }
    model = CalibratedModel(model.kinematics, model.residual, {"config": cfg.name, "source": ds.source})
    return Processed(report, model, result)


def fit_residual_layer(cfg: CampaignConfig, kin, q, p, weights, payload=None):
    """The configured residual layer (IDW or GPR) fitted on calibration points, or None."""
    c = cfg.calibration
    if c.residual == "idw":
        return fit_idw_layer(kin, q, p, c.idw_power, c.idw_k_nearest, weights)
    if c.residual == "gpr":
        layer = fit_gpr_layer(kin, q, p, weights, payload)
        return layer.with_payload(cfg.tool.payload_kg) if layer.uses_payload else layer
    return None


def residual_cv(cfg: CampaignConfig, kin, q, p, weights, payload=None, folds: int = 5, seed: int = 0) -> dict | None:
    """Does the residual layer predict anything? k-fold cross-validation over the calibration points (kinematics
    fixed): RMS of the held-out residual without and with the layer. A negative gain means the layer only
    interpolates noise (e.g. purely geometric errors, or a pose set too sparse for the structure)."""
    if cfg.calibration.residual == "none":
        return None
    idx = np.flatnonzero(np.asarray(weights) > 0)
    if len(idx) < 4 * folds:
        return None
    fold = np.random.default_rng(seed).permutation(len(idx)) % folds
    r0 = p - smr_tracker(kin, q)
    without, with_ = [], []
    for k in range(folds):
        tr, te = idx[fold != k], idx[fold == k]
        pay = (lambda rows: None) if payload is None else (lambda rows: payload[rows])  # noqa: E731
        layer = fit_residual_layer(cfg, kin, q[tr], p[tr], None, pay(tr))
        without.append(r0[te])
        with_.append(p[te] - _predict(CalibratedModel(kin, layer), q[te], pay(te)))
    a = error_stats(np.concatenate(without)).rms_mm
    b = error_stats(np.concatenate(with_)).rms_mm
    return {"folds": folds, "rms_without_mm": a, "rms_with_mm": b, "gain": 1.0 - b / a}


def _parameters(result: CalibrationResult) -> list[dict]:
    """Parameter table with angles converted to degrees for people."""
    rows = []
    for row in result.parameters_table():
        if row["unit"] == "rad":
            row = dict(row, unit="deg", delta=float(np.degrees(row["delta"])),
                       std=None if row["std"] is None else float(np.degrees(row["std"])))
        rows.append(row)
    return rows


def _write_json(path: Path, data: dict) -> None:
    atomic_write(path, json.dumps(data, indent=1, allow_nan=False, default=_plain).encode())


def _plain(x):
    if isinstance(x, (np.floating, np.integer)):
        return x.item()
    if isinstance(x, np.ndarray):
        return x.tolist()
    raise TypeError(f"not JSON serialisable: {type(x).__name__}")


def write_outputs(processed: Processed, out_dir: str | Path) -> Path:
    """DIR/report.json and DIR/model.json (the calibrated model, plain JSON with units)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    _write_json(out / "report.json", processed.report)
    _write_json(out / "model.json", processed.model.to_dict())
    return out / "report.json"


def load_model(path: str | Path) -> CalibratedModel:
    """Read a model.json written by write_outputs."""
    try:
        return CalibratedModel.from_dict(json.loads(Path(path).read_text()))
    except (OSError, ValueError, KeyError) as exc:
        raise DataError(str(path), f"not a readable calibrated model: {exc}") from None
