"""The link form of gravity compliance offered once the lever form is taken (``robocal.effects.library.
LINKS_AFTER_LEVERS``): recovered on a truth campaign whose masses sit off the roll axes, through the default
calibration, where the lever points fall short."""
from __future__ import annotations

from pathlib import Path
from unittest import mock

import pytest

import robocal.effects.library as library
from campaign.calibrate.stages import calibrate_dataset
from campaign.config.load import load_cell
from campaign.data.source import load_source
from robocal.simulation.truth_cell import TruthProtocol, simulate
from tests.campaign.helpers import truth_csv

# issue 32's strong-compliance form, smaller: masses off the roll axes (the truth's lumped masses) at 3 x the
# industrial compliance, poses sparse far out
STRONG = TruthProtocol(n_calib=150, n_test=60, check_poses=4, sampling="sparse_extremes")
SEED = 44                                    # a development seed of the fourteenth protocol's looks


@pytest.mark.system
def test_the_link_form_is_taken_where_the_lever_points_fall_short(tmp_path: Path):
    camp = simulate(["joint_compliance"], SEED, STRONG, 3.0)
    csv, cfg = truth_csv(tmp_path, camp)
    ds, cell = load_source(csv).dataset, load_cell(cfg)
    with mock.patch.object(library, "LINKS_AFTER_LEVERS", False):
        off = calibrate_dataset(ds, cell).report
    on = calibrate_dataset(ds, cell).report
    assert off.effects.selection["taken"] == ["joint_compliance(J2,3 levers)"]
    assert "joint_compliance(J2,3 links)" in on.effects.selection["taken"]
    assert not any("levers" in t for t in on.effects.selection["taken"])     # the final check dropped the lever form
    assert on.final.test.rms_mm < 0.85 * off.final.test.rms_mm, (on.final.test.rms_mm, off.final.test.rms_mm)
    print(f"\nheld out: lever form {off.final.test.rms_mm:.4f} mm, link form {on.final.test.rms_mm:.4f} mm "
          f"(floor {on.noise_floor_mm:.4f})")
