"""The in-sample evidence of the effect selection (``robocal.effects.select.F_LEVEL``, off by default; issue 32's
seventeenth and eighteenth protocols did not keep it) wired through the default process: on 50 rows of a simulated
compliance + gear + drift campaign (seed 49, rule ``f``'s rows) it takes the truth's registration drift, which the
held-out evidence alone does not take at 50 rows on the lever form's path, and the held-out RMS falls (the
selection's second path, ``LINKS_PATH_GAIN``, off here: with it the held-out evidence takes the drift too)."""
from __future__ import annotations

from unittest import mock

import numpy as np
import pytest

import robocal.effects.select as select
from campaign.calibrate.select_adaptive import adaptive_rows
from campaign.calibrate.stages import calibrate_dataset
from tests.campaign.adaptive_forms import ADAPTIVE_FORMS

pytestmark = pytest.mark.system


def test_in_sample_evidence_takes_the_drift_the_held_out_evidence_misses(tmp_path):
    ds, cell = ADAPTIVE_FORMS["compliance+gear+drift"](tmp_path, 49)
    keep = ~ds.mask("calib")
    keep[np.asarray(adaptive_rows(ds, cell, 50, rule="f").order[:50])] = True
    rows = ds.with_order_context().subset(keep)
    fitted = {}
    for level, parts in ((None, True), (0.01, False)):
        with mock.patch.multiple(select, F_LEVEL=level, F_PARTS=parts, LINKS_PATH_GAIN=None):
            r = calibrate_dataset(rows, cell)
        fitted[level] = ([fe.choice.name for fe in r.model.effects], r.report.final.test.rms_mm)
    assert "registration_drift" not in fitted[None][0]
    assert "registration_drift" in fitted[0.01][0]
    assert fitted[0.01][1] < 0.95 * fitted[None][1]
