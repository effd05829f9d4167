"""Write-back of chains other than 6R: the RAPID module of a robot on a track (the carriage in eax_a of both
target kinds) and of a seven-axis arm (axis 7 in the jointtarget's eax_a, the arm angle in the robtarget's), read back
by the project's RAPID parser; UR refuses other joint counts in one line; a correction that would change the arm's
configuration is refused naming the joint."""
from __future__ import annotations

import math

import numpy as np
import pytest

from campaign.correct.bounds import CorrectedTarget
from campaign.correct.configuration import configuration_reasons
from campaign.correct.rapid_module import render_rapid_module
from campaign.correct.ur_program import render_ur_json
from drivers.abb_axes import axes_layout
from drivers.emulators.rws_server import parse_literal, parse_module
from robocal.kinematics.chains import arm_angle_rad
from robocal.kinematics.models import Kinematics

pytestmark = pytest.mark.unit
LO, HI = (-170.0,) * 7, (170.0,) * 7


def _target(q, arm_angle=math.nan, tid="P1") -> CorrectedTarget:
    return CorrectedTarget(tid, tuple(q), tuple(q), (500.0, 100.0, 600.0), (0.0, 0.0, 1.0, 0.0), (0, -1, 0, 1), 0.01,
                           arm_angle_deg=arm_angle)


def _arrays(text: str) -> tuple[list, list]:
    syms = parse_module(text).symbols
    return parse_literal(syms["jt_cal"].value), parse_literal(syms["rt_cal"].value)


def test_track_carriage_is_eax_a_of_both_targets():
    q = (4321.5, 10.0, -20.0, 30.0, 40.0, 50.0, 60.0)
    text = render_rapid_module([_target(q)], q_min_deg=(0.0,) + LO[1:], q_max_deg=(6000.0,) + HI[1:],
                               axes=axes_layout(7, track=True))
    (jt,), (rt,) = _arrays(text)
    assert jt == [[10, -20, 30, 40, 50, 60], [4321.5] + [9e9] * 5] and rt[3] == [4321.5] + [9e9] * 5


def test_seven_axis_jointtarget_and_robtarget_carry_axis_7_and_the_arm_angle():
    q = (10.0, -20.0, 35.5, 30.0, 40.0, 50.0, 60.0)            # physical order: joint 3 is ABB's axis 7
    text = render_rapid_module([_target(q, arm_angle=-12.25)], q_min_deg=LO, q_max_deg=HI, axes=axes_layout(7))
    (jt,), (rt,) = _arrays(text)
    assert jt == [[10, -20, 30, 40, 50, 60], [35.5] + [9e9] * 5] and rt[3] == [-12.25] + [9e9] * 5
    with pytest.raises(ValueError, match="needs the arm angle"):
        render_rapid_module([_target(q)], q_min_deg=LO, q_max_deg=HI, axes=axes_layout(7))


def test_ur_refuses_seven_joints_in_one_line():
    with pytest.raises(ValueError) as err:
        render_ur_json([_target((0.0,) * 7)], q_min_deg=LO, q_max_deg=HI)
    assert "6 joints" in str(err.value) and "\n" not in str(err.value)


def test_a_configuration_change_is_refused_naming_the_joint():
    kin = Kinematics.from_table("dh", [-90, 90, 90, -90, -90, 90, 0], [0] * 7, [360, 0, 420, 0, 400, 0, 126],
                                [0] * 7, [-170] * 7, [170] * 7)
    q0 = np.radians([[0, 40, 0, -70, 0, 50, 0]] * 3)
    q = q0.copy()
    q[1, 5] = -q[1, 5]                                   # J6 through its branch boundary
    q[2, 2] += np.radians(0.1)                           # J3: a self-motion step, the arm angle moves
    why = configuration_reasons(kin, q, q0)
    assert why[0] is None and "J6" in why[1] and "arm angle" in why[2]
    moved = np.degrees(abs(arm_angle_rad(kin, q[2:]) - arm_angle_rad(kin, q0[2:])))[0]
    assert f"{moved:.3f}" in why[2]


def test_rapid_refuses_fewer_than_six_axes_in_one_line():
    with pytest.raises(ValueError) as err:
        render_rapid_module([_target((0.0,) * 5)], q_min_deg=LO[:5], q_max_deg=HI[:5], axes=axes_layout(5))
    assert "5-axis" in str(err.value) and "\n" not in str(err.value)
