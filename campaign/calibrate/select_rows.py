"""``campaign select``: which N calibration rows of a measured campaign an optimal plan would have measured.

The same criterion as ``plan.kind: optimal`` (``robocal.design``), on the measured rows: the identification
Jacobian of the geometry and the pose-dependent effects at the measured joints, whitened by the calibration
weights, with the major joints spread over their ranges. The subset keeps every row that is not a calibration
row (test, check, nest) and the chosen calibration rows, all in their original (measurement) order.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from robocal.design import Forecast, criterion, d_optimal, forecast
from robocal.identify import IdentificationError, register

from campaign.config.cell_model import CellModel
from campaign.data.dataset import Dataset
from campaign.errors import DataError

from .plausibility import check_dataset

FORECAST_MAX_ROWS = 20_000      # the forecast of all rows (a Jacobian of every row and parameter) up to this size


@dataclass(frozen=True, eq=False)
class Selection:
    """The rows of the subset (N,) bool, and what the parameter uncertainty predicts of the subset's and of all
    calibration rows (``robocal.design.Forecast``, at the test rows; None for all rows beyond
    ``FORECAST_MAX_ROWS``)."""
    keep: np.ndarray
    n_chosen: int
    n_calib: int
    subset: Forecast
    everything: Forecast | None
    judged_at: str = "test rows"           # where the forecasts are evaluated: "test rows", else "calibration rows"
    effects_need: int = 0                  # rows that also determine every pose-dependent effect ``auto`` may take


def select_rows(ds: Dataset, cell: CellModel, n: int) -> Selection:
    """The subset with ``n`` calibration rows chosen by the optimal-plan criterion; DataError when the data has
    another robot's joint count, fewer calibration rows, or ``n`` is below the identifiable geometric parameters
    + 10 % (the calibration's own minimum; the effects ``auto`` may take need more rows, which the record notes);
    the data-alone plausibility checks of ``reprocess`` first (``check_dataset``: PlausibilityError unless
    forced)."""
    check_dataset(ds, cell)
    cal = np.flatnonzero(ds.mask("calib"))
    if len(cal) < n:
        raise DataError(ds.source, f"has {len(cal)} calibration rows, fewer than the {n} requested (--points)")
    q = np.radians(ds.q_deg[cal])
    if not np.all(np.isfinite(q)):
        raise DataError(ds.source, "calibration rows without joint values cannot be selected")
    p = ds.p_tracker_mm[cal]
    try:
        kin = register(cell.kinematics, q, p)
    except IdentificationError as exc:
        raise DataError(ds.source, f"cannot register the calibration rows: {exc}") from None
    payload = float(np.mean(ds.payload_kg[cal])) if ds.payload_kg is not None else cell.payload_kg
    cov = cell.weights(ds)[0]
    crit = criterion(kin, q, cov[cal], payload)
    need = math.ceil(1.1 * crit.identifiable_geometric)
    if n < need:
        raise DataError(ds.source, f"--points {n} cannot identify the {crit.identifiable_geometric} geometric "
                                   f"parameters these rows determine: at least {need} (identifiable + 10 %)")
    chosen = d_optimal(crit.A, n, crit.spread).chosen
    keep = ~ds.mask("calib")
    keep[cal[chosen]] = True
    test = np.flatnonzero(ds.mask("test") & np.all(np.isfinite(ds.q_deg), axis=1))
    at = test if len(test) else cal                       # judged at the test rows, else at the calibration rows
    q_at, cov_at = np.radians(ds.q_deg[at]), cov[at]
    sub = forecast(kin, q[chosen], cov[cal][chosen], q_at, cov_at, payload)
    every = forecast(kin, q, cov[cal], q_at, cov_at, payload) if len(cal) <= FORECAST_MAX_ROWS else None
    return Selection(keep, n, len(cal), sub, every, "test rows" if len(test) else "calibration rows",
                     math.ceil(1.1 * crit.identifiable))
