"""The campaign config: the YAML schema as frozen dataclasses (``schema``), the section reader whose errors name the
file and the key path (``reader``, ``bounded_yaml``), loading and the whole-config checks (``load``, ``sections``,
``checks``), the numerics a config describes (``cell_model``: nominal kinematics, measurement covariance,
calibration options; built once per command) and the simulation section as robocal objects (``simulation``).
Imports robocal, ``drivers.registry`` (driver option checks) and the shared leaves only."""
