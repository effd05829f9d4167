"""The error budget of ``reprocess``: the report's stages (nominal -> kinematic -> + effects -> + residual layer)
on the test rows, split by cause with ``robocal.diagnose.budget`` (the same attribution as ``campaign
diagnose``)."""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from robocal.diagnose.budget import ErrorBudget, HeldOut, model_budget
from robocal.effects.cv import CV_MAX_ROWS, capped_rows
from robocal.kinematics.models import ParamLayout


def calibration_budget(predict, stage_models: list, geo, elastic, layer_kind: str, q: np.ndarray, p: np.ndarray,
                       cov: np.ndarray, cov_floor: np.ndarray, meta: dict, kept_rows: np.ndarray, test: np.ndarray,
                       floor_mm: float, sub, folds: int) -> ErrorBudget | None:
    """The budget on the test rows (None without test rows). ``predict(model, rows)`` the tracker-frame
    prediction of a stage model at rows; ``stage_models`` [(name, model)] of the report (nominal, kinematic,
    [elastic], compensated); ``geo`` the geometric fit; ``elastic`` the elastic fit or None; ``layer_kind`` the
    residual layer chosen ("none": no layer); ``cov`` (N, 3, 3) the fit's weights (covariance), ``cov_floor`` the
    measurement covariance (the floor's shape); ``meta`` the effects' metadata of every row, ``sub(meta, rows)``
    its rows; ``floor_mm`` the report's noise floor. Beyond ``CV_MAX_ROWS`` fit rows, the linearised subset fits
    and the noise share use the seeded subset of that many the other cross-validated choices use (said in the
    budget's ``attribution``): their memory and time stay bounded at any size."""
    rows = np.flatnonzero(test)
    if len(rows) < 5:
        return None
    models = dict(stage_models)
    kinematic = models["kinematic"]
    final = models.get("elastic", kinematic)
    err2 = {name: np.sum((p[rows] - predict(m, rows)) ** 2, axis=1) for name, m in models.items()}
    tr = np.trace(cov_floor[rows], axis1=1, axis2=2)
    held = HeldOut(q[rows], p[rows], sub(meta, rows), err2["nominal"], err2["kinematic"],
                   err2.get("elastic", err2["kinematic"]), None if layer_kind == "none" else err2["compensated"],
                   layer_kind, tr * floor_mm**2 / float(np.mean(tr)))
    layout = ParamLayout.of(geo.result.kinematics)
    cols = np.array([layout.index(n) for n in geo.result.identified], int)
    effects = () if elastic is None else tuple(elastic.effects)
    k = np.asarray(kept_rows)
    few = capped_rows(len(k), CV_MAX_ROWS)
    k = k if few is None else k[few]
    r_fit = p[k] - predict(final, k)
    n_params = len(cols) + sum(fe.values.size for fe in effects)
    budget = model_budget(geo.result.kinematics, cols, q[k], p[k], cov[k], sub(meta, k), effects, r_fit, n_params,
                          held, folds)
    if few is None:
        return budget
    return replace(budget, attribution=f"{budget.attribution}; fitted on a seeded subset of {len(k)} of the "
                                       f"{len(kept_rows)} calibration rows in the fit")
