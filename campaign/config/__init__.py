"""The campaign config: the YAML schema as frozen dataclasses (``schema``), the section reader whose errors name the
file and the key path (``reader``, ``bounded_yaml``), loading and the whole-config checks (``load``, ``sections``,
``checks``), the numerics a config describes (``cell_model``: nominal kinematics, measurement covariance,
calibration options; built once per command) and the simulation section as robocal objects (``simulation``).
Imports robocal, ``drivers.registry`` (driver option checks) and the shared leaves only."""
from drivers import lazy_exports

_HOMES = {                      # module -> the public names it holds
    "cell_model": ("CellModel",),
    "load": ("load_cell",),
    "plan_schema": ("NestsConfig",),
    "schema": ("CampaignConfig", "MeasurementConfig"),
    "simulation": ("simulated_cell",),
}
__all__ = [name for names in _HOMES.values() for name in names]
__getattr__ = lazy_exports(__name__, _HOMES)
