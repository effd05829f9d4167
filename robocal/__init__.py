"""robocal: the numerics of robot calibration. Arrays in, arrays out: no files, no devices, no clock.

Rooms along the calibration's own flow, lowest first; a room imports only the rooms before it
(``tests/test_structure.py`` checks it):

    kinematics < measure < identify < effects < layers < multi_smr < correct < design < simulation < diagnose
    < iso9283

``kinematics`` (frames, chain models, structure, IK, gravity torques, swept paths), ``measure`` (what a measurement
tells by itself: tracker noise, repeats, approach, read-back, drift, error statistics), ``identify`` (registration,
identification, the fault screen), ``effects`` (physical effects and the one effect engine), ``layers`` (residual
layers and the calibrated model they complete), ``multi_smr`` (tools with two or three SMRs), ``correct`` (target
correction), ``design`` (which poses to measure), ``simulation`` (simulated cells), ``diagnose`` (the sim-to-real
gap) and ``iso9283`` (the standard's characteristics). Each room's ``__init__`` names what it offers (``__all__``);
its modules load on first use.
"""
import importlib


def lazy_exports(package: str, homes: dict[str, tuple[str, ...]]):
    """The ``__getattr__`` of a room's ``__init__``: each public name (``homes``: module -> its names) loads from
    its module the first time it is asked for, so that importing a room runs none of its modules."""
    where = {name: module for module, names in homes.items() for name in names}

    def load(name: str):
        if name not in where:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        return getattr(importlib.import_module(f"{package}.{where[name]}"), name)
    return load
