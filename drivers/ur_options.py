"""UR driver tables and options: controller modes, RTDE fields, rated speeds, nominal DH, ``UROptions``.

Shared by the parent (``drivers.ur``), the worker process (``drivers.ur_worker``) and the RTDE emulator.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Any, Mapping
from urllib.parse import urlsplit

from .base import DriverError, RobotError


ROBOT_MODES = {-1: "NO_CONTROLLER", 0: "DISCONNECTED", 1: "CONFIRM_SAFETY", 2: "BOOTING", 3: "POWER_OFF",
               4: "POWER_ON", 5: "IDLE", 6: "BACKDRIVE", 7: "RUNNING", 8: "UPDATING_FIRMWARE"}
SAFETY_MODES = {1: "NORMAL", 2: "REDUCED", 3: "PROTECTIVE_STOP", 4: "RECOVERY", 5: "SAFEGUARD_STOP",
                6: "SYSTEM_EMERGENCY_STOP", 7: "ROBOT_EMERGENCY_STOP", 8: "VIOLATION", 9: "FAULT",
                10: "VALIDATE_JOINT_ID", 11: "UNDEFINED_SAFETY_MODE", 12: "AUTOMATIC_MODE_SAFEGUARD_STOP",
                13: "SYSTEM_THREE_POSITION_ENABLING_STOP"}
ROBOT_MODE_RUNNING, SAFETY_MODE_NORMAL = 7, 1
RECEIVE_VARIABLES = ["timestamp", "actual_q", "actual_qd", "target_q", "actual_TCP_pose", "robot_mode",
                     "safety_mode", "safety_status_bits", "runtime_state", "robot_status_bits", "joint_temperatures",
                     "target_speed_fraction"]
PROTECTIVE_STOP, ROBOT_MODE_POWER_OFF, ROBOT_MODE_IDLE = 3, 3, 5
# rated speed of the slowest joint (rad/s) per model family: base and shoulder of the larger arms are 120 deg/s
RATED_JOINT_SPEED_RAD_S = {"UR3": math.pi, "UR5": math.pi, "UR10": math.radians(120), "UR16": math.radians(120),
                           "UR20": math.radians(120), "UR30": math.radians(120)}
TCP_SAMPLES, TCP_MARGIN = 48, 0.9      # path samples for the TCP speed bound; safety factor on the sampled bound
# nominal standard DH (m) of UR arms, published by Universal Robots: (d1..d6, a1..a6); alpha = (pi/2, 0, 0, pi/2,
# -pi/2, 0). Used only to bound the TCP speed along a joint move (mm-level model errors do not matter there).
UR_DH = {
    "UR3": ((0.1519, 0, 0, 0.11235, 0.08535, 0.0819), (0, -0.24365, -0.21325, 0, 0, 0)),
    "UR5": ((0.089159, 0, 0, 0.10915, 0.09465, 0.0823), (0, -0.425, -0.39225, 0, 0, 0)),
    "UR10": ((0.1273, 0, 0, 0.163941, 0.1157, 0.0922), (0, -0.612, -0.5723, 0, 0, 0)),
    "UR3e": ((0.15185, 0, 0, 0.13105, 0.08535, 0.0921), (0, -0.24355, -0.2132, 0, 0, 0)),
    "UR5e": ((0.1625, 0, 0, 0.1333, 0.0997, 0.0996), (0, -0.425, -0.3922, 0, 0, 0)),
    "UR10e": ((0.1807, 0, 0, 0.17415, 0.11985, 0.11655), (0, -0.6127, -0.57155, 0, 0, 0)),
    "UR16e": ((0.1807, 0, 0, 0.17415, 0.11985, 0.11655), (0, -0.4784, -0.36, 0, 0, 0)),
}
UR_DH_ALPHA = (math.pi / 2, 0.0, 0.0, math.pi / 2, -math.pi / 2, 0.0)
BOOL_OPTIONS = ("power_on", "unlock_protective_stop")
JOINT_SPEED_MAX_RAD_S, JOINT_ACCELERATION_MAX_RAD_S2 = 3.14, 40.0   # ur_rtde's argument limits


class InvalidTarget(RobotError, ValueError):
    """A joint target the driver refuses before sending anything (wrong length, NaN, inf)."""


@dataclass(frozen=True)
class UROptions:
    """Driver options (``robot.options`` in the campaign config); rad, rad/s, rad/s², s.

    ``speed_rad_s`` / ``acceleration_rad_s2``: moveJ speed and acceleration of the leading joint.
    ``frequency_hz``: RTDE rate, -1 = library default (125 Hz CB3, 500 Hz e-Series).
    ``settle_qd_rad_s`` / ``settle_hold_s`` / ``settle_band_deg``: settled when, over a window of ``settle_hold_s``,
    every joint's drift (slope of actual_q) is below the threshold and its spread stays within the band.
    ``in_position_tol_deg``: max |mean q - target| accepted as "in position" (deg, like the Robot protocol).
    ``power_on``: power on and release the brakes through the Dashboard at connect.
    ``unlock_protective_stop``: unlock a protective stop through the Dashboard before the next move (the
    controller refuses it for 5 s; retried for up to ``protective_stop_wait_s``); off = the operator unlocks.
    ``tool_radius_mm``: the TCP speed cap also holds for points this far from the TCP (SMR, tool body).
    ``stall_s``: standing still this long away from the target -> MotionError.
    ``settle_timeout_s``: in position but not settled this long -> MotionError.
    ``stale_after_s``: controller timestamp must advance within this, else ConnectionLost.
    ``stop_deceleration_rad_s2``: stopJ deceleration used by ``stop()``.
    ``connect_timeout_s`` / ``move_timeout_s`` / ``call_timeout_s``: hard parent-side limits (worker killed).
    ``worker_log``: file receiving the worker's (library's) output; default a temp file removed at close.
    """
    speed_rad_s: float = 0.5
    acceleration_rad_s2: float = 1.0
    frequency_hz: float = -1.0
    settle_qd_rad_s: float = 1e-4
    settle_hold_s: float = 0.5
    settle_band_deg: float = 0.02
    in_position_tol_deg: float = 0.01
    stall_s: float = 2.0
    settle_timeout_s: float = 10.0
    stale_after_s: float = 0.5
    stop_deceleration_rad_s2: float = 2.0
    connect_timeout_s: float = 20.0
    move_timeout_s: float = 120.0
    call_timeout_s: float = 5.0
    worker_log: str | None = None
    power_on: bool = False
    unlock_protective_stop: bool = False
    protective_stop_wait_s: float = 10.0
    tool_radius_mm: float = 200.0

    @classmethod
    def from_mapping(cls, url: str, options: Mapping[str, Any]) -> "UROptions":
        """Validated options; unknown keys and bad values raise DriverError naming the key."""
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(options) - known)
        if unknown:
            raise DriverError(f"{url}: unknown option(s) {', '.join(unknown)} (expected: {', '.join(sorted(known))})")
        values = {k: _option_value(url, k, v) for k, v in options.items()}
        opts = cls(**values)
        opts._check_ranges(url)
        return opts

    def _check_ranges(self, url: str) -> None:
        if not 0 < self.speed_rad_s <= JOINT_SPEED_MAX_RAD_S:
            raise DriverError(f"{url}: options.speed_rad_s must be in (0, {JOINT_SPEED_MAX_RAD_S}], "
                              f"got {self.speed_rad_s}")
        if not 0 < self.acceleration_rad_s2 <= JOINT_ACCELERATION_MAX_RAD_S2:
            raise DriverError(f"{url}: options.acceleration_rad_s2 must be in (0, {JOINT_ACCELERATION_MAX_RAD_S2}], "
                              f"got {self.acceleration_rad_s2}")
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name not in ("frequency_hz", "worker_log", *BOOL_OPTIONS) and not value > 0:
                raise DriverError(f"{url}: options.{f.name} must be > 0, got {value}")


def _option_value(url: str, key: str, value: Any) -> Any:
    if key == "worker_log":
        if value is not None and not isinstance(value, str):
            raise DriverError(f"{url}: options.worker_log must be a path string, got {value!r}")
        return value
    if key in BOOL_OPTIONS:
        if not isinstance(value, bool):
            raise DriverError(f"{url}: options.{key} must be true or false, got {value!r}")
        return value
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise DriverError(f"{url}: options.{key} must be a finite number, got {value!r}")
    return float(value)


# ================================================================================================ parent


def validate_options(url: str, options: Mapping[str, Any], **context: Any) -> None:
    """What ``open_robot`` checks, without starting the worker: the url (host only) and the options."""
    parts = urlsplit(url)
    try:
        port = parts.port
    except ValueError as exc:
        raise DriverError(f"{url}: {exc}") from None
    if parts.scheme != "ur-rtde" or not parts.hostname:
        raise DriverError(f"{url}: expected ur-rtde://<controller host>")
    if port is not None or parts.path not in ("", "/"):
        raise DriverError(f"{url}: ur_rtde uses the controller's fixed ports (29999, 30003, 30004); give only the host")
    UROptions.from_mapping(url, options or {})
    n = context.get("n_joints")
    if n is not None and int(n) != 6:
        raise DriverError(f"{url}: a UR arm has 6 joints, the config has {n}")
