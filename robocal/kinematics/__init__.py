"""Kinematics: where the chain puts the SMR, and what its structure implies.

``frames`` (rigid transforms on arrays, ``T_a_b`` naming), ``models`` (the chain models: DH, MDH, Hayati beta, a
linear track; forward kinematics and the identification Jacobian, batched over poses), ``chains`` (spherical joints,
alignments, branch signs, a seven-axis arm's arm angle: docs/chains.md), ``ik`` (batched iterative inverse
kinematics on a branch), ``gravity`` (the one gravity-torque model: lumped link masses, payload) and ``sweep``
(swept joint-interpolated paths: flange points, box tests, speed profiles). Imports no other room.
"""
from robocal import lazy_exports

_HOMES = {                      # module -> the public names it holds
    "chains": ("alignment_label", "alignment_margin_rad", "alignments", "arm_angle_rad", "branch_signs", "redundant",
               "spherical_joints", "wrap_rad", "wrist_joints"),
    "frames": ("fit_rigid", "inv_T", "make_T", "matrix_to_rotvec", "rotvec_to_matrix", "skew", "transform_points"),
    "gravity": ("G_MM_S2", "GravityModel", "default_link_masses", "gravity_torques", "lever_torques", "link_frames",
                "link_mass_torques", "link_masses"),
    "ik": ("branch_signature", "reachable", "solve_ik", "solve_on_branch"),
    "models": ("JACOBIAN_ROWS", "JOINT_PARAMS", "Kinematics", "ParamLayout", "apply_update", "chain", "fk",
               "identification_jacobian", "identification_jacobian_t", "jacobian_blocks", "joint_motion_columns",
               "parameter_difference", "smr_base", "smr_tracker", "within_limits"),
    "sweep": ("Boxes", "check_segments", "clearances_mm", "flange_points_base", "move_durations_s",
              "peak_speed_per_unit_s"),
}
__all__ = [name for names in _HOMES.values() for name in names]
__getattr__ = lazy_exports(__name__, _HOMES)
