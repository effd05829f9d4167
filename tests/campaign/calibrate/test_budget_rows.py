"""The error budget of reprocess beyond ``CV_MAX_ROWS`` fit rows (campaign/calibrate/budget_stage.py): its
linearised subset fits and noise share use the seeded subset of that many rows (memory bounded at any size; issue
36's 1M-row reprocess), said in its attribution; up to that many rows the budget is unchanged."""
from __future__ import annotations

import pytest

from campaign.calibrate import budget_stage
from campaign.calibrate.stages import calibrate_dataset
from campaign.config.load import load_cell
from tests.campaign.helpers import simulated_campaign, small_config

CAP = 100     # fit rows kept by the capped budget (the plan below fits about twice as many)


@pytest.mark.system
def test_the_budget_beyond_the_row_cap_fits_a_seeded_subset_and_says_so(tmp_path, monkeypatch):
    cell = load_cell(small_config(tmp_path, phenomena=True, **{"plan.grid.step_mm": 250}))
    ds = simulated_campaign(cell, seed=3)
    full = calibrate_dataset(ds, cell).report.budget
    seen = []
    model_budget = budget_stage.model_budget
    monkeypatch.setattr(budget_stage, "model_budget", lambda kin, cols, q, *a, **k: seen.append(len(q)) or
                        model_budget(kin, cols, q, *a, **k))
    monkeypatch.setattr(budget_stage, "CV_MAX_ROWS", CAP)
    capped = calibrate_dataset(ds, cell).report.budget
    assert seen == [CAP] and f"seeded subset of {CAP} of the" in capped.attribution
    assert "seeded subset" not in full.attribution
    assert capped.n_points == full.n_points and capped.nominal_rms_mm == full.nominal_rms_mm
    for c in full.components:             # end points exact; the effects' split from a smaller fit, close
        assert capped.component(c.name).rms_mm == pytest.approx(c.rms_mm, rel=0.25, abs=0.005), c.name
    assert capped.component(full.components[0].name).rms_mm == full.components[0].rms_mm
