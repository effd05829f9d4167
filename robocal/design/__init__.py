"""Which poses to measure: optimal calibration experiments (``optimal``: information of a pose set, D-optimal and
space-filling orders, the predicted held-out RMS and the learning-curve forecast), candidate poses (``pool``) and the
adaptive batch chosen with the model fitted so far (``adaptive``). Imports ``kinematics``, ``identify`` and
``effects``.
"""
from robocal import lazy_exports

_HOMES = {                      # module -> the public names it holds
    "adaptive": ("Batch", "Coverage", "KernelTerm", "LinearTerm", "choose_batch", "learning_curve"),
    "optimal": ("Criterion", "Forecast", "criterion", "criterion_effects", "d_optimal", "design_columns", "forecast",
                "greedy_order", "lever_scaled", "prediction", "short_tour", "space_filling",
                "whiten_rows"),
    "pool": ("candidate_poses", "incidence_rad", "smr_base_and_axis", "tilted_rotations"),
}
__all__ = [name for names in _HOMES.values() for name in names]
__getattr__ = lazy_exports(__name__, _HOMES)
