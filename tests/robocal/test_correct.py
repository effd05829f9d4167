import numpy as np
import pytest

from robocal.correct import (GENERATORS, correct, correct_ensemble, matrix_to_quat, next_pseudo_target, pose_errors,
                             project_so3, quat_mul, quat_to_matrix, tool_transform)
from robocal.effects.bases import joint_compliance
from robocal.kinematics.frames import make_T, rotvec_to_matrix
from robocal.kinematics.models import fk
from robocal.simulation.mock_cell import random_geometric_errors
from tests.cells import irb2600



def truth_model(seed=0):
    nominal = irb2600()
    truth = random_geometric_errors(nominal, np.random.default_rng(seed))
    comp = joint_compliance(form="trig")
    k = np.array([1e-3, 5e-4, 5e-4, 5e-4, 5e-4])
    T_tool = tool_transform(nominal.p_flange_smr_mm)
    return nominal, T_tool, lambda q: fk(truth, q + comp.basis(truth, q, {}).dq @ k) @ T_tool


def targets(nominal, T_tool, n=200, seed=1):
    lo, hi = np.radians([-120, -40, -100, -150, 20, -150]), np.radians([120, 100, 40, 150, 110, 150])
    q = np.random.default_rng(seed).uniform(lo, hi, (n, 6))
    return q, fk(nominal, q) @ T_tool


@pytest.mark.unit
@pytest.mark.parametrize("generator", GENERATORS)
def test_every_generator_compensates_position(generator):
    nominal, T_tool, ap = truth_model()
    q, Td = targets(nominal, T_tool)
    before = pose_errors(ap(q), Td)[0]
    c = correct(Td, q, ap, nominal, T_tool, generator=generator)
    assert before.mean() > 0.5
    assert np.quantile(c.pos_err_mm, 0.99) < 1e-3, generator
    if generator != "fixed":                     # orientation is compensated too (except by the fixed method)
        assert np.degrees(c.rot_err_rad).mean() < 0.02


@pytest.mark.system
def test_pose_error_function_and_ensemble_pick_the_best():
    nominal, T_tool, ap = truth_model(2)
    q, Td = targets(nominal, T_tool, 100, 3)
    single = [correct(Td, q, ap, nominal, T_tool, generator=g, error="pose") for g in ("multiply", "quaternion")]
    ens = correct_ensemble(Td, q, ap, nominal, T_tool, generators=("multiply", "quaternion"), error="pose")
    np.testing.assert_allclose(ens.error, np.minimum(single[0].error, single[1].error))
    assert set(ens.generator) <= {"multiply", "quaternion"}


@pytest.mark.unit
def test_exact_model_needs_no_iteration():
    nominal, T_tool, _ = truth_model()
    q, Td = targets(nominal, T_tool, 20)
    c = correct(Td, q, lambda qq: fk(nominal, qq) @ T_tool, nominal, T_tool)
    assert np.all(c.iterations == 0) and np.allclose(c.q_rad, q)


@pytest.mark.unit
def test_generators_are_fixed_points_at_the_target():
    rng = np.random.default_rng(4)
    R = rotvec_to_matrix(rng.normal(size=(5, 3)))
    Td = make_T(R, rng.normal(size=(5, 3)) * 500)
    Tp = make_T(rotvec_to_matrix(rng.normal(size=(5, 3)) * 0.1) @ R, rng.normal(size=(5, 3)) * 500)
    for g in GENERATORS:                          # actual == target: the pseudo-target must not move
        np.testing.assert_allclose(next_pseudo_target(g, Tp, Td, Td)[:, :3, 3], Tp[:, :3, 3], atol=1e-9)
        if g not in ("fixed",):
            np.testing.assert_allclose(project_so3(next_pseudo_target(g, Tp, Td, Td)[:, :3, :3]), Tp[:, :3, :3],
                                       atol=1e-9)


@pytest.mark.unit
def test_quaternion_update_is_eq19():
    rng = np.random.default_rng(5)
    Rp, Ra, Rd = (rotvec_to_matrix(rng.normal(size=(4, 3))) for _ in range(3))
    T = lambda R: make_T(R, np.zeros((4, 3)))
    got = next_pseudo_target("quaternion", T(Rp), T(Ra), T(Rd))[:, :3, :3]
    np.testing.assert_allclose(got, Rp @ np.swapaxes(Ra, 1, 2) @ Rd, atol=1e-12)   # q_p q_a* q_d
    q = matrix_to_quat(Rp)
    np.testing.assert_allclose(quat_to_matrix(q), Rp, atol=1e-12)
    np.testing.assert_allclose(quat_mul(q, q * [1, -1, -1, -1]), np.tile([1.0, 0, 0, 0], (4, 1)), atol=1e-12)
