"""``campaign select``: which N calibration rows of a measured campaign would have done.

A space-filling design (``robocal.design.optimal.space_filling``): rows chosen farthest-first in joint space, each joint
scaled by its lever (how far its angle moves the SMR), provided they determine every geometric parameter all the
rows determine; else the D-optimal criterion of ``plan.kind: optimal`` (the identification Jacobian of the geometry
and the pose-dependent effects, whitened by the calibration weights, with the major joints spread). The default
calibration has non-parametric layers (the joint-error GP, the GPR) that need the poses spread, not pushed to the
extremes that D-optimality favours; the choice was made by held-out prediction over a real and four simulated
campaigns (``bench/bench_select.py``). The subset keeps every row that is not a calibration row (test, check,
nest) and the chosen calibration rows, all in their original (measurement) order. Beyond ``CV_MAX_ROWS`` (200 000)
calibration rows they are chosen among a seeded subset of that many (memory and time bounded at any size), and the
forecast is judged at up to that many test rows.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from robocal.design.optimal import Forecast, criterion, forecast, space_filling
from robocal.effects.cv import capped_rows
from robocal.identify.identification import IdentificationError, register

from campaign.config.cell_model import CellModel
from campaign.data.dataset import Dataset
from campaign.errors import DataError

from .plausibility import check_dataset

SPACE_FILLING = "space-filling in joint space, each joint scaled by its lever"
D_FALLBACK = "D-optimal, joints spread (the space-filling rows left a geometric parameter undetermined)"
FORECAST_MAX_ROWS = 20_000      # the forecast of all rows (a Jacobian of every row and parameter) up to this size


@dataclass(frozen=True, eq=False)
class Selection:
    """The rows of the subset (N,) bool, and what the parameter uncertainty predicts of the subset's and of all
    calibration rows (``robocal.design.optimal.Forecast``, at the test rows; None for all rows beyond
    ``FORECAST_MAX_ROWS``)."""
    keep: np.ndarray
    n_chosen: int
    n_calib: int
    subset: Forecast
    everything: Forecast | None
    judged_at: str = "test rows"           # where the forecasts are evaluated: "test rows", else "calibration rows"
    effects_need: int = 0                  # rows that also determine every pose-dependent effect ``auto`` may take
    criterion: str = SPACE_FILLING         # how the rows were chosen


def select_rows(ds: Dataset, cell: CellModel, n: int, *, force: bool = False) -> Selection:
    """The subset with ``n`` calibration rows (see the module docstring); DataError when the data has
    another robot's joint count, fewer calibration rows, or ``n`` is below the identifiable geometric parameters
    + 10 % (the calibration's own minimum; the effects ``auto`` may take need more rows, which the record notes);
    the data-alone plausibility checks of ``reprocess`` first (``check_dataset``: PlausibilityError unless
    ``force``)."""
    check_dataset(ds, cell, force=force)
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
    pool = capped_rows(len(cal))                 # beyond CV_MAX_ROWS rows, chosen among a seeded subset of them
    pool = np.arange(len(cal)) if pool is None else pool
    crit = criterion(kin, q[pool], cov[cal[pool]], payload)
    need = math.ceil(1.1 * crit.identifiable_geometric)
    if n < need:
        raise DataError(ds.source, f"--points {n} cannot identify the {crit.identifiable_geometric} geometric "
                                   f"parameters these rows determine: at least {need} (identifiable + 10 %)")
    chosen, filled = space_filling(kin, crit, q[pool], n)
    chosen, crit_identifiable = pool[chosen], crit.identifiable
    del crit
    keep = ~ds.mask("calib")
    keep[cal[chosen]] = True
    test = np.flatnonzero(ds.mask("test") & np.all(np.isfinite(ds.q_deg), axis=1))
    at = test if len(test) else cal                       # judged at the test rows, else at the calibration rows
    at = at if (few := capped_rows(len(at))) is None else at[few]
    q_at, cov_at = np.radians(ds.q_deg[at]), cov[at]
    sub = forecast(kin, q[chosen], cov[cal][chosen], q_at, cov_at, payload)
    every = forecast(kin, q, cov[cal], q_at, cov_at, payload) if len(cal) <= FORECAST_MAX_ROWS else None
    how = (SPACE_FILLING if filled else D_FALLBACK) + ("" if len(pool) == len(cal) else
                                                         f", among a seeded subset of {len(pool)} of them")
    return Selection(keep, n, len(cal), sub, every, "test rows" if len(test) else "calibration rows",
                     math.ceil(1.1 * crit_identifiable), how)
