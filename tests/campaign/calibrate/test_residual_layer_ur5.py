"""The residual layer's rule on sparse real data: 10 seeded random 100-pose subsets of the public UR5 campaign
(tests/data/serial_robots_datasets, MIT), the DEFAULT process (configs/ur5.yaml), judged on its 20 random
held-out poses. Where the layer is kept by the one-standard-error rule without the t > 3 evidence of a claim, the
same calibration without a layer is worse on the held-out poses (measured with the joint-error GP layer: 2 such
subsets, RMS 0.0970 -> 0.0716 and 0.0998 -> 0.0820 mm, the joint GP kept at t 2.55 and 2.78; with GPR as the best
layer there were 3: 0.1079 -> 0.0998, 0.0989 -> 0.0858, 0.1120 -> 0.0926 mm). ``-s`` prints them."""
from __future__ import annotations

import numpy as np
import pytest
import yaml

from campaign.config.load import load_cell
from tests.campaign.helpers import ROOT, layer_kept_without_claim

pytestmark = pytest.mark.system

UR5 = ROOT / "tests" / "data" / "serial_robots_datasets" / "UR5"
CONFIG = ROOT / "configs" / "ur5.yaml"


def test_a_layer_kept_without_a_claim_still_predicts_the_held_out_poses(tmp_path):
    importers = pytest.importorskip("campaign.data.importers", reason="needs the UR5 importer (campaign import)")
    full = importers.import_target_dif(UR5 / "3D_UR5_uncalibrated_grid_cleaned.csv",
                                       UR5 / "3D_UR5_uncalibrated_random_cleaned.csv")
    cell = load_cell(CONFIG)
    d = yaml.safe_load(CONFIG.read_text())
    d.setdefault("calibration", {})["residual"] = "none"
    (tmp_path / "none.yaml").write_text(yaml.safe_dump(d, sort_keys=False))
    cell_none = load_cell(tmp_path / "none.yaml")
    cal = np.flatnonzero(full.mask("calib"))
    weak = []
    for seed in range(10):
        keep = ~full.mask("calib")
        keep[np.random.default_rng(seed).choice(cal, 100, replace=False)] = True
        case = layer_kept_without_claim(full.subset(keep), cell, cell_none, f"subset {seed}")
        if case is not None:
            weak.append(case)
    assert weak, "no subset where the layer was kept without a claim: the rule is not exercised"
    assert all(with_ < without for without, with_ in weak)
