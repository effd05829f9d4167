"""closed_loop_step: the pure closed-loop update of verify (pseudo-target from the measured error + nominal IK)."""
import numpy as np
import pytest

from robocal.correct import closed_loop_step, tool_transform
from robocal.kinematics.ik import solve_ik
from robocal.kinematics.models import fk
from tests.cells import irb2600


def _setup(n=12, seed=3):
    kin = irb2600()
    T_tool = tool_transform(kin.p_flange_smr_mm)
    lo, hi = np.radians([-100, -30, -80, -120, 30, -120]), np.radians([100, 80, 30, 120, 100, 120])
    q = np.random.default_rng(seed).uniform(lo, hi, (n, 6))
    T = fk(kin, q) @ T_tool
    R_flange = T[:, :3, :3] @ T_tool[:3, :3].T
    return kin, T_tool, q, T[:, :3, 3], R_flange


@pytest.mark.unit
def test_matches_a_per_point_reference():
    kin, T_tool, q, p_target, R_flange = _setup()
    rng = np.random.default_rng(4)
    err = rng.normal(0.0, 0.5, q.shape[:1] + (3,))
    significant = rng.random(len(q)) < 0.6
    p_pseudo_old = p_target + 0.1
    q_new, p_pseudo = closed_loop_step(kin, T_tool, q, p_pseudo_old, err, significant, R_flange)
    for i in range(len(q)):                               # plain reference: one point at a time
        if not significant[i]:
            assert np.array_equal(q_new[i], q[i]) and np.array_equal(p_pseudo[i], p_pseudo_old[i])
            continue
        p_ref = (fk(kin, q[i:i + 1]) @ T_tool)[0, :3, 3] - err[i]
        q_ref = solve_ik(kin, p_ref[None], R_flange[i:i + 1], q[i:i + 1], point_mm=T_tool[:3, 3]).q_rad[0]
        np.testing.assert_allclose(p_pseudo[i], p_ref, atol=1e-12)
        np.testing.assert_allclose(q_new[i], q_ref, atol=1e-7)


@pytest.mark.unit
def test_one_step_removes_a_constant_measured_offset():
    kin, T_tool, q, p_target, R_flange = _setup()
    offset = np.array([0.8, -0.5, 0.3])                   # the real tool point = nominal + offset (base frame, mm)
    actual = lambda qq: (fk(kin, qq) @ T_tool)[:, :3, 3] + offset
    err = actual(q) - p_target
    q_new, _ = closed_loop_step(kin, T_tool, q, p_target, err, np.ones(len(q), bool), R_flange)
    assert np.linalg.norm(actual(q) - p_target, axis=1).min() > 0.9
    assert np.linalg.norm(actual(q_new) - p_target, axis=1).max() < 1e-3
