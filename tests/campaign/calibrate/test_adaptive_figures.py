"""Issue 32's goals on two of the protocol's simulated forms (seed 1, as ``bench/bench_select.py --adaptive`` prints
them): the adaptive replay's held-out RMS within 1.35 x all rows at 50 poses and 1.2 x at 100; and the forecast
learning curve (noise model + parameter priors, ``campaign.plan.learning``) against the held-out RMS measured on
the same prefixes."""
from __future__ import annotations

import numpy as np
import pytest

from campaign.calibrate.select_adaptive import adaptive_rows
from campaign.calibrate.stages import calibrate_dataset
from campaign.plan.learning import forecast_rms
from tests.campaign.adaptive_forms import ADAPTIVE_FORMS

pytestmark = pytest.mark.system


def _rms(ds, cell, rows=None) -> float:
    if rows is not None:
        keep = ~ds.mask("calib")
        keep[np.asarray(rows, int)] = True
        ds = ds.with_order_context().subset(keep)
    return float(calibrate_dataset(ds, cell).report.final.test.rms_mm)


# UR10-like seed 1 is at 1.342 at 50 poses, too close to 1.35 to assert across BLAS builds (bench_select figures)
@pytest.mark.parametrize("form", ["read-back lag", "IRB 4600-like (compliance + J3 gear + coupling)"])
def test_adaptive_replay_meets_the_goals(tmp_path, form):
    ds, cell = ADAPTIVE_FORMS[form](tmp_path, 1)
    everything = _rms(ds, cell)
    sel = adaptive_rows(ds, cell, 100)
    measured = [_rms(ds, cell, sel.order[:n]) for n in (50, 100)]
    r50, r100 = (m / everything for m in measured)
    fc = forecast_rms(cell, np.radians(ds.q_deg[sel.order]), np.radians(ds.q_deg[ds.mask("test")]), (50, 100))
    print(f"{form}, seed 1: all rows {everything:.4f} mm; adaptive 50 {r50:.3f} x, 100 {r100:.3f} x; measured "
          f"{measured[0]:.4f} / {measured[1]:.4f} mm, forecast {fc[0]:.4f} / {fc[1]:.4f} mm")
    assert r50 <= 1.35 and r100 <= 1.2
    assert all(abs(f / m - 1) < 0.25 for f, m in zip(fc, measured)), "forecast within 25 % of the measured"
