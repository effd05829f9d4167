"""Identification of the geometry: from measured SMR positions to the parameters of the chain.

``identification`` (registration of the base and the SMR, identifiability, whitening, the robust and the least-squares
estimator), ``lm`` (the one Levenberg-Marquardt loop), ``parameters`` (``ParameterTable``: the identified values,
deltas and std) and ``screening`` (the measurement-fault screen that cannot eat structure). Imports ``kinematics``
and ``measure``.
"""
from robocal import lazy_exports

_HOMES = {                      # module -> the public names it holds
    "identification": ("CalibrationOptions", "CalibrationResult", "IdentificationError", "Unidentifiable",
                       "analyse_identifiability", "calibrate", "priority_order", "register", "register_tool",
                       "whiten", "whitening"),
    "lm": ("levenberg_marquardt",),
    "parameters": ("GEOMETRY_AND_EFFECTS", "ParameterTable"),
    "screening": ("NEAR_FRACTION", "ScreenResult", "joint_levers_mm", "near_neighbours", "nest_misreads", "reach_mm",
                  "screen", "smr_triangle"),
}
__all__ = [name for names in _HOMES.values() for name in names]
__getattr__ = lazy_exports(__name__, _HOMES)
