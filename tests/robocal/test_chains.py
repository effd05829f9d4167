"""Chains other than 6R (robocal.kinematics.chains, the redundancy of robocal.kinematics.ik): spherical joints, branch signs, the arm angle
of a seven-axis arm held by the IK, the solution nearest a rest pose, default link masses of any count."""
from __future__ import annotations

import numpy as np
import pytest

from robocal.kinematics.chains import (alignments, arm_angle_rad, branch_signs, spherical_joints, wrist_joints)
from robocal.kinematics.gravity import DEFAULT_LINK_MASSES_KG, GravityModel, default_link_masses
from robocal.effects.library import candidates
from robocal.kinematics.ik import solve_ik
from robocal.kinematics.models import Kinematics, chain, fk
from tests.cells import irb2600, ur10

IIWA = Kinematics.from_table("dh", [-90, 90, 90, -90, -90, 90, 0], [0] * 7, [360, 0, 420, 0, 400, 0, 126], [0] * 7,
                             [-170, -120, -170, -120, -170, -120, -175], [170, 120, 170, 120, 170, 120, 175],
                             p_flange_smr_mm=[0, 0, 39.4])


def _poses(rng, n=40):
    """Seven-axis poses off the branch boundaries (|q2|, |q4|, |q6| >= 20 deg)."""
    q = rng.uniform(-1.0, 1.0, (n, 7)) * np.radians([150, 100, 150, 100, 150, 100, 160])
    for j in (1, 3, 5):
        q[:, j] = np.sign(q[:, j]) * np.maximum(np.abs(q[:, j]), np.radians(20))
    return q


@pytest.mark.unit
def test_spherical_joints_and_alignments_follow_the_geometry():
    assert spherical_joints(IIWA) == (1, 3, 5)                 # shoulder, elbow, wrist of an LBR iiwa
    assert alignments(IIWA) == ((0, 2), (2, 4), (4, 6))
    assert wrist_joints(IIWA) == (5, 6, 7)
    assert spherical_joints(irb2600()) == (4,) and wrist_joints(irb2600()) == (4, 5, 6)
    assert spherical_joints(ur10()) == () and wrist_joints(ur10()) == ()   # offset wrist
    assert alignments(ur10()) == ((3, 5),)             # 6R keeps its J4 || J6 planner rule


@pytest.mark.unit
def test_branch_signs_are_kukas_status_bits():
    """The sides of the iiwa's alignments are the signs of A2, A4 and A6 (up to one fixed sign per joint)."""
    q = _poses(np.random.default_rng(1))
    ratio = branch_signs(IIWA, q) * np.sign(q[:, [1, 3, 5]])
    assert np.all(np.abs(ratio) == 1) and np.all(ratio == ratio[0])


@pytest.mark.unit
def test_ik_holds_the_arm_angle_and_the_elbow_turns_about_the_shoulder_wrist_line():
    """Held at an arm angle 25 deg away, the flange pose is unchanged and the elbow has turned by 25 deg about the
    shoulder-wrist line (an arm with a spherical shoulder and wrist: independent geometry)."""
    q0 = _poses(np.random.default_rng(2), 30)
    T0 = fk(IIWA, q0)
    psi0 = arm_angle_rad(IIWA, q0)
    target = psi0 + np.radians(25)
    res = solve_ik(IIWA, T0[:, :3, 3], T0[:, :3, :3], q0, point_mm=np.zeros(3), arm_angle_rad=target)
    ok = res.converged
    assert ok.mean() > 0.8
    np.testing.assert_allclose(fk(IIWA, res.q_rad[ok]), T0[ok], atol=1e-6)
    d = np.angle(np.exp(1j * (arm_angle_rad(IIWA, res.q_rad[ok]) - target[ok])))
    assert np.max(np.abs(d)) < 1e-8
    o0, o1 = chain(IIWA, q0[ok], full=False).origin, chain(IIWA, res.q_rad[ok], full=False).origin
    u = o0[:, 5] - o0[:, 1]
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    e0, e1 = o0[:, 3] - o0[:, 1], o1[:, 3] - o1[:, 1]
    p0 = e0 - np.sum(e0 * u, axis=1, keepdims=True) * u
    p1 = e1 - np.sum(e1 * u, axis=1, keepdims=True) * u
    turned = np.arctan2(np.sum(u * np.cross(p0, p1), axis=1), np.sum(p0 * p1, axis=1))
    np.testing.assert_allclose(np.degrees(turned), 25.0, atol=1e-6)


@pytest.mark.unit
def test_rest_pose_gives_the_nearest_solution_along_the_self_motion():
    """With q_rest the IK ends at the joint-space point of the self-motion nearest q_rest: no arm angle on a 1-deg
    scan of the self-motion comes nearer."""
    rng = np.random.default_rng(3)
    q0 = _poses(rng, 6)
    T0 = fk(IIWA, q0)
    q_rest = q0[0] + np.radians([10, -8, 25, 6, -12, 9, 15])
    res = solve_ik(IIWA, T0[:1, :3, 3], T0[:1, :3, :3], q0[:1], point_mm=np.zeros(3), q_rest_rad=q_rest)
    assert res.converged[0]
    np.testing.assert_allclose(fk(IIWA, res.q_rad), T0[:1], atol=1e-6)
    best = np.linalg.norm(res.q_rad[0] - q_rest)
    psi = arm_angle_rad(IIWA, res.q_rad) + np.radians(np.arange(-40.0, 40.5, 1.0))
    scan = solve_ik(IIWA, np.repeat(T0[:1, :3, 3], len(psi), 0), np.repeat(T0[:1, :3, :3], len(psi), 0), res.q_rad,
                    point_mm=np.zeros(3), arm_angle_rad=psi)
    dist = np.linalg.norm(scan.q_rad[scan.converged] - q_rest, axis=1)
    assert best <= dist.min() + 1e-6
    assert best < np.linalg.norm(q0[0] - q_rest) - 1e-3          # it moved towards the rest pose


@pytest.mark.unit
def test_default_link_masses_keep_the_six_axis_values_and_total_for_any_count():
    assert default_link_masses(6) == DEFAULT_LINK_MASSES_KG
    for n in (4, 5, 7):
        m = np.array(default_link_masses(n))
        assert len(m) == n and np.isclose(m.sum(), sum(DEFAULT_LINK_MASSES_KG)) and np.all(m >= 0)
    g = GravityModel.of_robot(7, mass_kg=29.9)
    assert len(g.link_masses_kg) == 7 and np.isclose(sum(g.link_masses_kg), 0.7 * 29.9)
    assert len(GravityModel().sized(7).link_masses_kg) == 7


@pytest.mark.unit
def test_effect_candidates_are_named_per_joint_and_coupling_needs_a_spherical_wrist():
    rng = np.random.default_rng(4)
    q = _poses(rng, 80)
    meta = {"payload_kg": np.ones(len(q))}
    cands, cannot = candidates(IIWA, q, meta, GravityModel.of_robot(7, mass_kg=29.9))
    labels = [c.label for c in cands]
    assert "axis_coupling(J5,6,7)" in labels
    assert {f"gear_cyclic(J{j}" for j in range(1, 8)} <= {lab.split(" ")[0].rstrip(")") for lab in labels}
    comp = next(c for c in cands if c.name == "joint_compliance")
    assert set(dict(comp.options)["joints"]) <= {1, 2, 3, 4}       # the main axes of a 7-axis arm: J1-J4
    ur = ur10()
    _, cannot = candidates(ur, rng.uniform(-2, 2, (80, 6)), meta, GravityModel.of_robot(6))
    skip = next(c for c in cannot if c["effect"] == "axis_coupling")
    assert "no spherical wrist" in skip["reason"]


@pytest.mark.unit
@pytest.mark.parametrize("convention", ["dh", "mdh"])
def test_hayati_beta_tilts_the_parallel_pair_in_either_convention(convention):
    """``hayati_joints: [2]`` (J2 || J3): a beta of 1 mrad on the row it flags tilts axis 3 against axis 2 by
    1 mrad and leaves the angle between axes 1 and 2 alone, in standard and modified DH alike."""
    al, a = [-90, 0, -90, 90, 90, 0], [150, 700, 115, 0, 0, 0]
    if convention == "mdh":
        al, a = [0] + al[:-1], [0] + a[:-1]
    kin = Kinematics.from_table(convention, al, a, [445, 0, 0, 795, 0, 85], [0, -90, 0, 0, 180, 0],
                                [-180] * 6, [180] * 6, hayati_joints=[2])
    assert kin.hayati == ((False, True) if convention == "dh" else (False, False, True)) + (False,) * (
        4 if convention == "dh" else 3)
    tilted = kin.with_(beta_rad=np.where(kin.hayati, 1e-3, 0.0))
    q = np.random.default_rng(5).uniform(-1, 1, (4, 6))
    angle = lambda k, i, j: np.arccos(np.clip(np.sum(chain(k, q).axis[:, i] * chain(k, q).axis[:, j], axis=1),  # noqa
                                              -1, 1))
    np.testing.assert_allclose(angle(tilted, 1, 2) - angle(kin, 1, 2), 1e-3, atol=1e-9)
    np.testing.assert_allclose(angle(tilted, 0, 1), angle(kin, 0, 1), atol=1e-12)


@pytest.mark.unit
def test_the_retry_rows_keep_the_flange_point_with_three_targets():
    """solve_on_branch re-seeds failed targets with their rows of the per-target options; the flange point (3,) is
    one for all, also when there are exactly three targets (it was sliced like a row: a crash of correct)."""
    from robocal.kinematics.ik import _rows

    kw = {"point_mm": np.array([0.0, 0.0, 150.0]), "q_rest_rad": np.zeros((3, 7)), "arm_angle_rad": np.arange(3.0)}
    rows = _rows(kw, np.array([0, 2]), 3)
    assert rows["point_mm"].shape == (3,) and rows["q_rest_rad"].shape == (2, 7)
    assert list(rows["arm_angle_rad"]) == [0.0, 2.0]
