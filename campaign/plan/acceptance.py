"""The config's ``acceptance`` criterion against the noise floor, before anything is measured (``validate``, ``plan``,
``run``): repeats are not known yet, so the floor is the one the specs predict (tracker uncertainty model + robot
repeatability, ``CellModel.noise_floor_mm``) at the plan's test targets, the tracker at
``tracker.position_in_base_mm`` (the base origin when unknown, as the plan's forecast takes it). The report states
the same against the measured floor (``campaign.calibrate.summary.verdict``)."""
from __future__ import annotations

import numpy as np

from campaign.config.cell_model import CellModel
from campaign.io.quantities import floor_mm
from robocal.noise import noise_max_mm

from .poses import test_targets


def predicted_floor_mm(cell: CellModel) -> float:
    """The specs' noise floor (mm, 3-D RMS) at the plan's test targets (``plan.test``, in the grid box)."""
    p_base, _ = test_targets(cell.config)
    tracker_at = np.asarray(cell.config.tracker.position_in_base_mm or (0.0, 0.0, 0.0), float)
    return cell.noise_floor_mm(p_base - tracker_at)


def acceptance_warnings(cell: CellModel) -> list[str]:
    """One line per ``acceptance`` bound that a perfect model would fail more often than not on the predicted noise
    alone, or why no verdict will come (no test points); [] without a criterion or when every bound is reachable."""
    cfg = cell.config
    acc, n = cfg.acceptance, cfg.plan.test.count
    if not acc.configured or cfg.plan.kind == "iso9283":
        return []
    if n == 0:
        return ["acceptance is set but plan.test.count is 0: without held-out test points there is no verdict"]
    floor = predicted_floor_mm(cell)
    why = (f"the noise floor the specs predict at the plan's {n} test points is {floor_mm(floor)} mm (tracker uncertainty "
           "+ robot repeatability)")
    lines = {"max_rms_mm": lambda: f"acceptance.max_rms_mm {acc.max_rms_mm:g} mm is below the noise floor: {why}",
             "max_mm": lambda: f"acceptance.max_mm {acc.max_mm:g} mm is below {noise_max_mm(floor, n):.3f} mm, the "
                               f"median largest of {n} errors of noise alone: {why}"}
    return [f"{lines[name]()}; a perfect model would fail it more often than not"
            for name in acc.below_noise(floor, n)]
