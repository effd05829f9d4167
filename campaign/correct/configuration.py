"""Corrected joints keep the arm's configuration (docs/chains.md): the same IK branch as the commanded joints and,
on a seven-axis arm, the same arm angle. A corrected target that would change either is refused with one line that
names the joint."""
from __future__ import annotations

import numpy as np

from robocal.kinematics.chains import arm_angle_rad, redundant, spherical_joints, wrap_rad
from robocal.kinematics.ik import branch_signature
from robocal.kinematics.models import Kinematics

ARM_ANGLE_TOL_DEG = 0.01      # a corrected seven-axis target keeps its arm angle to this
BRANCH_JOINTS_6R = ("J1 (shoulder)", "J3 (elbow)", "J5 (wrist)")   # the joints of robocal.kinematics.ik.branch_signature


def branch_joint_names(kin: Kinematics) -> tuple[str, ...]:
    """The joint that flips each column of ``branch_signature``."""
    if kin.n - kin.n_track == 6:
        return tuple(f"J{int(name[1]) + kin.n_track}{name[2:]}" for name in BRANCH_JOINTS_6R)
    return tuple(f"J{j + 1}" for j in spherical_joints(kin))


def configuration_reasons(kin: Kinematics, q_rad: np.ndarray, q_cmd_rad: np.ndarray) -> list[str | None]:
    """Per target: None when the corrected joints q (N, n) rad keep the configuration of the commanded joints q_cmd
    (N, n) rad, else why not (one line)."""
    q, q0 = np.atleast_2d(q_rad), np.atleast_2d(q_cmd_rad)
    flips = branch_signature(kin, q) != branch_signature(kin, q0)
    names = branch_joint_names(kin)
    moved = np.degrees(np.abs(wrap_rad(arm_angle_rad(kin, q) - arm_angle_rad(kin, q0)))) if redundant(kin) else \
        np.zeros(len(q))
    out: list[str | None] = []
    for i in range(len(q)):
        if flips[i].any():
            out.append(f"the correction would change the arm's configuration ({names[int(np.argmax(flips[i]))]} "
                       "crosses its branch boundary)")
        elif moved[i] > ARM_ANGLE_TOL_DEG:
            out.append(f"the correction would move the arm angle by {moved[i]:.3f} deg (J1-J7 self-motion; max "
                       f"{ARM_ANGLE_TOL_DEG:g} deg)")
        else:
            out.append(None)
    return out
