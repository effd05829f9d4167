"""``campaign select``: which N calibration rows of a measured campaign an optimal plan would have measured.

The same criterion as ``plan.kind: optimal`` (``robocal.design``), on the measured rows: the identification
Jacobian of the geometry and the pose-dependent effects at the measured joints, whitened by the calibration
weights, with the major joints spread over their ranges. The subset keeps every row that is not a calibration
row (test, check, nest) and the chosen calibration rows, all in their original (measurement) order.
"""
from __future__ import annotations

import math

import numpy as np

from robocal.design import criterion, d_optimal
from robocal.identify import IdentificationError, register

from campaign.config.cell_model import CellModel
from campaign.data.dataset import Dataset
from campaign.errors import DataError


def select_rows(ds: Dataset, cell: CellModel, n: int) -> np.ndarray:
    """(N,) bool: the rows of the subset with ``n`` calibration rows chosen by the optimal-plan criterion;
    DataError when the data holds fewer calibration rows, or ``n`` is below the identifiable parameters + 10 %."""
    ds.require_joints(cell.kinematics.n)
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
    crit = criterion(kin, q, cell.weights(ds)[0][cal], payload)
    need = math.ceil(1.1 * crit.identifiable)
    if n < need:
        raise DataError(ds.source, f"--points {n} cannot identify the {crit.identifiable} parameters these rows "
                                   f"determine: at least {need} (identifiable + 10 %)")
    keep = ~ds.mask("calib")
    keep[cal[d_optimal(crit.A, n, crit.spread).chosen]] = True
    return keep
