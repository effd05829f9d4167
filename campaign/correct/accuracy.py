"""The accuracy a corrected target can expect, and what ``correct`` says about it.

The predicted position error of a target is the final model's held-out RMS (its 3-D error on the calibration's test
points, ``report.json`` beside ``model.json``) combined in quadrature with the residual layer's predictive standard
deviation at the target where the model has a GPR layer, and with the solver tolerance. A rotation error is
predicted only where orientation was measured (a three-SMR calibration: its held-out orientation RMS), else nan.
The pseudo-target iteration's own convergence is the solver tolerance, reported apart: it is not an accuracy.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from robocal.layers.calibrated_model import CalibratedModel

from campaign.errors import one_line

from .bounds import CorrectedTarget

PREDICTED_ERROR_METHOD = ("held-out RMS of the final model on the calibration's test points (report.json beside "
                          "model.json), combined in quadrature with the residual layer's predictive standard "
                          "deviation at the target (GPR layers) and the solver tolerance")


@dataclass(frozen=True)
class HeldOut:
    """What a model's calibration measured on held-out points: the final model's 3-D RMS (mm) on ``n`` test points,
    the noise floor (mm) and its source, the three-SMR flange orientation RMS (deg, None without three SMRs), and
    ``source``: where the figures come from, or, with ``rms_mm`` None, why they are unknown."""
    rms_mm: float | None
    source: str
    n: int = 0
    noise_floor_mm: float | None = None
    noise_floor_source: str = ""
    rot_rms_deg: float | None = None
    rot_n: int = 0


def held_out_of(model: CalibratedModel, model_path: str | Path) -> HeldOut:
    """The held-out figures of ``model`` from the calibration report beside ``model_path`` (the run or reprocess
    directory's report.json); unknown (``rms_mm`` None, with the reason) when there is no such report, it is not
    readable, not a calibration report, of another calibration, or has no test points."""
    from campaign.calibrate.calibration_report import CalibrationReport
    from campaign.calibrate.stages import REPORT_FORMAT
    from campaign.io.json_fields import RecordError

    path = Path(model_path).parent / "report.json"
    unknown = lambda why: HeldOut(None, why)  # noqa: E731
    if not path.exists():
        return unknown(f"no report.json beside {Path(model_path).name}: keep the model in the directory that run or "
                       "reprocess wrote")
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
        if not isinstance(doc, dict) or doc.get("format") != REPORT_FORMAT:
            return unknown(f"{path} is not a calibration report")
        report = CalibrationReport.from_dict(doc)
    except (OSError, ValueError, RecordError) as exc:
        return unknown(f"{path} is not readable ({one_line(exc)})")
    meta = model.meta or {}
    if any(k in meta and meta[k] != getattr(report, k) for k in ("config", "source")):
        return unknown(f"{path} is the report of another calibration than {Path(model_path).name}")
    test = report.final.test if report.final is not None else None
    if test is None or not test.n or test.rms_mm is None:
        return unknown(f"the calibration in {path} had no test points (plan.test.count)")
    orient = report.multi_smr.orientation_error_arcsec if report.multi_smr is not None else None
    return HeldOut(test.rms_mm, str(path), test.n, report.noise_floor_mm, report.noise_floor_source or "",
                   None if orient is None else orient.rms / 3600.0, 0 if orient is None else orient.n)


def predicted_errors_mm(held: HeldOut, std_mm: np.ndarray, solver_mm: np.ndarray) -> np.ndarray:
    """Predicted position error (N,) mm: sqrt(held-out RMS^2 + std^2 + solver^2), without the std where ``std_mm`` is
    nan (no GPR layer); the solver's remaining distance ``solver_mm`` is a miss the model itself predicts (normally
    negligible). nan everywhere when the held-out RMS is unknown."""
    std = np.nan_to_num(np.asarray(std_mm, float), nan=0.0)
    rms = math.nan if held.rms_mm is None else held.rms_mm
    return np.sqrt(rms**2 + std**2 + np.asarray(solver_mm, float) ** 2)


def rotation_errors_deg(held: HeldOut, model_rot_err_rad: np.ndarray) -> np.ndarray:
    """Predicted orientation error (N,) deg where orientation was measured (a three-SMR calibration): the model's
    orientation error at the corrected joints ``model_rot_err_rad`` (a position-only correction leaves it) combined
    in quadrature with the held-out orientation RMS; nan without orientation measurements (the model's orientation
    was never checked)."""
    rms = math.nan if held.rot_rms_deg is None else held.rot_rms_deg
    return np.hypot(np.degrees(np.asarray(model_rot_err_rad, float)), rms)


def _span(values: Sequence[float], fmt: str, unit: str = "mm") -> str:
    lo, hi = f"{min(values):{fmt}}", f"{max(values):{fmt}}"
    return f"{lo} {unit}" if lo == hi else f"{lo} to {hi} {unit}"


def summary_lines(accepted: Sequence[CorrectedTarget], held: HeldOut, threshold_mm: float) -> list[str]:
    """What ``correct`` prints about the written targets: the predicted position and orientation errors, where
    they come from, and the solver tolerance apart."""
    if not accepted:
        return []
    return [_position_line(accepted, held), _rotation_line(accepted, held), _solver_line(accepted, threshold_mm)]


def _position_line(accepted: Sequence[CorrectedTarget], held: HeldOut) -> str:
    if held.rms_mm is None:
        return f"predicted position error: unknown ({held.source}); predicted_error_mm is nan"
    source = held.source
    if held.noise_floor_mm:
        source += f"; {held.rms_mm / held.noise_floor_mm:.2f} x the noise floor {held.noise_floor_mm:.3f} mm"
        source += f" from the {held.noise_floor_source}" if held.noise_floor_source else ""
    how = f"held-out RMS {held.rms_mm:.3f} mm of the final model on {held.n} test points ({source})"
    stds = [t.predicted_std_mm for t in accepted if not math.isnan(t.predicted_std_mm)]
    if stds:
        how += f", combined with the GPR layer's predictive std at each target ({_span(stds, '.2g')})"
    span = _span([t.predicted_error_mm for t in accepted], ".3f")
    return f"predicted position error (predicted_error_mm) {span}: {how}"


def _rotation_line(accepted: Sequence[CorrectedTarget], held: HeldOut) -> str:
    if held.rot_rms_deg is None:
        return ("predicted orientation error: not predicted (orientation is measured only with three SMRs); "
                "predicted_rot_err_deg is nan")
    rot = [t.predicted_rot_err_deg for t in accepted]
    return (f"predicted orientation error (predicted_rot_err_deg) {_span(rot, '.4f', 'deg')}: the model's orientation "
            f"at the corrected joints combined with the held-out RMS {held.rot_rms_deg:.4f} deg of the three-SMR "
            f"calibration on {held.rot_n} test poses")


def _solver_line(accepted: Sequence[CorrectedTarget], threshold_mm: float) -> str:
    left = [t.solver_tolerance_mm for t in accepted]
    short = sum(v >= threshold_mm for v in left)
    missed = f"; {short} target{'s' if short > 1 else ''} did not get there" if short else ""
    return (f"solver tolerance (solver_tolerance_mm): the pseudo-target iteration left at most {max(left):.2e} mm "
            f"between the model and the targets (stops below {threshold_mm:g} mm{missed}); a convergence figure, "
            "not an accuracy")
