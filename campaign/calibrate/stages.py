"""Calibrate and evaluate a dataset (live run or interchange CSV): seed 000's two stages, judged on the test set.

Stages (seed 000 Table 3): ``nominal`` (nominal model, closed-form registration on the calibration points),
``kinematic`` (registration + geometric identification after the measurement-fault screen, ``geometric_fit``),
``elastic`` (geometry + the physical effects taken, when any: ``calibration.effects``) and ``compensated`` (the
final model: + the residual layer that k-fold CV supports under ``calibration.residual: auto``, or the configured
IDW / GPR layer; equal to the previous stage without a layer). A GPR layer's predictive standard deviation per
test point is reported as ``stages.compensated.test_pred_std_mm``.
Every figure is computed on held-out ``test`` rows; ``check`` rows (repeated poses) give the noise floor.
The report's ``parameters`` are the rows of the written model's own record (``CalibratedModel.parameters``: the final
fit's values and std); with physical effects the geometric fit's rows are reported beside them, labelled.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
import warnings

import numpy as np

from campaign.config.cell_model import CellModel
from campaign.config.schema import CampaignConfig
from campaign.data.dataset import Dataset
from campaign.errors import DataError, DataWarning
from robocal.kinematics.frames import transform_points
from robocal.layers.gp_layer import GPRResidual
from robocal.layers.joint_gp import MIN_SPAN_RAD, JointGPResidual
from robocal.identify.identification import CalibrationResult, IdentificationError, calibrate, register
from robocal.kinematics.models import smr_tracker
from robocal.layers.choice import LayerChoice, choose_layer, fit_layer, layer_summary
from robocal.layers.calibrated_model import CalibratedModel
from robocal.measure.repeats import noise_floor_from_repeats, repeat_groups
from robocal.identify.screening import NEAR_FRACTION, ScreenResult, joint_levers_mm, near_neighbours, reach_mm, screen
from robocal.measure.stats import error_stats

from .budget_stage import calibration_budget
from .calibration_report import COMPENSATED, ELASTIC, KINEMATIC, NOMINAL, CalibrationReport
from .effects_stage import ElasticStage, elastic_stage, order_meta, subset
from .multi_smr import multi_smr_report, screen_smrs
from .plausibility import check_dataset, check_deltas, registered_kinematics, start_kinematics, start_smr_offsets_mm
from .prepare import MIN_CALIB_ROWS, prepare
from .report_points import PointTable, cell_summary, point_table, report_points_value
from .report_sections import (NO_POINTS, EffectsReport, ErrorFigures, ExcludedPoint, HeldOutOutliers, HeldOutPoint,
                              LayerSummary, MethodChoice, PredictiveStd, ResidualChoice, ResidualCV, RowCounts,
                              StageResult, parameter_rows)


REPORT_FORMAT = "campaign-report/1"
NO_TEST_ROWS = "no test rows: nothing is held out, so no figure is a held-out accuracy; give some rows set 'test'"


@dataclass(frozen=True, eq=False)
class Calibrated:
    report: CalibrationReport
    model: CalibratedModel
    calibration: CalibrationResult
    points: PointTable | None = None       # the per-point rows (report.json's ``points``, or points.csv beyond a size)


def _check_dataset(ds: Dataset, cfg: CampaignConfig) -> None:
    ds.require_joints(len(cfg.robot.joints))
    if ds.mask("calib").sum() < MIN_CALIB_ROWS:
        raise DataError(ds.source, f"only {int(ds.mask('calib').sum())} calib rows: at least {MIN_CALIB_ROWS} are "
                                   "needed")


def _predict(kin_or_model, q, payload=None, meta=None) -> np.ndarray:
    """Predicted SMR positions (N, 3) mm in the tracker frame of a kinematic model or a calibrated model
    (``meta``: per-row metadata of its physical effects)."""
    if isinstance(kin_or_model, CalibratedModel) and getattr(kin_or_model.residual, "uses_payload", False):
        p_kin = kin_or_model.kinematic_smr_base(q, meta)           # per-row payloads as GPR inputs
        return transform_points(kin_or_model.kinematics.T_tracker_base,
                                p_kin + kin_or_model.residual.predict(q, p_kin, payload))
    if isinstance(kin_or_model, CalibratedModel):
        return kin_or_model.smr_tracker(q, meta)
    return smr_tracker(kin_or_model, q)


def _stage(kin_or_model, q, p, payload=None, meta=None) -> ErrorFigures:
    if len(q) == 0:
        return NO_POINTS
    return ErrorFigures.of(error_stats(p - _predict(kin_or_model, q, payload, meta)))


def _varying_payload(ds: Dataset, cal: np.ndarray) -> np.ndarray | None:
    """Per-row payloads (kg) when they vary over the calib rows (then a GPR input), else None."""
    if ds.payload_kg is None or np.ptp(ds.payload_kg[cal]) == 0:
        return None
    return np.asarray(ds.payload_kg, float)


def _pred_std(layer: GPRResidual | JointGPResidual, q: np.ndarray, payload, point_ids
              ) -> tuple[PredictiveStd, np.ndarray]:
    """GPR predictive standard deviation (eq. 8, 3-D: sqrt(sx^2 + sy^2 + sz^2), mm) of every test point: the
    report entry and the values (M,)."""
    if len(q) == 0:
        return PredictiveStd(None, None, None, 0, {}), np.zeros(0)
    s = np.linalg.norm(layer.predict_std(q, None, payload), axis=1)
    return PredictiveStd(float(s.max()), float(s.mean()), float(np.sqrt(np.mean(s**2))), int(len(s)),
                         {pid: float(v) for pid, v in zip(point_ids, s)}), s


def prepared_dataset(ds: Dataset, cell: CellModel) -> Dataset:
    """The single place where a dataset is prepared before any fit: joint-set choice (commanded / read-back)
    and tracker-drift compensation from the reference nests (campaign/calibrate/prepare.py)."""
    return prepare(ds, cell).dataset


@dataclass(frozen=True, eq=False)
class GeometricFit:
    """The geometric-only calibration of the calib rows ``rows`` (indices into the dataset): ``result`` with
    ``point_weights`` 0 on excluded points and residuals of every calib row; ``screen`` the fault screening."""
    result: CalibrationResult
    screen: ScreenResult | None
    rows: np.ndarray

    @property
    def keep(self) -> np.ndarray:
        return np.asarray(self.result.point_weights) > 0


def _identify(kin0, q, p, cov, options, source):
    try:
        return calibrate(kin0, q, p, cov, options)
    except IdentificationError as exc:
        raise DataError(source, f"calibration failed: {exc}") from None


def _geometric(ds: Dataset, cell: CellModel, kin0, rescreen: _Screen) -> GeometricFit:
    """Geometry-only calibration from ``kin0`` (the nominal model with the registered SMR offset) with the
    measurement-fault screen (``calibration.outliers``): fit, screen the residuals locally, refit without the
    faults, until the excluded set is stable (at most 3 refits); ``rescreen`` the screen of this dataset."""
    rows = np.flatnonzero(ds.mask("calib"))
    q, p = np.radians(ds.q_deg[rows]), ds.p_tracker_mm[rows]
    cov = cell.weights(ds)[0][rows]
    options = cell.options
    result = _identify(kin0, q, p, cov, options, ds.source)
    keep = np.ones(len(rows), bool)
    sc = None
    if cell.config.calibration.outliers == "local":
        for _ in range(4):
            sc = rescreen(rows, p - smr_tracker(result.kinematics, q))
            new_keep = sc.keep
            if np.array_equal(new_keep, keep):
                break
            keep = new_keep
            if keep.sum() < MIN_CALIB_ROWS:
                raise DataError(ds.source, f"the fault screen left fewer than {MIN_CALIB_ROWS} calibration points")
            result = _identify(kin0, q[keep], p[keep], cov[keep], options, ds.source)
    w = np.zeros(len(rows))
    w[keep] = result.point_weights
    result = replace(result, point_weights=w, residual_tracker_mm=p - smr_tracker(result.kinematics, q))
    return GeometricFit(result, sc, rows)


class _Screen:
    """The measurement-fault screen of calib rows ``rows`` of one dataset with residuals r_mm (nominal levers and
    reach): ``screen(rows, r_mm)``. The neighbour search of the last row set is kept: it depends on the poses
    only, and the refits screen the same rows again with new residuals."""

    def __init__(self, ds: Dataset, kin0):
        self.ds, self.kin0, self.near_mm = ds, kin0, NEAR_FRACTION * reach_mm(kin0)
        self._last: tuple[bytes, tuple] | None = None

    def __call__(self, rows: np.ndarray, r_mm: np.ndarray) -> ScreenResult:
        ds, q = self.ds, np.radians(self.ds.q_deg[rows])
        p = ds.p_tracker_mm[rows]
        key = np.asarray(rows).tobytes()
        if self._last is None or self._last[0] != key:
            self._last = (key, near_neighbours(q, p, joint_levers_mm(self.kin0, q), self.near_mm))
        return screen(q, p, r_mm, None, self.near_mm, None if ds.sigma_mm is None else ds.sigma_mm[rows],
                      repeat_groups(ds.q_deg[rows]), neighbours=self._last[1])


def geometric_fit(ds: Dataset, cell: CellModel, *, force: bool = False) -> CalibrationResult:
    """The geometric-only calibration the "kinematic" stage reports (after the dataset preparation and the
    measurement-fault screen): the baseline of ``diagnose``. ``point_weights`` (calib rows) 0 = excluded."""
    _check_dataset(ds, cell.config)
    ds, plaus = check_dataset(ds, cell, force=force)
    ds = prepared_dataset(ds, cell)
    keep, _ = screen_smrs(ds, cell)
    ds = ds.subset(keep) if not keep.all() else ds
    kin0 = start_kinematics(cell, plaus)
    return _geometric(ds, cell, kin0, _Screen(ds, kin0)).result


@dataclass(frozen=True, eq=False)
class Fitted:
    """What reprocess and diagnose share: the preparation, the dataset the fits saw (SMR-triangle faults set
    aside), those set-aside rows, the geometric fit and the elastic stage (the effect engine's answer)."""
    prep: object
    dataset: Dataset
    smr_excluded: list
    kin0: object
    geo: GeometricFit
    stage: ElasticStage


def fit_stages(ds: Dataset, cell: CellModel, plaus) -> Fitted:
    """Preparation, SMR-triangle screen, geometric fit (from the registered start ``kin0`` of the plausibility
    check ``plaus``) and elastic stage of a checked dataset: one sequence for ``reprocess`` and ``diagnose``, so
    both take the same effects with the same values."""
    prep = prepare(ds, cell); ds = prep.dataset  # joint set, nest drift (campaign/calibrate/prepare.py)  # noqa: E702
    order = order_meta(ds)                                  # approach and moves from the full measurement order
    smr_keep, smr_excluded = screen_smrs(ds, cell)          # SMR-triangle faults: calib, test and check rows
    if not smr_keep.all():
        ds, order = ds.subset(smr_keep), subset(order, smr_keep)
        _check_dataset(ds, cell.config)
    kin0 = start_kinematics(cell, plaus)                    # registration before plausibility: base + SMR offset
    rescreen = _Screen(ds, kin0)
    geo = _geometric(ds, cell, kin0, rescreen)
    stage = elastic_stage(ds, cell, geo, order, rescreen)
    return Fitted(prep, ds, smr_excluded, kin0, geo, stage)


@dataclass(frozen=True, eq=False)
class FinalLayer:
    """The residual layer chosen on the fitted rows of a dataset (``calibration.residual``), with what it was
    chosen with: per-row payloads when they vary (a GPR input; else None) and the noise floor (the check rows'
    repeats, else the specs at the test rows, or at the calibration rows without test rows); ``base`` the model
    the layer sits on: the elastic stage's, or its geometric model when the choice left the effects out."""
    choice: LayerChoice
    payload: np.ndarray | None
    floor_mm: float
    repeats_mm: float | None
    specs_mm: float
    base: CalibratedModel


def final_layer(ds: Dataset, cell: CellModel, stage: ElasticStage) -> FinalLayer:
    """The layer of the final model on top of the elastic stage ``stage`` of the prepared dataset ``ds``."""
    cfg, c = cell.config, cell.config.calibration
    cal, test, check = ds.mask("calib"), ds.mask("test"), ds.mask("check")
    q, p, kept = np.radians(ds.q_deg), ds.p_tracker_mm, stage.kept_rows
    qk, pk = q[kept], p[kept]
    payload = _varying_payload(ds, cal) if c.residual in ("gpr", "trend_gpr", "auto") else None
    pay_k = None if payload is None else payload[kept]
    repeats = noise_floor_from_repeats(ds.q_deg[check], p[check]) if check.any() else None
    specs = cell.noise_floor_mm(p[test if test.any() else cal])
    floor = repeats if repeats is not None else specs
    lay_kw = dict(meta=subset(stage.meta, kept), payload_kg=pay_k, idw_power=c.idw_power,
                  idw_k_nearest=c.idw_k_nearest, noise_floor_mm=floor)
    model_el = stage.model
    if c.residual == "auto":
        rival = stage.geometric if c.effects == "auto" else None       # configured effects are never left out
        choice = choose_layer(model_el, qk, pk, folds=c.cv_folds, geometric=rival, **lay_kw)
    elif c.residual == "none":
        choice = LayerChoice("none", None, {}, c.cv_folds)
    else:
        choice = choose_layer(model_el, qk, pk, candidates=(c.residual,), folds=c.cv_folds, **lay_kw)
        forced = fit_layer(c.residual, model_el, qk, pk, **lay_kw)
        if forced is None:                                  # joint_gp: no joint moves enough to carry a curve
            warnings.warn(f"{ds.source}: calibration.residual: {c.residual}: no joint moves "
                          f"{np.degrees(MIN_SPAN_RAD):.0f} deg over the "
                          "calibration rows; no residual layer", DataWarning, stacklevel=2)
        choice = LayerChoice(c.residual if forced is not None else "none", forced, choice.cv, c.cv_folds)
    return FinalLayer(choice, payload, floor, repeats, specs, stage.geometric if choice.on_geometry else model_el)


@dataclass(frozen=True, eq=False)
class Evaluation:
    """Every stage of a calibration evaluated, before the report is written: ``fitted`` the checked fits,
    ``dataset`` the rows they saw, ``plaus`` the plausibility verdict, ``layer`` the final layer, ``model`` the
    model written (SMR offsets of a multi-SMR tool in its meta), ``stage_models`` (name, model) in stage order,
    ``stages`` their figures, ``table`` the per-point rows and ``points`` their report value, the excluded and
    weight-rejected calibration points, the multi-SMR section and the error budget."""
    fitted: Fitted
    dataset: Dataset
    plaus: object
    layer: FinalLayer
    model: CalibratedModel
    stage_models: list
    stages: dict
    table: PointTable
    points: dict
    excluded: list
    rejected_ids: list
    multi: object
    budget: object


def calibrate_dataset(ds: Dataset, cell: CellModel, *, force: bool = False) -> Calibrated:
    """Calibrate on the calib rows, evaluate every stage on the test rows, and build the report; ``force``
    (``--force``): failed plausibility checks are overridden and reported as such."""
    ev = evaluate_stages(ds, cell, force=force)
    return Calibrated(calibration_report(ev, cell), ev.model, ev.fitted.geo.result, ev.table)


def _checked_fit(ds: Dataset, cell: CellModel, force: bool):
    """The plausibility checks and the fits of ``ds`` (checked again on the identified geometry): (fitted, plaus)."""
    _check_dataset(ds, cell.config)
    ds, plaus = check_dataset(ds, cell, force=force)        # issue 12: before anything is fitted or written
    fitted = fit_stages(ds, cell, plaus)
    plaus = check_deltas(fitted.kin0, fitted.geo.result.kinematics, fitted.dataset.source, plaus, force=force)
    if not fitted.dataset.mask("test").any():
        plaus = replace(plaus, notes=plaus.notes + (NO_TEST_ROWS,))
        # stacklevel 4: the caller of calibrate_dataset (through evaluate_stages), where the warning was raised before
        warnings.warn(f"{fitted.dataset.source}: {NO_TEST_ROWS}", DataWarning, stacklevel=4)
    return fitted, plaus


def evaluate_stages(ds: Dataset, cell: CellModel, *, force: bool = False) -> Evaluation:
    """The checked fits of ``ds``, the final model and every stage's figures on the test and calib rows, the
    per-point table and the error budget (see :class:`Evaluation`)."""
    cfg, c = cell.config, cell.config.calibration
    fitted, plaus = _checked_fit(ds, cell, force)
    ds, geo, stage = fitted.dataset, fitted.geo, fitted.stage
    q, p = np.radians(ds.q_deg), ds.p_tracker_mm
    cal, test = ds.mask("calib"), ds.mask("test")
    meta_all, kept_rows = stage.meta, stage.kept_rows
    fl = final_layer(ds, cell, stage)
    payload, choice, base = fl.payload, fl.choice, fl.base
    layer = choice.layer
    if isinstance(layer, GPRResidual) and layer.uses_payload:
        layer = layer.with_payload(cfg.tool.payload_kg)
    model = CalibratedModel(base.kinematics, layer, {"config": cfg.name, "source": ds.source},
                            base.effects, float(cfg.tool.payload_kg or 0.0), base.parameters)
    rows = lambda m: None if payload is None else payload[m]  # noqa: E731
    predict = lambda m, r: _predict(m, q[r], rows(r), subset(meta_all, r))  # noqa: E731
    stage_models = [(NOMINAL, register(registered_kinematics(cell, plaus), q[cal], p[cal])),
                    (KINEMATIC, geo.result.kinematics)]
    if stage.elastic is not None:
        stage_models.append((ELASTIC, stage.model))
    stage_models.append((COMPENSATED, model))
    stages = {name: StageResult(_stage(m, q[test], p[test], rows(test), subset(meta_all, test)),
                                _stage(m, q[cal], p[cal], rows(cal), subset(meta_all, cal)))
              for name, m in stage_models}
    spread, pred_std = None, None                         # (N,) GPR predictive std of the test rows, else NaN
    if isinstance(model.residual, (GPRResidual, JointGPResidual)):
        pred_std = np.full(len(ds), np.nan)
        spread, pred_std[test] = _pred_std(model.residual, q[test], rows(test), np.array(ds.point_id)[test].tolist())
    excluded, rejected_ids = _excluded_points(ds, fitted, c.weights)
    multi = None
    if ds.p2_tracker_mm is not None:
        multi = multi_smr_report(ds, cell, fitted.kin0, kept_rows, test, start_smr_offsets_mm(cfg, plaus))
        if multi.p_flange_smr_mm is not None:
            model = replace(model, meta={**(model.meta or {}), "p_flange_smrs_mm": multi.p_flange_smr_mm})
    used = np.full(len(ds), np.nan)                      # 1 = in the fit, 0 = excluded calib row
    used[geo.rows], used[kept_rows] = 0.0, 1.0
    table = point_table(ds.point_id, ds.set, ds.q_deg, p, model.kinematics.T_tracker_base,  # HTML figures
                        {name: (lambda r, m=m: predict(m, r)) for name, m in stage_models}, used, ds.t_s, pred_std)
    points = report_points_value(table)
    stages[COMPENSATED] = _final_stage(stages[COMPENSATED], choice, spread, points)
    # the budget of the final model: without the elastic stage when the layer sits on the geometry alone
    budget_models = [sm for sm in stage_models if sm[0] != ELASTIC or not choice.on_geometry]
    budget = calibration_budget(predict, budget_models, geo, None if choice.on_geometry else stage.elastic,
                                choice.kind, q, p, cell.weights(ds)[0],
                                cell.covariance(p), meta_all, kept_rows, test, fl.floor_mm, subset, c.cv_folds)
    if test.any():
        outliers = held_out_outliers(np.array(ds.point_id)[test], table.err_base_mm[COMPENSATED][test],
                                     fl.floor_mm)
        stages[COMPENSATED] = replace(stages[COMPENSATED], test_outliers=outliers)
    return Evaluation(fitted, ds, plaus, fl, model, stage_models, stages, table, points, excluded, rejected_ids,
                      multi, budget)


def _excluded_points(ds: Dataset, fitted: Fitted, weights: str) -> tuple[list, list]:
    """The calibration points left out of the fit: (every excluded point with its reason: SMR-triangle faults,
    the measurement-fault screen, zero robust weight; the ids of the calib rows out of the fit, calib order)."""
    geo, stage = fitted.geo, fitted.stage
    calib_ids = np.array(ds.point_id)[geo.rows]
    excluded = list(fitted.smr_excluded) + ([] if stage.screen is None else [
        ExcludedPoint(str(calib_ids[e.index]), "calib", e.reason) for e in stage.screen.excluded])
    in_fit = np.zeros(len(ds), bool)
    in_fit[stage.kept_rows] = True
    rejected_ids = calib_ids[~in_fit[geo.rows]].tolist()
    listed = {e.point_id for e in excluded}
    excluded += [ExcludedPoint(pid, "calib", f"zero {weights} weight of the robust_ridge estimator")
                 for pid in rejected_ids if pid not in listed]
    return excluded, rejected_ids


def calibration_report(ev: Evaluation, cell: CellModel) -> CalibrationReport:
    """The report of an evaluated calibration (report.json)."""
    cfg, c, ds = cell.config, cell.config.calibration, ev.dataset
    result, stage, choice, model = ev.fitted.geo.result, ev.fitted.stage, ev.layer.choice, ev.model
    selection = None if stage.engine is None else stage.engine.selection
    repeats = ev.layer.repeats_mm
    return CalibrationReport(
        format=REPORT_FORMAT, config=cfg.name, source=ds.source,
        n=RowCounts(int(ds.mask("calib").sum()), int(ds.mask("test").sum()), int(ds.mask("check").sum()),
                    len(ev.rejected_ids)),
        stages=ev.stages, noise_floor_mm=ev.layer.floor_mm,
        noise_floor_source="repeats" if repeats is not None else "specs",
        noise_floor_specs_mm=ev.layer.specs_mm, noise_floor_repeats_mm=repeats,
        parameters=parameter_rows(model.parameters), unidentifiable=tuple(result.unidentifiable),
        condition_number=result.condition_number, observability=result.observability,
        sigma0=result.sigma0, iterations=result.iterations, converged=result.converged,
        rejected_points=tuple(ev.rejected_ids), excluded_points=tuple(ev.excluded),
        structure_note=None if stage.screen is None else stage.screen.structure_note(),
        T_tracker_base=model.kinematics.T_tracker_base.tolist(),
        method=MethodChoice(c.method, c.weights if c.method == "robust_ridge" else None, c.outliers,
                            c.effects if isinstance(c.effects, str) else "list", choice.kind, c.residual,
                            cell.weights(ds)[1]),
        effects=_effects_report(selection, stage.elastic, choice), residual_choice=ResidualChoice.of(choice),
        plausibility=ev.plaus, residual_cv=_residual_cv_summary(choice), preparation=ev.fitted.prep.report,
        multi_smr=ev.multi, cell=cell_summary(cfg), points=ev.points, parameters_fit=model.parameters.fit,
        parameters_sigma0=model.parameters.sigma0,
        parameters_geometry_only=None if not model.effects else parameter_rows(result.table()), budget=ev.budget)


ABSURD_OVER_FLOOR = 100.0     # a held-out error this many noise floors ...
ABSURD_OVER_MEDIAN = 10.0     # ... and this many times the median held-out error: a misread, not an accuracy


def held_out_outliers(point_ids: np.ndarray, err_mm: np.ndarray, floor_mm: float) -> HeldOutOutliers | None:
    """The held-out points (ids (M,), errors (M, 3) mm) whose 3-D error exceeds both ABSURD_OVER_FLOOR x the
    noise floor and ABSURD_OVER_MEDIAN x the median held-out error, with the figures without them; None when
    there is none (or every point would be one)."""
    e = np.linalg.norm(err_mm, axis=1)
    absurd = (e > ABSURD_OVER_FLOOR * floor_mm) & (e > ABSURD_OVER_MEDIAN * np.median(e))
    if not absurd.any() or absurd.all():
        return None
    order = np.flatnonzero(absurd)[np.argsort(-e[absurd])]
    return HeldOutOutliers(f"error > {ABSURD_OVER_FLOOR:g} x the noise floor ({floor_mm:.3g} mm) and > "
                           f"{ABSURD_OVER_MEDIAN:g} x the median held-out error",
                           tuple(HeldOutPoint(str(point_ids[i]), float(e[i])) for i in order),
                           ErrorFigures.of(error_stats(err_mm[~absurd])))


def _final_stage(stage: StageResult, choice: LayerChoice, spread: PredictiveStd | None, points: dict) -> StageResult:
    """The final model's stage with the GPR predictive spread (per point: in points.csv when the rows are there)
    and the fitted residual layer's summary."""
    if spread is not None and "file" in points:
        spread = replace(spread, per_point_mm={"file": points["file"], "column": "pred_std_mm"})
    layer = None if choice.layer is None else LayerSummary(**layer_summary(choice, stage.to_dict()))
    return replace(stage, test_pred_std_mm=spread, layer=layer)


def _effects_report(selection, elastic, choice: LayerChoice) -> EffectsReport:
    if elastic is None:
        return EffectsReport(None if selection is None else selection.to_dict())
    notes = tuple(f"{fe.choice.label}.{n}: negative compliance {v:.3g} rad/(N*m) ({-v / s:.1f} std below zero): "
                  "not physical; check the link masses, payload and joint directions"
                  for fe in elastic.effects if fe.unit == "rad/(N*m)"
                  for n, v, s in zip(fe.param_names, fe.values, fe.std) if np.isfinite(s) and v < -3 * s)
    if choice.on_geometry:
        notes = (left_out_note(choice.without_effects),) + notes
    return EffectsReport(None if selection is None else selection.to_dict(), tuple(fe.to_dict() for fe in elastic.effects),
                         tuple(elastic.unidentifiable), elastic.sigma0, notes, elastic.condition_number)


def left_out_note(rival) -> str:
    """The one wording of effects left out of the final model (``robocal.layers.choice.WithoutEffects``)."""
    return (f"not in the final model: {', '.join(rival.effects)}; the geometry with a trend + GPR layer predicted "
            f"the calibration points better in cross-validation ({rival.cv_rms_mm:.4f} mm against "
            f"{rival.cv_rms_with_effects_mm:.4f} mm with the effects, paired t {rival.t:.1f})")


def _residual_cv_summary(choice: LayerChoice) -> ResidualCV | None:
    """The CV figure of the chosen (else the best) candidate layer against none (earlier report key); on the
    geometric model, the rival's figure against the model with its effects."""
    rival = choice.without_effects
    if choice.on_geometry:                                  # the layer against none, both on the geometric model
        return ResidualCV(choice.folds, rival.layer, rival.geometry_cv_rms_mm, rival.cv_rms_mm,
                          1.0 - rival.cv_rms_mm / rival.geometry_cv_rms_mm, rival.geometry_t,
                          rival.geometry_significant)
    cands = {k: v for k, v in choice.cv.items() if k != "none"}
    if not cands:
        return None
    kind = choice.kind if choice.kind in cands else min(cands, key=lambda k: cands[k]["cv_rms_mm"])
    a, b = choice.cv["none"]["cv_rms_mm"], cands[kind]["cv_rms_mm"]
    return ResidualCV(choice.folds, kind, a, b, 1.0 - b / a, cands[kind]["t"], cands[kind]["significant"])
