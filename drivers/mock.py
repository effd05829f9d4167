"""Mock robot and mock laser tracker for CI and demos, driven by the robocal simulator.

Both share a ``MockWorld``: the simulated cell (true geometry, effects), a virtual clock, the current
joint state and the SMR's realised position. Moves draw the robot's repeatability scatter; each
measurement draws the tracker's spherical-model error once per point (MPE-type errors do not average
out) plus a small per-sample jitter, so averaging samples behaves like a real tracker.
Fault injection (beam break, timeout, garbage) follows the configured probabilities.
A multi-SMR tool (seed 003): ``extra_smrs_flange_mm`` gives the true flange-frame centres of SMRs 2, 3, ...;
they move rigidly with SMR 1 (same repeatability scatter, own tracker error) and ``MockTracker.select_smr(k)``
chooses which SMR the following ``measure()`` calls read.
Real-cell phenomena (all off by default, seeded): read-back lag (``readback_lag_deg_per_deg``: the robot stands at
the commanded joints but reports ``q_cmd + lag * last move + N(0, readback_noise_deg)``), tracker-registration
drift (``tracker_drift``: every reading, SMR or nest, is displaced by ``u(t) (v + w x p)`` in the tracker frame)
and fixed reference nests (``nests``: id -> position in the base frame; ``MockTracker.select_nest`` aims at one).
Motion caps: ``MockRobot`` takes ``set_motion_limits`` like a real driver, times every joint move so that no
joint exceeds its share of the rated speed and neither the flange nor any SMR exceeds the TCP cap, and its
command layer refuses (``MotionError``) any move that would be faster; accepted commands are recorded in
``MockRobot.commands`` with their peak speeds. It also reports mock identity, payload and speed override.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, replace
from typing import Mapping, Sequence

import numpy as np

from robocal.measure.noise import repeatability_sigma_mm
from robocal.simulation.mock_cell import SimulatedCell, readback_joints_deg, tracker_drift_mm

from robocal.kinematics.sweep import move_durations_s, peak_speed_per_unit_s

from .base import (BeamBroken, GarbageReply, MotionError, MotionLimits, Payload, TargetNotFound, TrackerReading,
                   TrackerTimeout)

MOCK_SOFTWARE_VERSION = "mock-1"


@dataclass(frozen=True)
class MotionCommand:
    """One move that reached the mock controller: duration (s), peak flange/SMR speed (mm/s), joint speed (%)."""
    q_from_deg: tuple[float, ...]
    q_to_deg: tuple[float, ...]
    duration_s: float
    peak_tcp_mm_s: float
    joint_speed_pct: float


class VirtualClock:
    """Simulated campaign time (s) advanced by moves and waits; never really sleeps."""
    def __init__(self) -> None:
        self.t = 0.0

    def now(self) -> float:
        return self.t

    def sleep(self, seconds: float) -> None:
        self.t += max(0.0, float(seconds))


class MockWorld:
    """State shared by MockRobot and MockTracker."""

    def __init__(self, cell: SimulatedCell, seed: int = 0, *, motion_time_s: float = 0.0,
                 joint_speed_deg_s: float = 60.0, payload_kg: float = 0.0, faults: Mapping[str, float] | None = None,
                 jitter_mm: float = 0.002, q0_deg: Sequence[float] | None = None,
                 extra_smrs_flange_mm: Sequence[Sequence[float]] = (),
                 readback_lag_deg_per_deg: Sequence[float] | None = None, readback_noise_deg: float = 0.0,
                 tracker_drift: tuple | None = None, nests: Mapping[str, Sequence[float]] | None = None) -> None:
        self.cell = cell
        self.rng = np.random.default_rng(seed)
        self.fault_rng = np.random.default_rng(seed + 7919)
        self.clock = VirtualClock()
        self.motion_time_s = motion_time_s
        self.joint_speed_deg_s = joint_speed_deg_s
        self.payload_kg = payload_kg
        self.faults = dict(faults or {})
        self.jitter_mm = jitter_mm
        n = cell.truth.n
        self.q_deg = np.zeros(n) if q0_deg is None else np.asarray(q0_deg, float)
        self.approach = np.zeros(n)
        self.extra_cells = tuple(replace(cell, truth=cell.truth.with_(p_flange_smr_mm=np.asarray(p, float)))
                                 for p in extra_smrs_flange_mm)
        self.p_smr_tracker_mm = self._realise()
        self.point_error_mm = np.zeros(3)
        self.p_extra_tracker_mm = np.zeros((len(self.extra_cells), 3))     # SMRs 2, 3, ... (tracker frame)
        self.extra_error_mm = np.zeros((len(self.extra_cells), 3))
        self.moves = 0
        self.stopped = False
        self.readback_rng = np.random.default_rng(seed + 104729)       # own stream: enabling lag changes nothing else
        self.readback_lag = np.zeros(n) if readback_lag_deg_per_deg is None else np.asarray(readback_lag_deg_per_deg,
                                                                                             float)
        self.readback_noise_deg = float(readback_noise_deg)
        self.last_move_deg = np.zeros(n)
        self.q_read_deg = self.q_deg.copy()
        self.tracker_drift = tracker_drift          # (v_mm_per_h (3,), w_rad_per_h (3,), tau_s) or None
        self.nests = {str(k): np.asarray(v, float) for k, v in (nests or {}).items()}
        self.nest_rng = np.random.default_rng(seed + 15485863)

    def drift_mm(self, p_tracker_mm: np.ndarray) -> np.ndarray:
        """Apparent displacement (3,) mm of a point read at p_tracker_mm now (tracker-registration drift)."""
        if self.tracker_drift is None:
            return np.zeros(3)
        v, w, tau_s = self.tracker_drift
        return tracker_drift_mm(p_tracker_mm, self.clock.now(), v, w, tau_s)[0]

    def nest_tracker_mm(self, nest_id: str) -> np.ndarray:
        """True position (3,) mm of a nest in the tracker frame (undrifted)."""
        T = self.cell.truth.T_tracker_base
        return T[:3, :3] @ self.nests[nest_id] + T[:3, 3]

    def meta(self) -> dict:
        return {"t_s": np.array([self.clock.now()]), "payload_kg": np.array([self.payload_kg]),
                "approach": self.approach[None, :]}

    def _realise(self) -> np.ndarray:
        p = self.cell.true_smr_tracker(np.radians(self.q_deg)[None], self.meta())[0]
        s = repeatability_sigma_mm(self.cell.repeatability_rp_mm)
        self.scatter_mm = self.rng.normal(0.0, s, 3) if s > 0 else np.zeros(3)
        return p + self.scatter_mm

    def _realise_extra(self) -> None:
        """Extra SMRs: true positions + the same repeatability scatter as SMR 1, each with its tracker error."""
        if not self.extra_cells:
            return
        q = np.radians(self.q_deg)[None]
        p = np.array([c.true_smr_tracker(q, self.meta())[0] for c in self.extra_cells]) + self.scatter_mm
        cov = self.cell.tracker.covariance(p)
        self.p_extra_tracker_mm = p
        self.extra_error_mm = np.einsum("kij,kj->ki", np.linalg.cholesky(cov), self.rng.standard_normal(p.shape))

    def move(self, q_deg: np.ndarray, duration_s: float | None = None) -> None:
        """Go to q_deg in ``duration_s`` of virtual time (default: at the rated joint speed)."""
        delta = q_deg - self.q_deg
        self.approach = np.where(np.abs(delta) > 1e-9, np.sign(delta), self.approach)
        self.clock.sleep(float(np.max(np.abs(delta))) / self.joint_speed_deg_s if duration_s is None else duration_s)
        if self.motion_time_s > 0:
            time.sleep(self.motion_time_s)
        self.q_deg = q_deg.copy()
        self.last_move_deg = delta
        self.q_read_deg = readback_joints_deg(q_deg, delta, self.readback_lag, self.readback_noise_deg,
                                              self.readback_rng)
        self.p_smr_tracker_mm = self._realise()
        cov = self.cell.tracker.covariance(self.p_smr_tracker_mm[None])[0]
        self.point_error_mm = np.linalg.cholesky(cov) @ self.rng.standard_normal(3)
        self._realise_extra()
        self.moves += 1

    def fault(self, name: str) -> bool:
        p = self.faults.get(name, 0.0)
        return p > 0 and self.fault_rng.random() < p


class MockRobot:
    """A robot that moves instantly (or after ``motion_time_s``) inside its joint limits."""

    def __init__(self, world: MockWorld, url: str = "mock://robot", speed_override_pct: float = 100.0) -> None:
        self.world, self.url = world, url
        self.simulated_clock = world.clock          # campaign time of the simulated cell (Cell.clock)
        self.n_joints = world.cell.truth.n
        kin = world.cell.truth
        self.q_min_deg, self.q_max_deg = np.degrees(kin.q_min_rad), np.degrees(kin.q_max_rad)
        self.limits = MotionLimits()
        self.payload = Payload(world.payload_kg)
        self.override_pct = float(speed_override_pct)
        self.commands: list[MotionCommand] = []
        self.p_points_mm = np.vstack([np.zeros(3), kin.p_flange_smr_mm] +
                                     [c.truth.p_flange_smr_mm[None] for c in world.extra_cells])

    def set_motion_limits(self, limits: MotionLimits) -> None:
        """Caps for every later move (TCP mm/s > 0, joint percent in (0, 100])."""
        if not (limits.max_tcp_speed_mm_s > 0 and 0 < limits.max_joint_speed_pct <= 100):
            raise MotionError(f"{self.url}: invalid motion limits {limits}")
        self.limits = limits

    def set_payload(self, payload: Payload) -> None:
        if payload.mass_kg < 0:
            raise MotionError(f"{self.url}: negative payload {payload.mass_kg} kg")
        self.payload = payload

    def identity(self) -> Mapping[str, str]:
        return {"vendor": "mock", "model": "simulated robot", "controller_type": "mock controller",
                "serial": "MOCK-R-0001", "software_version": MOCK_SOFTWARE_VERSION}

    def speed_override_pct(self) -> float:
        return self.override_pct

    def move_duration_s(self, q_from_deg: np.ndarray, q_to_deg: np.ndarray) -> float:
        """The shortest move time (s) within the caps, at the rated joint speed x the joint percentage."""
        lim = self.limits
        return float(move_durations_s(self.world.cell.truth, np.radians(q_from_deg), np.radians(q_to_deg),
                                      self.p_points_mm, np.radians(self.world.joint_speed_deg_s)
                                      * lim.max_joint_speed_pct / 100.0, lim.max_tcp_speed_mm_s)[0])

    def command_move(self, q_deg: np.ndarray, duration_s: float) -> None:
        """The controller's command layer: refuses a move faster than the caps, else executes and records it."""
        q_from = self.world.q_deg
        span = float(np.max(np.abs(q_deg - q_from), initial=0.0))
        if span == 0.0:
            duration_s = max(duration_s, 0.0)
        elif not duration_s > 0:
            raise MotionError(f"{self.url}: refused a move of {span:.3f} deg in {duration_s} s")
        peak = float(peak_speed_per_unit_s(self.world.cell.truth, np.radians(q_from), np.radians(q_deg),
                                           self.p_points_mm)[0]) / duration_s if span else 0.0
        pct = 100.0 * span / duration_s / self.world.joint_speed_deg_s if span else 0.0
        lim = self.limits
        if peak > lim.max_tcp_speed_mm_s * (1 + 1e-9) or pct > lim.max_joint_speed_pct * (1 + 1e-9):
            raise MotionError(f"{self.url}: refused a move at {peak:.0f} mm/s, {pct:.0f} % joint speed "
                              f"(caps {lim.max_tcp_speed_mm_s:g} mm/s, {lim.max_joint_speed_pct:g} %)")
        self.commands.append(MotionCommand(tuple(q_from), tuple(q_deg), duration_s, peak, pct))
        self.world.move(q_deg, duration_s)

    def connect(self) -> None:
        self.world.stopped = False

    def move_joints(self, q_deg: Sequence[float]) -> None:
        q = np.asarray(q_deg, float)
        if q.shape != (self.n_joints,) or not np.all(np.isfinite(q)):
            raise MotionError(f"{self.url}: expected {self.n_joints} finite joint values, got {list(q_deg)}")
        bad = np.flatnonzero((q < self.q_min_deg) | (q > self.q_max_deg))
        if len(bad):
            j = bad[0]
            raise MotionError(f"{self.url}: joint {j + 1} target {q[j]:.3f} deg outside "
                              f"[{self.q_min_deg[j]:.1f}, {self.q_max_deg[j]:.1f}]")
        self.command_move(q, self.move_duration_s(self.world.q_deg, q))

    def read_joints(self) -> tuple[float, ...]:
        """The read-back joints (deg): the commanded ones, plus the simulated read-back lag and noise."""
        return tuple(float(v) for v in self.world.q_read_deg)

    def stop(self) -> None:
        self.world.stopped = True

    def close(self) -> None:
        pass


class MockTracker:
    """A tracker measuring the world's SMR with the spherical noise model and injected faults.

    With a non-mock ``robot`` (a real or emulated controller) it follows that robot: before measuring it reads
    the robot's joints and places the simulated SMR there, so a real robot can be dry-run without a tracker."""

    def __init__(self, world: MockWorld, url: str = "mock://tracker", robot=None) -> None:
        self.world, self.url = world, url
        self.simulated_clock = world.clock          # campaign time of the simulated cell (Cell.clock)
        self.robot = None if isinstance(robot, MockRobot) else robot
        self.smr = 1
        self.nest: str | None = None
        self.nest_error_mm = np.zeros(3)

    def follow(self) -> None:
        """Place the simulated robot at the followed robot's read-back joints (deg); it moves only if they differ."""
        q = np.asarray(self.robot.read_joints(), float)
        if q.shape != self.world.q_deg.shape or np.max(np.abs(q - self.world.q_deg)) > 1e-9:
            self.world.move(q)

    def connect(self) -> None:
        pass

    def select_smr(self, k: int) -> None:
        """Aim at SMR k (1 = the main SMR, 2.. = the world's extra SMRs) for the following measurements."""
        if not 1 <= k <= 1 + len(self.world.extra_cells):
            raise TargetNotFound(f"{self.url}: no SMR {k} on the tool (it has {1 + len(self.world.extra_cells)})")
        self.smr = k
        self.nest = None

    def select_nest(self, nest_id: str, p_tracker_mm_guess: Sequence[float] | None = None) -> None:
        """Aim at a fixed reference nest (the world's ``nests``) for the following measurements."""
        w = self.world
        if nest_id not in w.nests:
            raise TargetNotFound(f"{self.url}: no reference nest {nest_id!r}")
        self.nest = nest_id
        p = w.nest_tracker_mm(nest_id)
        cov = w.cell.tracker.covariance(p[None])[0]
        self.nest_error_mm = np.linalg.cholesky(cov) @ w.nest_rng.standard_normal(3)

    def measure(self) -> TrackerReading:
        w = self.world
        if self.robot is not None:
            self.follow()
        if w.fault("beam_break_probability"):
            raise BeamBroken(f"{self.url}: beam broken")
        if w.fault("timeout_probability"):
            raise TrackerTimeout(f"{self.url}: no reply")
        if w.fault("garbage_probability"):
            raise GarbageReply(f"{self.url}: unparseable reply '#%!?'")
        if self.nest is not None:
            p = w.nest_tracker_mm(self.nest)
            xyz = p + w.drift_mm(p) + self.nest_error_mm + w.nest_rng.normal(0.0, w.jitter_mm, 3)
            w.clock.sleep(0.05)
            return TrackerReading(tuple(float(v) for v in xyz), w.clock.now())
        if self.smr == 1:
            xyz = w.p_smr_tracker_mm + w.point_error_mm + w.rng.normal(0.0, w.jitter_mm, 3)
        else:
            k = self.smr - 2
            xyz = w.p_extra_tracker_mm[k] + w.extra_error_mm[k] + w.rng.normal(0.0, w.jitter_mm, 3)
        xyz = xyz + w.drift_mm(xyz)
        w.clock.sleep(0.05)
        return TrackerReading(tuple(float(v) for v in xyz), w.clock.now())

    def environment(self) -> Mapping[str, float]:
        return {}

    def identity(self) -> Mapping[str, str]:
        return {"vendor": "mock", "model": "simulated laser tracker", "serial": "MOCK-T-0001",
                "firmware": MOCK_SOFTWARE_VERSION}

    def close(self) -> None:
        pass
