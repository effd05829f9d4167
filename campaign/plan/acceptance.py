"""The config's ``acceptance`` criterion against the noise floor, before anything is measured (``validate``, ``plan``,
``run``): repeats are not known yet, so the floor is the one the specs predict (tracker uncertainty model + robot
repeatability, ``CellModel.noise_floor_mm``) at the plan's test targets, the tracker at
``tracker.position_in_base_mm`` (the base origin when unknown, as the plan's forecast takes it). The report states
the same against the measured floor (``campaign.calibrate.summary.verdict``)."""
from __future__ import annotations

import numpy as np

from campaign.config.cell_model import CellModel
from campaign.io.quantities import floor_mm
from robocal.measure.noise import noise_max_mm

from .points import Plan
from .poses import test_targets


def predicted_floor_mm(cell: CellModel, p_base_mm: np.ndarray | None = None) -> float:
    """The specs' noise floor (mm, 3-D RMS) at test positions (N, 3) mm in the base frame: the plan's test points,
    or by default the config's test targets (``plan.test``, in the grid box; before unreachable ones are dropped)."""
    p_base = test_targets(cell.config)[0] if p_base_mm is None else np.asarray(p_base_mm, float).reshape(-1, 3)
    tracker_at = np.asarray(cell.config.tracker.position_in_base_mm or (0.0, 0.0, 0.0), float)
    return cell.noise_floor_mm(p_base - tracker_at)


def acceptance_warnings(cell: CellModel, plan: Plan | None = None) -> list[str]:
    """One line per ``acceptance`` bound that a perfect model would fail more often than not on the predicted noise
    alone, or why no verdict will come (no test points); [] without a criterion or when every bound is reachable.
    With the ``plan``, at its test points (what ``plan``'s forecast uses), else at the config's test targets."""
    cfg = cell.config
    acc = cfg.acceptance
    if not acc.configured or cfg.plan.kind == "iso9283":
        return []
    p_test = None if plan is None else [p.p_base_mm for p in plan.points if p.set == "test"]
    n = cfg.plan.test.count if p_test is None else len(p_test)
    where = "the config's" if plan is None else "the plan's"
    if n == 0:
        return [f"acceptance is set but {where} test points are none: without held-out test points there is no "
                "verdict"]
    floor = predicted_floor_mm(cell, p_test)
    why = (f"the noise floor the specs predict at {where} {n} test points is {floor_mm(floor)} mm (tracker "
           "uncertainty + robot repeatability)")
    lines = {"max_rms_mm": lambda: f"acceptance.max_rms_mm {acc.max_rms_mm:g} mm is below the noise floor: {why}",
             "max_mm": lambda: f"acceptance.max_mm {acc.max_mm:g} mm is below {noise_max_mm(floor, n):.3f} mm, the "
                               f"median largest of {n} errors of noise alone: {why}"}
    return [f"{lines[name]()}; a perfect model would fail it more often than not"
            for name in acc.below_noise(floor, n)]
