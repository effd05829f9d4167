"""Simulated cells, kept apart from the calibration and the diagnosis they serve as a reference for.

``mock_cell``: the simulated "real" robot behind the mock drivers and the recovery tests (nominal model + random
geometric errors + chosen effects of ``robocal.effects``, robot repeatability and laser-tracker noise).
``truth_cell``: the independent truth generator that tests the diagnosis: written from the physics, it imports
neither the diagnosis, the effect engine nor the effect bases (a test checks what importing it loads).

This package module imports nothing, so that importing ``truth_cell`` loads only what ``truth_cell`` imports.
"""
