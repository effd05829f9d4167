"""Registration of the base frame and the SMR offsets together (robocal.identify.identification.register_tool): a rough SMR offset
is a registration quantity, recovered from any start when the poses turn the flange, kept when they do not."""
import numpy as np
import pytest

from robocal.kinematics.frames import make_T, rotvec_to_matrix, transform_points
from robocal.identify.identification import register_tool
from robocal.kinematics.models import fk, smr_base
from tests.cells import T_SEED000, measure, make_cell, ur10, ur10_poses

pytestmark = pytest.mark.unit

TRUE_SMR = np.array([0.36, -0.28, 40.4])


def varied_poses(n, seed):
    """UR10 joint vectors (rad) around a working pose, each joint +-35 deg: the flange turns by tens of degrees."""
    rng = np.random.default_rng(seed)
    return np.radians([-19, -88, 110, -23, 60, 0]) + np.radians(rng.uniform(-35, 35, (n, 6)))


def geometric_cell(seed):
    return make_cell(ur10(), np.random.default_rng(seed), smr=tuple(TRUE_SMR))


@pytest.mark.parametrize("start_z", [40.0 - 84.0, 40.0 - 30.0, 40.0 + 90.0])
def test_a_rough_offset_is_recovered_from_any_start(start_z):
    cell = geometric_cell(0)
    q = varied_poses(300, 1)
    p, _ = measure(cell, q, np.random.default_rng(2))
    reg = register_tool(ur10().with_(p_flange_smr_mm=[0, 0, start_z]), q, p)
    assert reg.determined == 3
    ref = register_tool(ur10().with_(p_flange_smr_mm=TRUE_SMR), q, p)           # the right start: same answer
    np.testing.assert_allclose(reg.p_flange_smr_mm, ref.p_flange_smr_mm, atol=1e-6)
    np.testing.assert_allclose(reg.T_tracker_base, ref.T_tracker_base, atol=1e-6)
    # on the nominal geometry (the truth has seed 000 Table 2 errors) the offset is right within a millimetre
    assert np.linalg.norm(reg.p_flange_smr_mm[0] - TRUE_SMR) < 1.0


def test_exact_data_give_the_exact_offset_and_frame():
    kin = ur10().with_(p_flange_smr_mm=TRUE_SMR)
    q = varied_poses(50, 3)
    p = transform_points(T_SEED000, smr_base(kin, q))
    reg = register_tool(ur10().with_(p_flange_smr_mm=[0, 0, 0]), q, p)
    np.testing.assert_allclose(reg.p_flange_smr_mm[0], TRUE_SMR, atol=1e-8)
    np.testing.assert_allclose(reg.T_tracker_base, T_SEED000, atol=1e-8)


def test_one_flange_orientation_keeps_the_configured_offset():
    """A plan with a fixed SMR orientation cannot tell an offset from a base translation: nothing is registered."""
    qc, _ = ur10_poses()
    kin = ur10()
    p, _ = measure(geometric_cell(4), qc, np.random.default_rng(5))
    start = np.array([1.0, -2.0, 10.0])
    reg = register_tool(kin, qc, p, start)
    assert reg.determined == 0
    np.testing.assert_array_equal(reg.p_flange_smr_mm[0], start)


def test_gross_faults_do_not_move_the_offset():
    cell = geometric_cell(6)
    q = varied_poses(300, 7)
    p, _ = measure(cell, q, np.random.default_rng(8))
    clean = register_tool(ur10(), q, p).p_flange_smr_mm[0]
    rng = np.random.default_rng(9)
    bad = rng.choice(len(q), 15, replace=False)
    p_bad = p.copy()
    p_bad[bad] += rng.normal(0, 20.0, (15, 3))                                   # 5 % of the points 20 mm off
    reg = register_tool(ur10(), q, p_bad)
    assert np.linalg.norm(reg.p_flange_smr_mm[0] - clean) < 0.1
    assert np.all(reg.weights[bad] < 0.5)


def test_several_smrs_share_one_frame():
    kin = ur10()
    q = varied_poses(80, 10)
    offsets = np.array([[0.4, -0.3, 40.2], [60.1, 0.2, 35.0]])
    T = make_T(rotvec_to_matrix([0.02, -0.01, 2.0]), [3000.0, -400.0, 200.0])
    T_flange = fk(kin, q)
    P = np.stack([transform_points(T, transform_points(T_flange, o)) for o in offsets])
    reg = register_tool(kin, q, P, [[0, 0, 40.0], [50.0, 0, 40.0]])
    assert reg.determined == 6
    np.testing.assert_allclose(reg.p_flange_smr_mm, offsets, atol=1e-8)
    np.testing.assert_allclose(reg.T_tracker_base, T, atol=1e-8)
