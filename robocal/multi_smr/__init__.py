"""Tools with two or three SMRs: the 6D pose of a three-SMR tool from one measured and two GPR-predicted SMRs
(``three_smr_pose``, seed 003) and the calibration with one flange offset per SMR (``calibration``). Imports
``kinematics``, ``measure``, ``identify`` and ``layers`` (the GP).
"""
from robocal import lazy_exports

_HOMES = {                      # module -> the public names it holds
    "calibration": ("calibrate_multi_smr", "orientation_errors_arcsec"),
    "three_smr_pose": ("MultiSMRPoseEstimator", "SMRTool", "fit_points_pose"),
}
__all__ = [name for names in _HOMES.values() for name in names]
__getattr__ = lazy_exports(__name__, _HOMES)
