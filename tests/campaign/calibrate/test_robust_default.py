"""The default pipeline against plain LM on data it was not written for: random joint configurations (not the
plan's grid) with geometric-only truth; the plan's grid with poses sampled sparsely at extreme configurations
under strong compliance, with and without isolated gross faults (tests/campaign/screen_campaigns.py)."""
import numpy as np
import pytest

from campaign.config.cell_model import CellModel
from campaign.config.simulation import simulated_cell
from campaign.config.load import load_cell
from campaign.data.dataset import Dataset
from campaign.calibrate.stages import geometric_fit, calibrate_dataset
from robocal.identify.identification import CalibrationOptions, calibrate
from robocal.kinematics.models import smr_tracker
from tests.campaign.helpers import ROOT

CELL = load_cell(ROOT / "configs/irb2600.yaml")
CFG = CELL.config
N_CAL, N_TEST = 120, 60


def simulated_dataset(seed: int):
    """Random configurations in a working range, measured by the simulated cell (new geometry per seed)."""
    rng = np.random.default_rng(seed)
    lo = np.radians([-60, -40, -60, -120, -100, -180])
    hi = np.radians([60, 70, 40, 120, 100, 180])
    q = rng.uniform(lo, hi, (N_CAL + N_TEST, 6))
    cell = simulated_cell(CELL)
    from robocal.simulation.mock_cell import random_geometric_errors
    cell = type(cell)(random_geometric_errors(CELL.kinematics, rng).with_(
        T_tracker_base=cell.truth.T_tracker_base, p_flange_smr_mm=cell.truth.p_flange_smr_mm),
        cell.effects, cell.tracker, cell.repeatability_rp_mm)
    p, _ = cell.measure(q, rng)
    sets = ["calib"] * N_CAL + ["test"] * N_TEST
    ds = Dataset(tuple(f"P{i:03d}" for i in range(len(q))), tuple(sets), np.degrees(q), p, source=f"sim{seed}")
    return ds, q, p


def plain_lm_test_rms(q, p):
    kin0 = CELL.kinematics
    cov = CELL.covariance(p[:N_CAL])
    res = calibrate(kin0, q[:N_CAL], p[:N_CAL], cov, CalibrationOptions(method="lm"))
    e = p[N_CAL:] - smr_tracker(res.kinematics, q[N_CAL:])
    return float(np.sqrt(np.mean(np.sum(e**2, axis=1))))


@pytest.mark.system
def test_default_is_never_worse_than_plain_lm_without_gross_outliers():
    ratios, excluded, extra = [], 0, 0
    for seed in range(20):
        ds, q, p = simulated_dataset(seed)
        rep = calibrate_dataset(ds, CELL).report
        ratios.append(rep.final.test.rms_mm / plain_lm_test_rms(q, p))
        excluded += len(rep.excluded_points)
        extra += len(rep.effects.selection["taken"]) + (rep.residual_choice.chosen != "none")
    print(f"default / plain LM held-out RMS over 20 seeds: max {max(ratios):.4f}, median {np.median(ratios):.4f}; "
          f"{excluded} points excluded, {extra} effects/layers taken")
    assert max(ratios) <= 1.03


@pytest.mark.system
def test_sparse_extreme_poses_are_kept_and_isolated_faults_excluded():
    """Property over 20 seeds (the plan's grid + 10 calib poses sampled sparsely at extreme configurations, J2/J3
    compliance x4): without faults no point is excluded and the held-out max equals plain LM's; with 5 % isolated
    1-3 mm faults on the grid every fault is excluded and nothing else."""
    from tests.campaign.screen_campaigns import CELL as GRID, plain_lm_test_errors, sparse_campaign
    caught = n_faults = 0
    for seed in range(20):
        c = sparse_campaign(seed)
        res = geometric_fit(c.ds, GRID)
        q, p, test = np.radians(c.ds.q_deg), c.ds.p_tracker_mm, c.ds.mask("test")
        e_default = np.linalg.norm(p[test] - smr_tracker(res.kinematics, q[test]), axis=1)
        e_lm = plain_lm_test_errors(c.ds)
        assert np.all(res.point_weights > 0), f"seed {seed}: clean points excluded"
        assert e_default.max() <= e_lm.max() + 1e-6        # 1 nm: LM's step tolerance from another start offset
        f = sparse_campaign(seed, fault_fraction=0.05)
        excluded = geometric_fit(f.ds, GRID).point_weights == 0
        fault = f.fault[f.ds.mask("calib")]
        assert np.array_equal(excluded, fault), f"seed {seed}: excluded {np.flatnonzero(excluded)}, faults " \
                                                f"{np.flatnonzero(fault)}"
        caught, n_faults = caught + int(np.sum(excluded & fault)), n_faults + int(fault.sum())
    print(f"20 seeds: no clean point excluded (sparse extreme poses included), held-out max = plain LM's; "
          f"{caught} of {n_faults} isolated faults excluded, nothing else")


@pytest.mark.system
def test_structure_is_kept_and_faults_found_under_strong_compliance():
    """J2/J3 compliance at 4x the typical value, grid + sparse extreme poses, 5 % faults, the whole default
    pipeline: every fault is excluded with its reason (nothing else), the model takes compliance and the held-out
    RMS falls well below the geometric stage's."""
    from tests.campaign.screen_campaigns import CELL as GRID, sparse_campaign
    for seed in (200, 201):
        c = sparse_campaign(seed, fault_fraction=0.05)
        rep = calibrate_dataset(c.ds, GRID).report
        excluded = {r.point_id: r.reason for r in rep.excluded_points}
        taken = rep.effects.selection["taken"]
        kinematic, final = rep.stages["kinematic"].test.rms_mm, rep.final.test.rms_mm
        print(f"seed {seed}: taken {taken}, excluded {len(excluded)} of {c.fault.sum()} corrupted; test RMS "
              f"kinematic {kinematic:.4f} -> final {final:.4f} mm")
        assert set(excluded) == {c.ds.point_id[i] for i in np.flatnonzero(c.fault)}
        assert all("isolated against its" in r and "near neighbours" in r for r in excluded.values())
        # the gravity form or a free mass distribution (since the CV's ridge at rank_tol^2, seed 201 takes the
        # lever form: final 0.0369 mm against 0.0360 with the gravity form)
        assert taken[0] in ("joint_compliance(J2,3)", "joint_compliance(J2,3 levers)", "joint_compliance(J2,3 links)")
        assert final < 0.7 * kinematic


@pytest.mark.system
def test_three_smr_dataset_reports_offsets_and_orientation():
    from dataclasses import replace
    from robocal.multi_smr.calibration import predict_multi
    offsets = np.array([[0.36, 0.28, 39.43], [90.0, 0.0, 50.0], [0.0, 90.0, 50.0]])
    cfg = replace(CFG, tool=replace(CFG.tool, p_flange_smr2_mm=tuple(offsets[1] + 0.4),
                                    p_flange_smr3_mm=tuple(offsets[2] - 0.4)))
    rng = np.random.default_rng(7)
    truth = simulated_cell(CELL).truth
    q = rng.uniform(np.radians([-60, -40, -60, -120, -100, -180]), np.radians([60, 70, 40, 120, 100, 180]), (160, 6))
    P = predict_multi(truth, offsets, q) + rng.normal(0, 0.01, (3, 160, 3))
    ds = Dataset(tuple(f"P{i}" for i in range(160)), tuple(["calib"] * 120 + ["test"] * 40), np.degrees(q), P[0],
                 p2_tracker_mm=P[1], p3_tracker_mm=P[2], source="sim3")
    multi = calibrate_dataset(ds, CellModel.from_config(cfg)).report.multi_smr
    print(multi.test, multi.orientation_error_arcsec)
    assert multi.n_smr == 3 and multi.converged
    angles = multi.orientation_error_arcsec
    assert angles.n == 40 and 0 < angles.mean <= angles.rms <= angles.max and angles.source is None
    assert all(v.rms_mm < 0.03 for v in multi.test.values())
