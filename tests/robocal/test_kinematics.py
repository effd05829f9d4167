import numpy as np
import pytest

from robocal.kinematics.models import (Kinematics, ParamLayout, apply_update, fk, identification_jacobian, joint_jacobian,
                                smr_tracker)
from tests.cells import T_SEED000, irb2600, ur10

pytestmark = pytest.mark.unit


def dh_reference(alpha, a, d, theta, q):
    """Independent standard-DH FK written from the textbook matrix (seed 000 eq. 1), one pose."""
    T = np.eye(4)
    for al, aa, dd, th, qi in zip(alpha, a, d, theta, q):
        t = th + qi
        ct, st, ca, sa = np.cos(t), np.sin(t), np.cos(al), np.sin(al)
        T = T @ np.array([[ct, -ca * st, sa * st, aa * ct], [st, ca * ct, -sa * ct, aa * st],
                          [0, sa, ca, dd], [0, 0, 0, 1]])
    return T


def test_irb2600_zero_pose():
    T = fk(irb2600(), np.zeros((1, 6)))[0]
    np.testing.assert_allclose(T[:3, 3], [1030, 0, 1260], atol=1e-9)
    np.testing.assert_allclose(T[:3, 2], [1, 0, 0], atol=1e-12)


def test_ur10_matches_published_dh():
    kin = ur10()
    # the UR10 zero pose from UR's published DH: x = a2 + a3, y = -(d4 + d6), z = d1 - d5
    np.testing.assert_allclose(fk(kin, np.zeros((1, 6)))[0, :3, 3], [-1184.3, -256.141, 11.6], atol=1e-9)
    rng = np.random.default_rng(3)
    q = rng.uniform(-np.pi, np.pi, (6, 6))
    T = fk(kin, q)
    alpha = np.radians([90, 0, 0, 90, -90, 0])
    for i in range(6):
        np.testing.assert_allclose(T[i], dh_reference(alpha, kin.a_mm, kin.d_mm, kin.theta_rad, q[i]), atol=1e-9)


def test_mdh_equals_dh_when_last_link_has_no_offset():
    dh = irb2600()
    mdh = dh.with_(convention="mdh", alpha_rad=np.r_[0, dh.alpha_rad[:-1]], a_mm=np.r_[0, dh.a_mm[:-1]])
    q = np.random.default_rng(0).uniform(-2, 2, (20, 6))
    np.testing.assert_allclose(fk(mdh, q), fk(dh, q), atol=1e-9)


def test_hayati_beta_rotates_about_y():
    kin = irb2600()
    q = np.zeros((1, 6))
    b = 1e-3
    tilted = kin.with_(beta_rad=np.r_[0, b, 0, 0, 0, 0])
    T0, T1 = fk(kin, q)[0], fk(tilted, q)[0]
    # the distal chain turns by b about frame 2's y axis
    angle = np.arccos(np.clip((np.trace(T0[:3, :3].T @ T1[:3, :3]) - 1) / 2, -1, 1))
    assert angle == pytest.approx(b, rel=1e-6)


def test_batched_equals_single():
    kin = irb2600()
    q = np.random.default_rng(1).uniform(-1, 1, (7, 6))
    batch = fk(kin, q)
    for i in range(7):
        np.testing.assert_allclose(fk(kin, q[i:i + 1])[0], batch[i], atol=1e-12)


@pytest.mark.parametrize("convention", ["dh", "mdh"])
@pytest.mark.parametrize("robot", [irb2600, ur10])
def test_identification_jacobian_matches_finite_differences(convention, robot):
    kin = robot().with_(convention=convention, T_tracker_base=T_SEED000, p_flange_smr_mm=[20.0, -10.0, 60.0])
    q = np.random.default_rng(2).uniform(-1.5, 1.5, (8, 6))
    p, J = identification_jacobian(kin, q)
    np.testing.assert_allclose(p, smr_tracker(kin, q), atol=1e-9)
    layout = ParamLayout.of(kin)
    h = 1e-6
    for j in range(layout.size):
        d = np.zeros(layout.size)
        d[j] = h
        num = (smr_tracker(apply_update(kin, d), q) - smr_tracker(apply_update(kin, -d), q)) / (2 * h)
        np.testing.assert_allclose(J[:, :, j], num, atol=2e-5, err_msg=layout.names[j])


def test_layout_names_every_parameter_once():
    layout = ParamLayout.of(irb2600())
    assert len(layout.names) == 24 + 1 + 6 + 3 == len(set(layout.names))
    assert "beta2" in layout.names and "beta3" not in layout.names


def test_joint_jacobian_matches_finite_differences():
    kin = ur10()
    q = np.random.default_rng(4).uniform(-2, 2, (5, 6))
    T, J = joint_jacobian(kin, q)
    h = 1e-7
    for i in range(6):
        dq = np.zeros(6)
        dq[i] = h
        Tp, Tm = fk(kin, q + dq), fk(kin, q - dq)
        pp = Tp[:, :3, :3] @ kin.p_flange_smr_mm + Tp[:, :3, 3]
        pm = Tm[:, :3, :3] @ kin.p_flange_smr_mm + Tm[:, :3, 3]
        np.testing.assert_allclose(J[:, :3, i], (pp - pm) / (2 * h), atol=1e-4)


def test_dict_round_trip():
    kin = irb2600().with_(T_tracker_base=T_SEED000, beta_rad=np.r_[0, 1e-4, 0, 0, 0, 0])
    back = Kinematics.from_dict(kin.to_dict())
    q = np.random.default_rng(5).uniform(-1, 1, (4, 6))
    np.testing.assert_allclose(smr_tracker(back, q), smr_tracker(kin, q), atol=1e-9)
