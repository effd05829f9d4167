"""The elastic stage: which physical effects the calibration takes and their joint fit with the geometry.

``reprocess`` (its ``elastic`` stage) and ``diagnose`` both call ``elastic_stage`` on the geometric fit of the
same prepared dataset, so the same CSV and config give the same accepted effects, the same values and the same
"after" figures in both reports. The effects come from ``calibration.effects`` (a list), or from the effect
engine (``robocal.effects.engine.run_engine``) under ``auto``, the default.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from robocal.measure.approach import approach_signs, moves_from_order
from robocal.effects.model import EffectChoice
from robocal.effects.cv import capped_rows
from robocal.effects.engine import EngineOptions, EngineResult, select_candidates
from robocal.effects.fit import calibrate_elastic
from robocal.kinematics.models import ParamLayout
from robocal.layers.calibrated_model import CalibratedModel
from robocal.identify.screening import ScreenResult

from campaign.config.cell_model import CellModel
from campaign.errors import DataError
from campaign.data.dataset import Dataset

from .prepare import MIN_CALIB_ROWS


def order_meta(ds: Dataset) -> dict:
    """What the measurement order gives each row of ``ds`` (rows in measurement order, as the interchange CSV
    defines them): approach signs, the signed last move and the move before (rad), the position in the order.
    Computed before any row is set aside, then subset with the rows; a subset of a campaign carries them from the
    full order (``Dataset.order_context``)."""
    n = len(ds)
    c = ds.order_context
    if c is not None:                       # a subset of a campaign: the places of its rows in the full order
        return {"approach": c.approach, "move": c.move_rad, "prev_move": c.prev_move_rad, "order": c.order}
    q = np.radians(ds.q_deg)
    move, prev = moves_from_order(q)
    return {"approach": approach_signs(q) if n > 1 else None, "move": move, "prev_move": prev,
            "order": np.arange(n, dtype=float)}


def effect_meta(ds: Dataset, cell: CellModel, rows=None, order: dict | None = None) -> dict:
    """Per-row metadata of the physical effects of the rows ``rows`` (default all): payload (kg; the tool's when
    the data has none), time (s) and temperature (deg C), and the ``order_meta`` (given, or from ``ds``)."""
    n = len(ds)
    pay = ds.payload_kg if ds.payload_kg is not None else np.full(n, cell.payload_kg)
    meta = {"payload_kg": np.asarray(pay, float), "t_s": None if ds.t_s is None else np.asarray(ds.t_s, float),
            "temp_c": None if ds.temp_c is None else np.asarray(ds.temp_c, float),
            **(order_meta(ds) if order is None else order)}
    return meta if rows is None else subset(meta, np.asarray(rows))


def effect_choices(cell: CellModel, kin, cols, q, p, cov, meta, rows=None) -> tuple[list[EffectChoice], object]:
    """(choices, selection or None) of ``calibration.effects`` around the geometric solution ``kin`` (identified
    ParamLayout columns ``cols``) of the points q (N, n) rad, p (N, 3) mm, cov (N, 3, 3) mm^2, ``meta``: the
    configured list, or what the effect engine takes under ``auto``. ``rows``: the rows of those arrays to choose
    on (default all); beyond the engine's ``max_rows`` only a seeded subset of them is gathered, the one the
    selection cross-validates (robocal.effects.select)."""
    spec = cell.config.calibration.effects
    if spec == "none":
        return [], None
    if spec != "auto":
        return [EffectChoice.of_dict({"name": s.name, "options": s.params}) for s in spec], None
    opts = EngineOptions(folds=cell.config.calibration.cv_folds)
    of_rows = None
    if rows is not None:
        of_rows = len(rows)
        few = capped_rows(of_rows, opts.max_rows, opts.seed)
        rows = np.asarray(rows) if few is None else np.asarray(rows)[few]
        q, p, cov, meta = q[rows], p[rows], cov[rows], subset(meta, rows)
    eng = select_candidates(kin, cols, q, p, cov, meta, cell.gravity, opts, of_rows=of_rows)
    return list(eng.taken), eng


def subset(meta: dict, rows) -> dict:
    """The per-row metadata ``meta`` of the rows ``rows`` (index or mask)."""
    return {k: (None if v is None else np.asarray(v)[rows]) for k, v in meta.items()}


@dataclass(frozen=True, eq=False)
class ElasticStage:
    """``choices`` taken (configured or selected), ``engine`` the selection under ``auto`` (else None),
    ``elastic`` their joint fit (None without effects), ``model`` the geometric or elasto-geometric model (with the
    record of its parameters: ``CalibratedModel.parameters``),
    ``kept_rows`` the rows fitted (after the second fault screen), ``screen`` that screen (or the geometric one),
    ``meta`` the per-row metadata of every dataset row, ``geometric`` the geometric model (``model`` without
    effects)."""
    choices: tuple[EffectChoice, ...]
    engine: EngineResult | None
    elastic: object
    model: CalibratedModel
    kept_rows: np.ndarray
    screen: ScreenResult | None
    meta: dict
    geometric: CalibratedModel


def elastic_stage(ds: Dataset, cell: CellModel, geo, order: dict, rescreen) -> ElasticStage:
    """The effects of the model on top of the geometric fit ``geo`` (``campaign.calibrate.stages.GeometricFit``) of ``ds``,
    ``order`` its ``order_meta``; ``rescreen(rows, residual_mm)`` the measurement-fault screen of calib rows."""
    result = geo.result
    q, p = np.radians(ds.q_deg), ds.p_tracker_mm
    cov_all = cell.weights(ds)[0]
    meta_all = effect_meta(ds, cell, order=order)
    kept = geo.rows[geo.keep]
    payload = cell.payload_kg
    cols = np.array([ParamLayout.of(result.kinematics).index(n) for n in result.identified], int)
    choices, engine = effect_choices(cell, result.kinematics, cols, q, p, cov_all, meta_all, kept)
    geometric = model = CalibratedModel(result.kinematics, None, None, (), payload, result.table())
    if not choices:
        return ElasticStage((), engine, None, model, kept, geo.screen, meta_all, geometric)

    def fit(rows):
        try:
            return calibrate_elastic(result.kinematics, cols, q[rows], p[rows], cov_all[rows], subset(meta_all, rows),
                                     choices, cell.options)
        except (np.linalg.LinAlgError, ValueError) as exc:
            raise DataError(ds.source, f"elasto-geometric calibration failed: {exc}") from None
    elastic = fit(kept)

    def elastic_model(el):                # the record: the geometry's std from the joint fit, deltas from nominal
        table = el.table(result.start, result.identified)
        return CalibratedModel(el.kinematics, None, None, el.effects, payload, table)
    model = elastic_model(elastic)
    final_screen = geo.screen
    if cell.config.calibration.outliers == "local":
        # screen again against the model with its effects: structure the geometry alone could not fit is no
        # reason to exclude a point (and a fault hidden by that structure shows now)
        rc = geo.rows
        final_screen = rescreen(rc, p[rc] - model.smr_tracker(q[rc], subset(meta_all, rc)))
        robust_rejected = ~geo.keep
        robust_rejected[[e.index for e in geo.screen.excluded]] = False      # IGG3/Huber zero weights only
        new_keep = final_screen.keep & ~robust_rejected
        if new_keep.sum() < MIN_CALIB_ROWS:
            final_screen = geo.screen
        elif not np.array_equal(new_keep, geo.keep):
            kept = rc[new_keep]
            elastic = fit(kept)
            model = elastic_model(elastic)
    return ElasticStage(tuple(choices), engine, elastic, model, kept, final_screen, meta_all, geometric)
