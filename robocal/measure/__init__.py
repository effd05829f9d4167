"""What a measurement tells by itself, before any model is fitted to it.

``noise`` (the laser tracker's spherical uncertainty and the noise floor), ``repeats`` (repeated poses and the floor
they measure), ``approach`` (the sign of each joint's last motion), ``readback`` (commanded versus read-back
joints), ``drift`` (the tracker's registration drift from fixed reference nests) and ``stats`` (max / mean / RMS
of an error, the significance of a held-out gain and the t, chi^2 and F tail probabilities). Imports ``kinematics`` (frames).
"""
from robocal import lazy_exports

_HOMES = {                      # module -> the public names it holds
    "approach": ("approach_signs", "moves_from_order", "next_approach"),
    "drift": ("DriftModel", "fit_drift", "nest_rounds"),
    "noise": ("RP_PER_SIGMA", "TrackerUncertainty", "cartesian_to_spherical", "noise_floor_mm", "noise_max_mm",
              "repeatability_sigma_mm"),
    "readback": ("ENCODER_NOISE_DEG", "prefer_commanded", "readback_statistics"),
    "repeats": ("noise_floor_from_repeats", "repeat_dof", "repeat_groups"),
    "stats": ("ErrorStats", "SIGNIFICANT_GAIN", "average_ranks", "chi2_sf", "error_stats", "f_isf", "f_sf",
              "paired_gain", "signed_rank_z", "t_sf", "welch_t"),
}
__all__ = [name for names in _HOMES.values() for name in names]
__getattr__ = lazy_exports(__name__, _HOMES)
