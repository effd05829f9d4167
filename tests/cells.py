"""Shared simulated cells for tests and benches (nominal models written out independently of configs/)."""
from __future__ import annotations

import numpy as np

from robocal.kinematics.ik import solve_on_branch
from robocal.kinematics.models import Kinematics
from robocal.measure.noise import repeatability_sigma_mm
from robocal.simulation.mock_cell import SimulatedCell, random_geometric_errors

# seed 000 eq. 17, re-orthonormalised (the printed matrix has 6 decimals)
T_SEED000 = np.array([[-0.548100, 0.836354, -0.009874, 2180.859],
                      [-0.836050, -0.548172, -0.022956, 3795.221],
                      [-0.024612, -0.004326, 0.999687, -1145.211],
                      [0, 0, 0, 1.0]])
_U, _, _Vt = np.linalg.svd(T_SEED000[:3, :3])
T_SEED000[:3, :3] = _U @ _Vt


def irb2600() -> Kinematics:
    return Kinematics.from_table("dh", [-90, 0, -90, 90, 90, 0], [150, 700, 115, 0, 0, 0], [445, 0, 0, 795, 0, 85],
                                 [0, -90, 0, 0, 180, 0], [-180, -95, -180, -400, -120, -400],
                                 [180, 155, 75, 400, 120, 400], hayati_joints=[2], p_flange_smr_mm=[0, 0, 39.4])


def ur10() -> Kinematics:
    return Kinematics.from_table("dh", [90, 0, 0, 90, -90, 0], [0, -612, -572.3, 0, 0, 0],
                                 [127.3, 0, 0, 163.941, 115.7, 92.2], [0] * 6, [-360] * 6, [360] * 6,
                                 hayati_joints=[2, 3], p_flange_smr_mm=[0, 0, 40.0])


def tool_frame(z_dir, down=(0, 0, -1.0)) -> np.ndarray:
    """Flange orientation (3, 3) with z along z_dir and x as close as possible to ``down``."""
    z = np.asarray(z_dir, float) / np.linalg.norm(z_dir)
    x = np.asarray(down, float) - z * (z @ np.asarray(down, float))
    x /= np.linalg.norm(x)
    return np.stack([x, np.cross(z, x), z], axis=1)


def grid(center, size, step):
    ax = [np.arange(-size[i] / 2, size[i] / 2 + 1e-9, step) + center[i] for i in range(3)]
    return np.stack(np.meshgrid(*ax, indexing="ij"), -1).reshape(-1, 3)


def plan_poses(kin, center, size, step, z_dir, q_ref_deg, n_test=100, seed=0, down=(0, 0, -1.0)):
    """(q_calib, q_test) rad on q_ref's branch: grid vertices and random points in the same box."""
    R = tool_frame(z_dir, down)
    q_ref = np.radians(q_ref_deg)
    qc, ok = solve_on_branch(kin, grid(center, size, step), R, q_ref)
    rng = np.random.default_rng(seed)
    c, s = np.asarray(center, float), np.asarray(size, float)
    qt, okt = solve_on_branch(kin, rng.uniform(c - s / 2, c + s / 2, (3 * n_test, 3)), R, q_ref)
    return qc[ok], qt[okt][:n_test]


def irb2600_poses(seed=0):
    return plan_poses(irb2600(), [900, 0, 1000], [800, 1600, 1200], 200, [1, 0, -0.7], [0, 0, 0, 0, 45, 0], seed=seed)


def ur10_poses(seed=0):
    return plan_poses(ur10(), [-700, -300, 400], [600, 800, 600], 120, [-1, 0, -0.6], [0, -90, 90, -90, -90, 0],
                      seed=seed, down=(0, 0, -1.0))


def make_cell(nominal, rng, T_tracker_base=T_SEED000, smr=(0.3572, 0.2789, 39.4306), effects=(), rp_mm=0.04,
              scale=1.0):
    truth = random_geometric_errors(nominal, rng, scale).with_(T_tracker_base=T_tracker_base, p_flange_smr_mm=smr)
    return SimulatedCell(truth, effects=tuple(effects), repeatability_rp_mm=rp_mm)


def measure(cell, q, rng, meta=None):
    """Measured points and the full covariance (tracker + robot repeatability) used as weights."""
    p, cov = cell.measure(q, rng, meta)
    return p, cov + repeatability_sigma_mm(cell.repeatability_rp_mm) ** 2 * np.eye(3)
