"""One effect engine: `diagnose` and `reprocess` give the same answer on the same CSV and config (no calibration
section: the defaults): the same accepted effects, the same parameter values (1e-9 relative) and the same "after"
RMS on the test rows as reprocess's elastic stage.

20 simulated campaigns of robocal/simulation/truth_cell.py (the failure classes of real campaigns and single effects) and the
measured campaigns of DATASETS (the public UR5 campaign). Adding a dataset is one line: ``Case(name, make)`` with
``make(tmp_path) -> (csv_path, config_path)``.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np
import pytest

from campaign.config.load import load_cell
from campaign.calibrate.diagnosis import diagnose_dataset
from campaign.data.importers import import_target_dif
from campaign.data.interchange_csv import read_csv, write_csv
from campaign.calibrate.stages import calibrate_dataset
from robocal.diagnose.selfcheck import FORMS, trial_setting
from robocal.simulation.truth_cell import TruthProtocol, simulate, small_arm_nominal
from tests.campaign.helpers import ROOT, truth_csv

SMALL = dict(n_calib=160, n_test=50, check_poses=6, check_repeats=4)


@dataclass(frozen=True)
class Case:
    name: str
    make: Callable


def _truth(kind: str, effects: tuple, seed: int) -> Case:
    def make(tmp_path):
        pr, small = trial_setting(kind, effects, seed)
        pr = TruthProtocol(**{**pr.__dict__, **SMALL})
        camp = simulate(effects, seed, pr, nominal=small_arm_nominal() if small else None)
        return truth_csv(tmp_path, camp, small_arm=small, **{"calibration.residual": "none"})
    return Case(f"{kind}-{'+'.join(effects)}-{seed}", make)


CAMPAIGNS = [_truth(kind, FORMS[kind][0], 500 + 10 * i + s) for i, kind in enumerate(FORMS) for s in range(3)]
CAMPAIGNS += [_truth("single", (e,), 600 + s) for s, e in enumerate(("joint_compliance", "backlash", "thermal_drift",
                                                                       "gear_cyclic", "axis_coupling"))]
def _target_dif(grid: Path, test: Path, config: Path) -> Callable:
    """A measured campaign in the target + dif layout (``campaign import target-dif``) with its config."""
    def make(tmp_path):
        write_csv(tmp_path / "data.csv", import_target_dif(grid, test))
        return tmp_path / "data.csv", config
    return make


UR5 = ROOT / "tests" / "data" / "serial_robots_datasets" / "UR5"
DATASETS: list[Case] = [       # measured campaigns, one line each
    Case("ur5-public", _target_dif(UR5 / "3D_UR5_uncalibrated_grid_cleaned.csv",
                                   UR5 / "3D_UR5_uncalibrated_random_cleaned.csv", ROOT / "configs" / "ur5.yaml")),
]


@pytest.mark.system
@pytest.mark.parametrize("case", CAMPAIGNS + DATASETS, ids=lambda c: c.name)
def test_diagnose_and_reprocess_take_the_same_effects_with_the_same_values(tmp_path, case):
    csv, cfg_path = case.make(tmp_path)
    cell = load_cell(cfg_path)
    rep = calibrate_dataset(read_csv(csv), cell).report
    diag = diagnose_dataset(read_csv(csv), cell).report
    fitted = rep.effects.fitted
    accepted = [f for f in diag["findings"] if f["accepted"]]
    print(case.name, [f["evidence"]["label"] for f in accepted], diag["final_test_rms_mm"])
    assert [f["evidence"]["label"] for f in accepted] == rep.effects.selection["taken"]
    assert [e["name"] for e in diag["effects"]] == [e["name"] for e in fitted]
    for mine, theirs in zip(diag["effects"], fitted):
        assert mine["options"] == theirs["options"]
        for name, row in theirs["params"].items():
            assert mine["params"][name]["value"] == pytest.approx(row["value"], rel=1e-9, abs=1e-300)
            if "stiffness_Nm_per_rad" in row:
                assert mine["params"][name]["stiffness_Nm_per_rad"] == pytest.approx(row["stiffness_Nm_per_rad"],
                                                                                     rel=1e-9)
    after = rep.stages["elastic" if fitted else "kinematic"].test.rms_mm
    assert diag["final_test_rms_mm"] == pytest.approx(after, rel=1e-9)
    assert diag["baseline_test_rms_mm"] == pytest.approx(rep.stages["kinematic"].test.rms_mm, rel=1e-9)
    assert np.isfinite(diag["unexplained_structure"]["excess_over_floor_mm"])
