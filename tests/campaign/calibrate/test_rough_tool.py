"""Registration before plausibility (issue 21): an SMR offset tens of millimetres off in the config is registered with
the base, reported with the value to configure, and changes nothing else; another robot's data are still refused."""
from __future__ import annotations


import numpy as np
import pytest

from campaign.config.load import load_cell
from campaign.data.dataset import Dataset
from campaign.data.interchange_csv import read_csv, write_csv
from campaign.calibrate.stages import calibrate_dataset
from tests.campaign.helpers import read_report, small_config
from tests.campaign.hostile import assert_one_line, cli, snapshot
from tests.cells import irb2600_poses, irb2600, make_cell, measure, ur10

TRUE_SMR = (0.36, -0.28, 40.4)

# ABB IRB 120-3/0.6 as standard DH in the convention of configs/irb2600.yaml, from the dimensions and axis ranges of
# ABB's product specification (document 3HAC035960-001): base to J2 290 mm, upper arm 270 mm, elbow offset 70 mm,
# forearm 302 mm, wrist centre to flange 72 mm.
IRB120_JOINTS = [
    {"alpha_deg": -90, "a_mm": 0, "d_mm": 290, "theta_deg": 0, "q_min_deg": -165, "q_max_deg": 165},
    {"alpha_deg": 0, "a_mm": 270, "d_mm": 0, "theta_deg": -90, "q_min_deg": -110, "q_max_deg": 110},
    {"alpha_deg": -90, "a_mm": 70, "d_mm": 0, "theta_deg": 0, "q_min_deg": -110, "q_max_deg": 70},
    {"alpha_deg": 90, "a_mm": 0, "d_mm": 302, "theta_deg": 0, "q_min_deg": -160, "q_max_deg": 160},
    {"alpha_deg": 90, "a_mm": 0, "d_mm": 0, "theta_deg": 180, "q_min_deg": -120, "q_max_deg": 120},
    {"alpha_deg": 0, "a_mm": 0, "d_mm": 72, "theta_deg": 0, "q_min_deg": -400, "q_max_deg": 400},
]
IRB120_PLAN = {"center_mm": [400, 0, 400], "size_mm": [200, 300, 200], "step_mm": 100}
# Universal Robots' published DH tables of the UR10e and the UR5 (CB-series): same structure as the UR10 (CB3)
UR10E_JOINTS = [{"alpha_deg": al, "a_mm": a, "d_mm": d, "theta_deg": 0, "q_min_deg": -360, "q_max_deg": 360}
                for al, a, d in zip([90, 0, 0, 90, -90, 0], [0, -613.27, -571.55, 0, 0, 0],
                                    [180.7, 0, 0, 174.15, 119.85, 116.55])]
UR5_JOINTS = [{"alpha_deg": al, "a_mm": a, "d_mm": d, "theta_deg": 0, "q_min_deg": -360, "q_max_deg": 360}
              for al, a, d in zip([90, 0, 0, 90, -90, 0], [0, -425, -392.25, 0, 0, 0],
                                  [89.159, 0, 0, 109.15, 94.65, 82.3])]


def ur10_campaign(path, n_calib=150, n_test=50, seed=0):
    """A UR10 campaign whose poses turn the flange (each joint +-35 deg around a working pose): interchange CSV."""
    rng = np.random.default_rng(seed)
    cell = make_cell(ur10(), rng, smr=TRUE_SMR)
    q = np.radians([-19, -88, 110, -23, 60, 0]) + np.radians(rng.uniform(-35, 35, (n_calib + n_test, 6)))
    p, _ = measure(cell, q, rng)
    ids = tuple(f"P{i:03d}" for i in range(len(q)))
    write_csv(path, Dataset(ids, ("calib",) * n_calib + ("test",) * n_test, np.degrees(q), p))
    return path


@pytest.fixture(scope="module")
def ur10_data(tmp_path_factory):
    return ur10_campaign(tmp_path_factory.mktemp("rough-tool") / "data.csv")


def _process(tmp_path, data, tool_z):
    """The report of the default processing with the SMR offset (0, 0, tool_z) in the config."""
    where = tmp_path / f"z{tool_z:g}"
    where.mkdir()
    cfg = small_config(where, "ur10", **{"tool.p_flange_smr_mm": [0.0, 0.0, tool_z]})
    return calibrate_dataset(read_csv(data), load_cell(cfg)).report


@pytest.mark.system
def test_rough_offsets_register_and_change_nothing_else(ur10_data, tmp_path):
    right = _process(tmp_path, ur10_data, TRUE_SMR[2])
    assert right.plausibility.tool.notes() == ()                            # within a few mm: nothing to say
    for off in (-84.0, 30.0, 90.0):
        rough = _process(tmp_path, ur10_data, TRUE_SMR[2] + off)
        tool = rough.plausibility.tool
        notes = tool.notes()
        assert tool.determined == 3
        assert len(notes) == 1 and "put [" in notes[0] and "tool.p_flange_smr_mm" in notes[0]
        assert abs(tool.difference_mm[0] - abs(off)) < 2.0
        np.testing.assert_allclose(tool.registered_mm, right.plausibility.tool.registered_mm, atol=1e-6)
        for stage, figures in right.stages.items():
            for key in ("rms_mm", "mean_mm", "max_mm"):
                got = getattr(rough.stages[stage].test, key)
                assert got == pytest.approx(getattr(figures.test, key), rel=0.01), (stage, off)
        assert not rough.plausibility.overridden


@pytest.mark.system
def test_the_terminal_prints_the_offset_to_configure(ur10_data, tmp_path, capsys):
    cfg = small_config(tmp_path, "ur10", **{"tool.p_flange_smr_mm": [0.0, 0.0, TRUE_SMR[2] + 90.0]})
    code, out, err = cli(capsys, "reprocess", ur10_data, "--config", cfg, "--out", tmp_path / "out")
    assert code == 0, err
    line = next(ln for ln in out.splitlines() if "tool.p_flange_smr_mm" in ln)
    registered = read_report(tmp_path / "out").plausibility.tool.registered_mm[0]
    assert f"put [{registered[0]:.1f}, {registered[1]:.1f}, {registered[2]:.1f}] in tool.p_flange_smr_mm" in line
    assert (tmp_path / "out" / "model.json").exists()


@pytest.mark.unit
@pytest.mark.parametrize("case,needle", [("irb2600_data_irb120_config", "belong to this robot"),
                                         ("ur10_data_ur10e_table", "not a calibration of this robot"),
                                         ("ur10_data_ur5_table", "belong to this robot")])
def test_another_robot_is_still_refused(case, needle, ur10_data, tmp_path, capsys):
    """Other models' DH tables, one of them (UR10e) so close that the SMR offset absorbs d6 and the base d1."""
    if case == "irb2600_data_irb120_config":
        qc, qt = irb2600_poses()
        rng = np.random.default_rng(3)
        p, _ = measure(make_cell(irb2600(), rng), np.vstack([qc, qt]), rng)
        data = tmp_path / "irb2600.csv"
        write_csv(data, Dataset(tuple(f"P{i:03d}" for i in range(len(p))), ("calib",) * len(qc) + ("test",) * len(qt),
                                np.degrees(np.vstack([qc, qt])), p))
        cfg = small_config(tmp_path, "irb2600", **{"robot.joints": IRB120_JOINTS, "robot.model": "ABB IRB 120-3/0.6",
                                                   "plan.grid": IRB120_PLAN})
    else:
        data = ur10_data
        grid = {"center_mm": [-500, -200, 300], "size_mm": [300, 300, 300], "step_mm": 150}
        cfg = small_config(tmp_path, "ur10", **{"robot.joints": UR10E_JOINTS if "ur10e" in case else UR5_JOINTS,
                                                "plan.grid": grid})
    before = snapshot(tmp_path)
    code, out, err = cli(capsys, "reprocess", data, "--config", cfg, "--out", tmp_path / "out")
    assert_one_line(code, out, err, 2, str(data), needle)
    assert snapshot(tmp_path) == before                                        # no report.json, no model.json
