"""Simulated IRB 2600 campaigns for the measurement-fault screen: the plan's grid (dense, fixed tool direction)
plus a few poses sampled sparsely at extreme configurations (|J1| 100-150 deg, J2 leaning far back), where strong
gravity compliance leaves structure a geometric model cannot fit; optionally isolated 1-3 mm faults on grid
points. Shared by tests/campaign/calibrate/test_robust_default.py and bench/bench_robust.py."""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from campaign.config.cell_model import CellModel
from campaign.config.simulation import simulated_cell
from campaign.config.load import load_config
from campaign.data.dataset import Dataset
from campaign.plan.build import build_plan
from robocal.effects.bases import joint_compliance
from robocal.identify.identification import CalibrationOptions, calibrate
from robocal.kinematics.models import smr_base, smr_tracker
from robocal.simulation.mock_cell import random_geometric_errors
from tests.campaign.helpers import ROOT

BASE = load_config(ROOT / "configs/irb2600.yaml")
CFG = replace(BASE, plan=replace(BASE.plan, test=replace(BASE.plan.test, count=40)))
CELL = CellModel.from_config(CFG)
KIN0 = CELL.kinematics
COMPLIANCE = np.array([3.3e-7, 6.7e-7])           # typical J2/J3 compliance, rad/(N*m)


@dataclass(frozen=True, eq=False)
class Campaign:
    """``ds`` the dataset (calib + test rows); ``fault`` (N,) rows given a gross error; ``sparse`` (N,) the
    extreme-pose rows."""
    ds: Dataset
    fault: np.ndarray
    sparse: np.ndarray


_PLAN = None


def _grid() -> tuple[np.ndarray, list[str]]:
    global _PLAN
    if _PLAN is None:
        _PLAN = build_plan(CELL)
    pts = [p for p in _PLAN.points if p.set in ("calib", "test")]
    return np.radians([p.q_deg for p in pts]), [p.set for p in pts]


def sparse_campaign(seed: int, fault_fraction: float = 0.0, compliance_scale: float = 4.0, n_sparse: int = 10,
                    n_sparse_test: int = 6, sag_mm_at_1m: float = 0.0) -> Campaign:
    """The plan's grid of the IRB 2600 config + ``n_sparse`` calib and ``n_sparse_test`` test poses at extreme
    configurations; truth: new random geometry per seed, J2/J3 compliance x ``compliance_scale`` and optionally a
    sag outside the effect library (``sag_mm_at_1m`` x (horizontal reach / 1 m)^2, down); ``fault_fraction`` of
    the grid's calib rows get a 1-3 mm error in a random direction."""
    rng = np.random.default_rng(seed)
    base = simulated_cell(CELL)
    truth = random_geometric_errors(KIN0, rng).with_(T_tracker_base=base.truth.T_tracker_base,
                                                      p_flange_smr_mm=base.truth.p_flange_smr_mm)
    effects = ((joint_compliance((2, 3)), compliance_scale * COMPLIANCE),) if compliance_scale else ()
    cell = replace(base, truth=truth, effects=effects)
    q_grid, sets = _grid()
    ns = n_sparse + n_sparse_test
    side = rng.choice([-1.0, 1.0])
    q_sparse = np.radians(np.column_stack([side * rng.uniform(100, 150, ns), rng.uniform(-85, -50, ns),
                                           rng.uniform(-60, 30, ns), rng.uniform(-90, 90, ns),
                                           rng.uniform(-100, 100, ns), rng.uniform(-180, 180, ns)]))
    q = np.vstack([q_grid, q_sparse])
    sets = sets + ["calib"] * n_sparse + ["test"] * n_sparse_test
    p, _ = cell.measure(q, rng, {"payload_kg": np.zeros(len(q))})
    if sag_mm_at_1m:
        reach_m = np.hypot(*smr_base(truth, q)[:, :2].T) / 1000.0
        p -= sag_mm_at_1m * reach_m[:, None] ** 2 * truth.T_tracker_base[:3, 2][None, :]
    fault = np.zeros(len(q), bool)
    grid_calib = np.flatnonzero(np.array(sets[:len(q_grid)]) == "calib")
    k = int(round(fault_fraction * len(grid_calib)))
    if k:
        rows = rng.choice(grid_calib, k, replace=False)
        d = rng.normal(size=(k, 3))
        p[rows] += d / np.linalg.norm(d, axis=1, keepdims=True) * rng.uniform(1.0, 3.0, (k, 1))
        fault[rows] = True
    sparse = np.arange(len(q)) >= len(q_grid)
    ds = Dataset(tuple(f"P{i:03d}" for i in range(len(q))), tuple(sets), np.degrees(q), p, source=f"sparse{seed}")
    return Campaign(ds, fault, sparse)


def plain_lm_test_errors(ds: Dataset) -> np.ndarray:
    """Held-out errors (N_test,) mm of plain LM on every calib row (no screen, no effects)."""
    q = np.radians(ds.q_deg)
    cal, test = ds.mask("calib"), ds.mask("test")
    p = ds.p_tracker_mm
    res = calibrate(KIN0, q[cal], p[cal], CELL.covariance(p[cal]), CalibrationOptions(method="lm"))
    return np.linalg.norm(p[test] - smr_tracker(res.kinematics, q[test]), axis=1)
