"""Hardware adapters: the device protocols the campaign talks to and their error tree (``base``), drivers chosen
by URL (``registry``: ``mock://``, ``abb-rws://``, ``ur-rtde://``, ``tracker+socket://``, ``emscon://``), the
drivers themselves (``mock``, ``abb_rws`` on ``rws_client``, ``ur`` on ``ur_worker``, ``line_tracker`` on
``line_codec``/``line_profile``, ``emscon`` on ``emscon_protocol``), the ABB axis map (``abb_axes``) and the one
redaction of secrets in text (``redact``). Sub-rooms: ``rapid`` (RAPID text), ``emulators`` (controllers and
trackers on loopback, for tests and demos) and ``bridge`` (the line-protocol reference bridge).

Drivers know protocols, not calibration; they import robocal only for the simulated cell of the mock drivers. A
copy of this folder runs the bridge with the standard library alone, so this door imports nothing and loads each
name from its module on first use.
"""
import importlib


def lazy_exports(package: str, homes: dict[str, tuple[str, ...]]):
    """The ``__getattr__`` of a room's ``__init__``: each public name (``homes``: module -> its names) loads from
    its module the first time it is asked for. The doors of drivers' and campaign's rooms use it; robocal keeps
    its own copy (``robocal.lazy_exports``: the bridge runs from a copy of ``drivers/`` without robocal, and
    robocal imports nothing of drivers)."""
    where = {name: module for module, names in homes.items() for name in names}

    def load(name: str):
        if name not in where:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        return getattr(importlib.import_module(f"{package}.{where[name]}"), name)
    return load


_HOMES = {                      # module -> the public names it holds
    "abb_axes": ("AbbAxes", "axes_layout"),
    "base": ("BeamBroken", "Clock", "DriverConfigError", "DriverError", "MotionLimits", "Payload", "Robot",
             "SystemClock", "Tracker", "TrackerError", "TrackerReading", "Unstable", "average_samples",
             # optional capabilities (runtime-checkable Protocols) and their helpers
             "DrainsEvents", "EnforcesMotionLimits", "Identifies", "ReacquireSwitch", "Reacquires",
             "ReadsJointTemperatures", "ReadsSpeedOverride", "SelectsNest", "SelectsSmr", "Simulated",
             "TakesPayload", "Versioned", "backoff_s", "can_reacquire", "device_url"),
    "emscon_protocol": ("AU_DEGREE", "COMMAND_CT", "CS_RHR", "C_CLEAR_COMMAND_QUEUE", "C_FIND_REFLECTOR",
                        "C_GET_ENVIRONMENT_PARAMS", "C_GET_REFLECTOR", "C_GET_REFLECTORS", "C_GET_SYSTEM_SETTINGS",
                        "C_GET_SYSTEM_STATUS", "C_GO_POSITION", "C_INITIALIZE", "C_SET_COORDINATE_SYSTEM_TYPE",
                        "C_SET_ENVIRONMENT_PARAMS", "C_SET_MEASUREMENT_MODE", "C_SET_REFLECTOR",
                        "C_SET_STATIONARY_MODE_PARAMS", "C_SET_STATISTIC_MODE", "C_SET_SYSTEM_SETTINGS",
                        "C_SET_UNITS", "C_START_MEASUREMENT", "C_STOP_MEASUREMENT", "DEFAULT_PORT", "FramingError",
                        "HU_RH", "LU_MILLIMETER", "MM_STATIONARY", "PU_MBAR", "PacketReader", "RS_ALL_OK",
                        "RS_MEASUREMENT_STATUS_NOT_READY", "RS_METEO_DATA_OUT_OF_RANGE", "RS_NOT_IMPLEMENTED",
                        "RS_SENSOR_NOT_WARMED_UP", "RS_TRACKER_NOT_INITIALIZED", "RS_WRONG_PARAMETER", "SM_EXTENDED",
                        "SM_STANDARD", "SSC_MEAS_STATUS_NOT_READY", "SSC_MEAS_STATUS_READY", "TPS_INITIALIZED",
                        "TU_CELSIUS", "WMS_NOT_CONNECTED", "WMS_READ_AND_CALCULATE", "WMS_READ_ONLY",
                        "decode_command", "encode_error", "encode_meas_result", "encode_reply",
                        "encode_status_change"),
    "mock": ("MockTracker", "MockWorld"),
    "redaction": ("has_userinfo", "redact", "redact_url", "register_userinfo"),
    "registry": ("CellContext", "ROBOT_SCHEMES", "TRACKER_SCHEMES", "check_options", "open_robot", "open_tracker"),
    "ur_options": ("ROBOT_MODES", "SAFETY_MODES"),
}
__all__ = ["lazy_exports", *(name for names in _HOMES.values() for name in names)]
__getattr__ = lazy_exports(__name__, _HOMES)
