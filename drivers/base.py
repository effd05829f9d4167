"""The small device protocols the campaign runner talks to, and the driver error tree.

Drivers know protocols, not calibration. Joint values cross this boundary in degrees (what controllers
report), positions in mm in the tracker frame. Every driver method either returns or raises a
``DriverError`` subclass within its configured timeout; none blocks forever.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Mapping, Protocol, Sequence, runtime_checkable

import numpy as np


class DriverError(Exception):
    """Base of all driver failures; ``str()`` is one line naming the device."""


class DriverConfigError(DriverError):
    """Bad driver URL or options (input error: the CLI exits with 2)."""


class ConnectionLost(DriverError):
    """The link to the device dropped or timed out."""


class RobotError(DriverError):
    """The robot refused or failed a command."""


class RobotNotReady(RobotError):
    """Preflight failed: not in AUTO, motors off, mastership held elsewhere, program stopped, ..."""


class MotionError(RobotError):
    """A commanded motion did not complete (limit, collision, error raised by the controller program)."""


class TrackerError(DriverError):
    """A tracker measurement failed; ``kind`` tells the runner whether retrying can help."""
    kind = "error"


class BeamBroken(TrackerError):
    kind = "beam_broken"


class TargetNotFound(TrackerError):
    kind = "not_found"


class Unstable(TrackerError):
    kind = "unstable"


class TrackerTimeout(TrackerError):
    kind = "timeout"


class GarbageReply(TrackerError):
    kind = "garbage"


@dataclass(frozen=True)
class TrackerReading:
    """One tracker sample: SMR centre xyz (mm, tracker frame) at time t_s (s, the driver's clock)."""
    xyz_mm: tuple[float, float, float]
    t_s: float
    extra: Mapping[str, float] = field(default_factory=dict)


def average_samples(readings: Sequence[TrackerReading | Sequence[float]],
                    stability_mm: float) -> tuple[np.ndarray, float]:
    """Mean xyz (3,) mm and spread (max distance of a sample from the mean, mm) of N tracker samples.

    ``Unstable`` if the spread exceeds ``stability_mm``; ``ValueError`` if there are no readings.
    """
    if len(readings) == 0:
        raise ValueError("average_samples: no readings")
    xyz = np.array([r.xyz_mm if isinstance(r, TrackerReading) else r for r in readings], float)
    mean = xyz.mean(axis=0)
    spread = float(np.max(np.linalg.norm(xyz - mean, axis=1)))
    if spread > stability_mm:
        raise Unstable(f"readings spread {spread:.4f} mm > stability limit {stability_mm:.4f} mm")
    return mean, spread


@dataclass(frozen=True, slots=True)
class MotionLimits:
    """Speed caps a robot driver enforces before any command leaves the process.

    ``max_tcp_speed_mm_s``: TCP speed cap (mm/s); ``max_joint_speed_pct``: cap on every joint's speed in percent
    of the robot's rated speed (0 < pct <= 100).
    """
    max_tcp_speed_mm_s: float = 250.0
    max_joint_speed_pct: float = 100.0


@dataclass(frozen=True, slots=True)
class Payload:
    """Load on the flange: mass (kg) and centre of gravity in the flange frame (mm)."""
    mass_kg: float
    cog_flange_mm: tuple[float, float, float] = (0.0, 0.0, 0.0)


@runtime_checkable
class Clock(Protocol):
    def now(self) -> float: ...
    def sleep(self, seconds: float) -> None: ...


class SystemClock:
    """Wall-clock time for real cells."""
    def now(self) -> float:
        return time.time()

    def sleep(self, seconds: float) -> None:
        if seconds > 0:
            time.sleep(seconds)


@runtime_checkable
class Robot(Protocol):
    """A robot the runner can move point to point."""
    n_joints: int

    def connect(self) -> None:
        """Open the session and run the preflight checks (raise RobotNotReady with the reason)."""

    def move_joints(self, q_deg: Sequence[float]) -> None:
        """Move to joint target (deg) with a fine stop; return when in position, or raise."""

    def read_joints(self) -> tuple[float, ...]:
        """Actual joint values (deg)."""

    def stop(self) -> None:
        """Stop any motion now (best effort, never raises)."""

    def close(self) -> None:
        """Release the session (logout, mastership); idempotent."""

    # Optional capabilities (the runner checks with ``hasattr``; real drivers implement them):
    # def set_motion_limits(self, limits: MotionLimits) -> None: enforce the caps on every later command
    # def set_payload(self, payload: Payload) -> None: send the load data to the controller
    # def identity(self) -> Mapping[str, str]: vendor, model, controller_type, serial, software_version
    # def speed_override_pct(self) -> float | None: the controller's speed override, if readable
    # def joint_temperatures_c(self) -> Sequence[float] | None: joint (motor) temperatures, logged per point


@runtime_checkable
class Tracker(Protocol):
    """A laser tracker that measures the SMR on request."""

    def connect(self) -> None: ...

    def measure(self) -> TrackerReading:
        """One reading of the SMR, or a TrackerError."""

    def environment(self) -> Mapping[str, float]:
        """Latest environment readings (e.g. temp_c, pressure_hpa, humidity_pct); empty if none."""

    def close(self) -> None: ...

    # Optional capabilities (the runner checks with ``hasattr``):
    # def identity(self) -> Mapping[str, str]: vendor, model, serial, firmware
    # def reacquire(self, p_tracker_mm_guess: Sequence[float]) -> None: aim at a predicted SMR position and
    #     search (GoPosition + FindReflector or the protocol's equivalent) after a beam break; raises TrackerError
    # can_reacquire: bool (attribute/property): False when ``reacquire`` exists but the device cannot aim or search
    # def drain_events(self) -> list[dict]: the driver's own recovery steps since the last call ({"step": ..., ...}:
    #     reconnect, initialize, go_position, find_reflector, ...), written to the run log by the runner
    # TrackerReading.extra may carry the device's own statistics: "std_x_mm", "std_y_mm", "std_z_mm",
    #     "cov_xy_mm2", "cov_xz_mm2", "cov_yz_mm2" and environment values "temp_c", "pressure_hpa", "humidity_pct"
