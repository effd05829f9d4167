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

    # Optional capabilities: the Protocols below (the runner asks ``isinstance``): EnforcesMotionLimits,
    # TakesPayload, Identifies, ReadsSpeedOverride, ReadsJointTemperatures, Versioned, Simulated.


@runtime_checkable
class Tracker(Protocol):
    """A laser tracker that measures the SMR on request."""

    def connect(self) -> None: ...

    def measure(self) -> TrackerReading:
        """One reading of the SMR, or a TrackerError."""

    def environment(self) -> Mapping[str, float]:
        """Latest environment readings (e.g. temp_c, pressure_hpa, humidity_pct); empty if none."""

    def close(self) -> None: ...

    # Optional capabilities: the Protocols below (the runner asks ``isinstance``): Identifies, Reacquires (and
    # ReacquireSwitch), SelectsSmr, SelectsNest, DrainsEvents, Versioned, Simulated.
    # TrackerReading.extra may carry the device's own statistics: "std_x_mm", "std_y_mm", "std_z_mm",
    #     "cov_xy_mm2", "cov_xz_mm2", "cov_yz_mm2" and environment values "temp_c", "pressure_hpa", "humidity_pct"


# --------------------------------------------------------------------------
# optional capabilities: one small Protocol each; a driver has one when it has the method (or attribute)


@runtime_checkable
class EnforcesMotionLimits(Protocol):
    """A robot that enforces speed caps on every later command (the runner refuses to move one that cannot)."""

    def set_motion_limits(self, limits: MotionLimits) -> None: ...


@runtime_checkable
class TakesPayload(Protocol):
    """A robot that sends the load data (mass, centre of gravity) to its controller."""

    def set_payload(self, payload: Payload) -> None: ...


@runtime_checkable
class ReadsSpeedOverride(Protocol):
    """A robot whose controller speed override (percent) is readable (None: not now)."""

    def speed_override_pct(self) -> float | None: ...


@runtime_checkable
class ReadsJointTemperatures(Protocol):
    """A robot that reports joint (motor) temperatures, deg C (n,), logged per point (None: not now)."""

    def joint_temperatures_c(self) -> Sequence[float] | None: ...


@runtime_checkable
class Identifies(Protocol):
    """A device that tells what it is: a robot vendor, model, controller_type, serial, software_version; a tracker
    vendor, model, serial, firmware."""

    def identity(self) -> Mapping[str, str]: ...


@runtime_checkable
class Versioned(Protocol):
    """A driver that names its own version (a string, or a callable giving it), logged beside its class."""

    driver_version: object


@runtime_checkable
class Simulated(Protocol):
    """A simulated device: ``simulated_clock`` is the simulated cell's time, shared by its robot and tracker."""

    simulated_clock: Clock


@runtime_checkable
class Reacquires(Protocol):
    """A tracker that aims at a predicted position (mm, tracker frame) and searches there after a beam break
    (GoPosition + FindReflector or the protocol's equivalent); raises TrackerError when not found."""

    def reacquire(self, p_tracker_mm_guess: Sequence[float]) -> None: ...


@runtime_checkable
class ReacquireSwitch(Protocol):
    """A tracker whose ``reacquire`` depends on its configuration: ``can_reacquire`` False when it cannot aim or
    search (a driver with ``reacquire`` and without this attribute always can)."""

    can_reacquire: bool


@runtime_checkable
class SelectsSmr(Protocol):
    """A tracker that aims at SMR ``k`` (1, 2, 3) of a multi-SMR tool at the same stop."""

    def select_smr(self, k: int) -> None: ...


@runtime_checkable
class SelectsNest(Protocol):
    """A tracker that finds a reference nest by its id (``p_tracker_mm_guess``, mm tracker frame, a hint or None)."""

    def select_nest(self, nest_id: str, p_tracker_mm_guess: Sequence[float] | None = None) -> None: ...


@runtime_checkable
class DrainsEvents(Protocol):
    """A tracker that reports its own recovery steps since the last call (``{"step": ..., ...}``: reconnect,
    initialize, go_position, find_reflector, ...), written to the run log by the runner."""

    def drain_events(self) -> list[dict]: ...


def can_reacquire(tracker: object) -> bool:
    """Whether ``tracker`` can aim and search after a beam break (:class:`Reacquires`, not switched off)."""
    return isinstance(tracker, Reacquires) and (not isinstance(tracker, ReacquireSwitch) or bool(tracker.can_reacquire))


def device_url(device: object, default: str) -> str:
    """The device's ``url`` (how errors name it), else ``default``."""
    url = getattr(device, "url", None)
    return url if isinstance(url, str) else default


def backoff_s(faults: int) -> float:
    """Pause (s) after the ``faults``-th failed reading of a point: 0.2 s doubling per fault, at most 2 s."""
    return min(2.0, 0.2 * 2 ** (faults - 1))
