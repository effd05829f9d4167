"""Sim-to-real gap diagnosis of a dataset (run directory or interchange CSV) against a cell config.

``diagnose_source`` loads the data, prepares it, fits the geometry and runs the elastic stage exactly as
``reprocess`` does (``campaign.calibrate.effects_stage``: the effect engine decides which effects the data support), takes
the noise floor from repeated check poses (``check`` rows) when there are enough, else from the tracker and robot
specifications of the config, and runs :func:`robocal.diagnose.diagnose` on the calibration and test rows with
that answer: the same effects, values and "after" figures as reprocess's elastic stage. The report is a plain
dict whose leading keys are the JSON contract of issue 7::

    {"noise_floor_mm", "noise_floor_source": "repeats" | "specs", "baseline_test_rms_mm", "final_test_rms_mm",
     "unexplained", "findings": [{"effect", "joints" (1-based), "accepted", "test_rms_before_mm",
     "test_rms_after_mm", "evidence": {...}}], "where": [{"description", "rms_mm", ...}], ...}

followed by detail keys (``format``, ``source``, ``undiagnosable``, ``structure``, ``stages``, ``maps``, ...).
``render`` prints it with rich; ``write_plots`` draws the maps when matplotlib (the ``plots`` extra) is
importable. The self-check (``robocal.diagnose.selfcheck``) is rendered by ``render_self_check``.
"""
from __future__ import annotations

from dataclasses import dataclass
import os
from pathlib import Path

import numpy as np

from campaign.config.cell_model import CellModel
from campaign.config.schema import CampaignConfig
from campaign.data.dataset import Dataset
from campaign.data.source import load_source
from campaign.errors import DataError
from campaign.io.durable import write_json as _write_json
from robocal.diagnose.records import Diagnosis, DiagnosisInput, DiagnosisOptions
from robocal.diagnose.core import FittedStage, diagnose
from robocal.effects.engine import EngineOptions, run_engine
from robocal.identify.identification import IdentificationError
from robocal.kinematics.models import ParamLayout
from robocal.measure.repeats import noise_floor_from_repeats, repeat_dof

from .effects_stage import subset
from .plausibility import check_dataset, registered_kinematics
from .stages import fit_stages


REPORT_FORMAT = "campaign-diagnosis/1"
MIN_DIAGNOSIS_ROWS = 40      # calib rows a diagnosis needs (a calibration alone needs prepare.MIN_CALIB_ROWS)


@dataclass(frozen=True, eq=False)
class DiagnosisReport:
    report: dict
    diagnosis: Diagnosis


def _check(ds: Dataset, cfg: CampaignConfig) -> None:
    ds.require_joints(len(cfg.robot.joints))
    n_cal = int(ds.mask("calib").sum())
    if n_cal < MIN_DIAGNOSIS_ROWS:
        raise DataError(ds.source, f"only {n_cal} calib rows: the diagnosis needs at least {MIN_DIAGNOSIS_ROWS}")


def diagnosis_input(ds: Dataset, cell: CellModel, stage, baseline, nominal=None, q_cmd_deg=None
                    ) -> tuple[DiagnosisInput, FittedStage, dict]:
    """The robocal input (calib + test rows of the prepared dataset ``ds``, in measurement order), the engine's
    answer of reprocess's elastic stage ``stage`` mapped to those rows, and a dict describing the floor and the
    metadata. ``baseline``: the geometric fit (reprocess's kinematic stage); ``nominal``: the model of reprocess's
    nominal stage (None: the cell's); ``q_cmd_deg`` (N, n): commanded joints of ``ds``'s rows when ``q_deg`` are
    the read-back ones."""
    cfg = cell.config
    _check(ds, cfg)
    check = ds.mask("check")
    use = np.flatnonzero(ds.mask("calib") | ds.mask("test"))
    p = ds.p_tracker_mm
    repeats = noise_floor_from_repeats(ds.q_deg[check], p[check]) if check.any() else None
    specs = cell.noise_floor_mm(p[use])
    floor, source = (repeats, "repeats") if repeats is not None else (specs, "specs")
    meta = subset(stage.meta, use)
    inp = DiagnosisInput(cell.kinematics, np.radians(ds.q_deg[use]), p[use], cell.covariance(p)[use],
                         ds.mask("calib")[use], ds.mask("test")[use], floor, source,
                         repeat_dof(ds.q_deg[check]) if repeats is not None else None,
                         t_s=meta["t_s"], temp_c=meta["temp_c"], payload_kg=meta["payload_kg"], order=meta["order"],
                         approach=meta["approach"], move_rad=meta["move"], prev_move_rad=meta["prev_move"],
                         gravity=cell.gravity, baseline=baseline.kinematics,
                         baseline_identified=tuple(baseline.identified), nominal=nominal,
                         q_cmd_rad=None if q_cmd_deg is None else np.radians(np.asarray(q_cmd_deg, float)[use]))
    position = np.full(len(ds), -1)
    position[use] = np.arange(len(use))
    engine, elastic, kept = stage.engine, stage.elastic, stage.kept_rows
    if engine is None:                  # effects configured (or none): the diagnosis still asks the engine
        engine = run_engine(baseline.kinematics, _identified(baseline), np.radians(ds.q_deg[kept]), p[kept],
                            cell.weights(ds)[0][kept], subset(stage.meta, kept), cell.gravity,
                            EngineOptions(folds=cfg.calibration.cv_folds), cell.options)
        elastic = engine.elastic
    fitted = FittedStage(engine, elastic, position[kept], meta)
    payloads = None if ds.payload_kg is None else sorted({round(float(v), 3) for v in ds.payload_kg[use]})
    info = {"noise_floor_specs_mm": specs, "noise_floor_repeats_mm": repeats,
            "n": {"calib": int(ds.mask("calib").sum()), "test": int(ds.mask("test").sum()), "check": int(check.sum())},
            "metadata": {"timestamps": ds.t_s is not None, "temperatures": ds.temp_c is not None,
                         "payloads_kg": payloads, "measurement_order": "rows in measurement order (interchange CSV)",
                         "mass_model": inp.gravity.source},
            "baseline": "the kinematic stage of reprocess (same preparation, fault screen and estimator)",
            "engine": "the elastic stage of reprocess (calibration.effects: auto)" if stage.engine is not None
            else "the effect engine on reprocess's fitted rows (calibration.effects is not auto)"}
    return inp, fitted, info


def _commanded(ds: Dataset, fitted) -> np.ndarray | None:
    """Commanded joints (deg) of the fitted dataset's rows when the fits use the read-back ones, else None."""
    if ds.qc_deg is None or fitted.prep.joints != "readback":
        return None
    row = {pid: i for i, pid in enumerate(ds.point_id)}
    return ds.qc_deg[[row[pid] for pid in fitted.dataset.point_id]]


def _identified(result) -> np.ndarray:
    layout = ParamLayout.of(result.kinematics)
    return np.array([layout.index(n) for n in result.identified], int)


def diagnose_dataset(ds: Dataset, cell: CellModel, options: DiagnosisOptions | None = None, *,
                     force: bool = False) -> DiagnosisReport:
    """Diagnose one dataset; the report dict leads with the JSON contract. ``options`` None: the defaults with the
    config's ``calibration.cv_folds`` (the engine answer itself always comes from reprocess's elastic stage);
    ``force``: failed plausibility checks are overridden and reported as such."""
    cfg = cell.config
    _check(ds, cfg)
    ds, plaus = check_dataset(ds, cell, force=force)        # issue 12: does this data belong to this robot?
    options = options or DiagnosisOptions(engine=EngineOptions(folds=cfg.calibration.cv_folds))
    try:
        fitted = fit_stages(ds, cell, plaus)   # the same preparation, fits and effect engine as reprocess
        inp, stage, info = diagnosis_input(fitted.dataset, cell, fitted.stage, fitted.geo.result,
                                           registered_kinematics(cell, plaus), _commanded(ds, fitted))
        info["plausibility"] = plaus.to_dict()
        info["preparation"] = fitted.prep.report
        d = diagnose(inp, options, stage)
    except (IdentificationError, np.linalg.LinAlgError) as exc:
        raise DataError(ds.source, f"diagnosis failed: {exc}") from None
    body = d.to_dict()
    contract = {k: body.pop(k) for k in ("noise_floor_mm", "noise_floor_source", "baseline_test_rms_mm",
                                         "final_test_rms_mm", "unexplained", "findings", "where")}
    report = {**contract, "format": REPORT_FORMAT, "source": ds.source, "config": cfg.name, **info, **body}
    return DiagnosisReport(report, d)


def diagnose_source(source: str | os.PathLike, cell: CellModel,
                    options: DiagnosisOptions | None = None, *, force: bool = False) -> DiagnosisReport:
    """``diagnose_dataset`` of a run directory or CSV (``options`` None: the engine's folds are the config's
    ``calibration.cv_folds``, as in reprocess)."""
    return diagnose_dataset(load_source(source).dataset, cell, options, force=force)


def write_diagnosis_json(path: str | os.PathLike, data: dict) -> Path:
    """The report as JSON (atomic, no NaN); a missing directory is bad input."""
    path = Path(path)
    if path.parent and not path.parent.exists():
        raise DataError(str(path), "the directory does not exist")
    return _write_json(path, data)
