"""Identification of the geometry: from measured SMR positions to the parameters of the chain.

``identification`` (registration of the base and the SMR, identifiability, the robust and the least-squares
estimator), ``lm`` (the one Levenberg-Marquardt loop and the ``Normal`` equations it works on), ``parameters``
(``ParameterTable``: the identified values, deltas and std; the geometric prior by unit), ``screening`` (the measurement-fault screen that cannot
eat structure) and ``whitened`` (per-point whitening; designs in row blocks, kept as their triangular factor).
Imports ``kinematics`` and ``measure``.
"""
from robocal import lazy_exports

_HOMES = {                      # module -> the public names it holds
    "identification": ("CalibrationOptions", "CalibrationResult", "IdentificationError", "Unidentifiable",
                       "analyse_identifiability", "calibrate", "priority_order", "register", "register_tool"),
    "lm": ("Normal", "levenberg_marquardt"),
    "parameters": ("GEOMETRY_AND_EFFECTS", "ParameterTable", "geometric_prior_sigma"),
    "screening": ("NEAR_FRACTION", "ScreenResult", "joint_levers_mm", "near_neighbours", "nest_misreads", "reach_mm",
                  "screen", "smr_triangle"),
    "whitened": ("DESIGN_ROWS", "DesignFactor", "r_factor", "whiten", "whiten_t", "whitening"),
}
__all__ = [name for names in _HOMES.values() for name in names]
__getattr__ = lazy_exports(__name__, _HOMES)
