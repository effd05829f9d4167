"""The before/after workspace map of the calibration report (issue 31): both panels on one colour scale, one
colour bar, so the nominal and the calibrated errors can be compared by colour."""
import numpy as np
import pytest

pytest.importorskip("matplotlib")

from campaign.calibrate.calibration_report import COMPENSATED, NOMINAL  # noqa: E402
from campaign.report import html_figures  # noqa: E402


@pytest.mark.unit
def test_before_and_after_share_one_colour_scale():
    rng = np.random.default_rng(31)
    p = np.c_[rng.uniform(500, 1400, 40), rng.uniform(-300, 300, 40), rng.uniform(400, 1600, 40)]
    err = {NOMINAL: rng.uniform(0.2, 0.8, 40), COMPENSATED: rng.uniform(0.01, 0.07, 40)}
    fig = html_figures.workspace_map(p, err, 0.03)
    try:
        panels = [ax for ax in fig.axes if ax.collections and ax.get_title()]
        assert [ax.get_title() for ax in panels] == ["before: nominal model", "after: calibrated model"]
        limits = {(c.norm.vmin, c.norm.vmax) for ax in panels for c in ax.collections}
        want = (min(err[COMPENSATED].min(), err[NOMINAL].min()), max(err[COMPENSATED].max(), err[NOMINAL].max()))
        assert limits == {want}                                 # the same limits in both panels: both errors' range
        bars = [ax for ax in fig.axes if ax not in panels]
        assert len(bars) == 1 and "both panels" in bars[0].get_ylabel()
        assert any(line.get_ydata()[0] == 0.03 for line in bars[0].lines)    # the noise floor on the colour bar
    finally:
        import matplotlib.pyplot as plt
        plt.close(fig)
