"""Simulated cells, kept apart from the calibration and the diagnosis they serve as a reference for.

``mock_cell``: the simulated "real" robot behind the mock drivers and the recovery tests (nominal model + random
geometric errors + chosen effects of ``robocal.effects``, robot repeatability and laser-tracker noise).
``truth_cell``: the independent truth generator that tests the diagnosis: written from the physics, it imports
neither the diagnosis, the effect engine nor the effect bases (a test checks what importing it loads).

This package module loads none of its modules, so that importing ``truth_cell`` loads only what ``truth_cell`` imports.
"""
from robocal import lazy_exports

_HOMES = {                      # module -> the public names it holds
    "mock_cell": ("SimulatedCell", "random_geometric_errors", "readback_joints_deg", "tracker_drift_mm"),
    "truth_cell": ("LIBRARY_TRUTHS", "TruthCampaign", "TruthProtocol", "simulate", "small_arm_nominal"),
}
__all__ = [name for names in _HOMES.values() for name in names]
__getattr__ = lazy_exports(__name__, _HOMES)
