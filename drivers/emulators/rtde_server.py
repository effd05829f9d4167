"""A Universal Robots controller emulator on loopback, good enough for the real ur_rtde library.

Run it as its own process (ur_rtde's constructors hold the GIL, so an emulator inside the client's
interpreter would deadlock)::

    python -m drivers.emulators.rtde_server --host 127.0.0.1 --print-ports

It serves what ``RTDEReceiveInterface`` / ``RTDEControlInterface`` (ur_rtde 1.6) use, on the controller's
fixed ports (the library cannot be pointed elsewhere):

* 29999 dashboard server (ASCII lines: ``PolyscopeVersion``, ``robotmode``, ``stop``, ``play``, ...);
* 30001/30002/30003 script ports: accept URScript programs and never reply. URScript is not interpreted:
  a program named ``rtde_control`` starts an emulation of ur_rtde's control script, which watches
  ``input_int_register_0`` (command id) and the double registers for arguments, and answers through
  ``output_int_register_0`` (1 = ready for a command, 2 = done) like ``rtde_control.script`` does;
* 30004 RTDE (protocol v1/v2: version, controller version, output/input recipes, start/pause, data
  packages both ways, text messages).

The emulated arm is a nominal UR10 (DH, metres/radians inside): ``movej`` moves all joints on a
synchronised trapezoidal profile whose leading axis respects the commanded speed and acceleration and
ends exactly on the target; ``actual_TCP_pose`` is the DH forward kinematics with the active TCP. The script
emulation also runs ``setPayload`` (command 17; a [0, 0, 0] CoG keeps the current one, as the real script does)
and records every movej speed and the highest TCP speed reached (``STATE``).

Dashboard: ``power on`` (-> IDLE), ``brake release`` (-> RUNNING), ``unlock protective stop`` (refused with UR's
message until ``--unlock-delay`` s, default 5, after the stop), ``close safety popup``, ``is in remote control``
(``--no-remote-control``), serial number, model and PolyScope version. A protective stop halts the arm and ends
the script program (ur_rtde's ``reuploadScript`` starts it again once unlocked).

Standstill noise (``--q-noise-rad``, ``--qd-noise-rad-s``, ``--ring-rad``, ``--seed``): white noise on
``actual_q`` / ``actual_qd`` and a decaying ~7 Hz oscillation after each move, to test settle detection.

A line-oriented back door on an extra port (``--control-port``, default ephemeral) injects state and
faults for tests: ``STATE``, ``SETQ``, ``MODE``, ``SAFETY``, ``DROP``, ``FREEZE``, ``HANG`` (the control
script stops answering while RTDE keeps streaming), ``ONLINE``,
``ARM <drop|freeze|pstop> <delay_s>`` (fires that long after the next motion starts), ``LOG``, ``QUIT``.
``start_emulator()`` runs the emulator as a subprocess and returns a handle that stops it.
"""
from __future__ import annotations

import argparse
import json
import os
import random
import re
import select
import socket
import struct
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Iterable, Sequence

import numpy as np

from . import rtde_protocol as proto

DASHBOARD_PORT = 29999
SCRIPT_PORTS = (30001, 30002, 30003)
RTDE_PORT = 30004
FIXED_PORTS = (DASHBOARD_PORT, *SCRIPT_PORTS, RTDE_PORT)

CB3_VERSION = (3, 15, 7, 106331)
from drivers.ur import ROBOT_MODES, SAFETY_MODES  # noqa: E402  (one table for driver and emulator)
RUNNING, NORMAL, PROTECTIVE_STOP = 7, 1, 3
RUNTIME_STOPPED, RUNTIME_PLAYING = 1, 2
JOINT_RUNNING_MODE = 253

# command ids of ur_rtde's control script (rtde.h RobotCommand::Type)
CMD_NO_CMD, CMD_MOVEJ, CMD_MOVEL_FK = 0, 1, 4
CMD_SET_PAYLOAD, CMD_SET_TCP, CMD_PROTECTIVE_STOP, CMD_STOPL, CMD_STOPJ = 17, 29, 31, 33, 34
CMD_GET_TCP_OFFSET, CMD_FK_DEFAULT, CMD_FK_ARGS, CMD_IS_STEADY, CMD_STOP_SCRIPT = 40, 43, 44, 47, 255
ASYNC_RUNNING_BIT = 1 << 15

# nominal UR10 (CB3), standard DH: a, d in m; alpha in rad
UR10_A = (0.0, -0.612, -0.5723, 0.0, 0.0, 0.0)
UR10_D = (0.1273, 0.0, 0.0, 0.163941, 0.1157, 0.0922)
UR10_ALPHA = (np.pi / 2, 0.0, 0.0, np.pi / 2, -np.pi / 2, 0.0)


# --------------------------------------------------------------------------------------------- kinematics

def _dh(theta: float, d: float, a: float, alpha: float) -> np.ndarray:
    """Standard DH link transform Rz(theta) Tz(d) Tx(a) Rx(alpha) (m, rad)."""
    ct, st, ca, sa = np.cos(theta), np.sin(theta), np.cos(alpha), np.sin(alpha)
    return np.array([[ct, -st * ca, st * sa, a * ct], [st, ct * ca, -ct * sa, a * st],
                     [0.0, sa, ca, d], [0.0, 0.0, 0.0, 1.0]])


def rotvec_to_matrix(r: Sequence[float]) -> np.ndarray:
    """Rotation matrix of a rotation vector (rad)."""
    r = np.asarray(r, float)
    angle = float(np.linalg.norm(r))
    if angle < 1e-12:
        return np.eye(3)
    k = r / angle
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * kx + (1 - np.cos(angle)) * kx @ kx


def matrix_to_rotvec(m: np.ndarray) -> np.ndarray:
    """Rotation vector (rad) of a rotation matrix, robust near 0 and pi."""
    cos = np.clip((np.trace(m) - 1) / 2, -1.0, 1.0)
    angle = float(np.arccos(cos))
    if angle < 1e-9:
        return np.zeros(3)
    if np.pi - angle > 1e-6:
        axis = np.array([m[2, 1] - m[1, 2], m[0, 2] - m[2, 0], m[1, 0] - m[0, 1]]) / (2 * np.sin(angle))
        return axis * angle
    b = (m + np.eye(3)) / 2                      # angle ~ pi: axis from the symmetric part
    i = int(np.argmax(np.diag(b)))
    axis = b[:, i] / np.sqrt(b[i, i])
    return axis / np.linalg.norm(axis) * angle


def tcp_pose(q: Sequence[float], tcp: Sequence[float]) -> list[float]:
    """UR pose [x, y, z (m), rx, ry, rz (rotation vector, rad)] of the TCP for joints q (rad)."""
    t = np.eye(4)
    for qi, a, d, alpha in zip(q, UR10_A, UR10_D, UR10_ALPHA):
        t = t @ _dh(qi, d, a, alpha)
    offset = np.eye(4)
    offset[:3, :3], offset[:3, 3] = rotvec_to_matrix(tcp[3:]), tcp[:3]
    t = t @ offset
    return [*t[:3, 3].tolist(), *matrix_to_rotvec(t[:3, :3]).tolist()]


# --------------------------------------------------------------------------------------------- motion

class JointMove:
    """Synchronised joint move (rad): the leading axis follows a trapezoid (speed v rad/s, accel a rad/s²)."""

    def __init__(self, q0: Sequence[float], q1: Sequence[float], v: float, a: float) -> None:
        self.q0, self.q1 = np.asarray(q0, float), np.asarray(q1, float)
        delta = self.q1 - self.q0
        self.dist = float(np.max(np.abs(delta)))
        self.unit = delta / self.dist if self.dist > 0 else np.zeros_like(delta)
        self.v, self.a = max(float(v), 1e-6), max(float(a), 1e-6)
        self.t_acc = min(self.v / self.a, np.sqrt(self.dist / self.a))
        self.v_peak = self.a * self.t_acc
        cruise = (self.dist - self.a * self.t_acc ** 2) / self.v_peak if self.v_peak > 0 else 0.0
        self.duration = 2 * self.t_acc + max(cruise, 0.0)

    def at(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """(q, qd) at time t (s) since start; exactly the target after ``duration``."""
        if t >= self.duration:
            return self.q1.copy(), np.zeros_like(self.q1)
        s, sd = self._path(max(t, 0.0))
        return self.q0 + self.unit * s, self.unit * sd

    def _path(self, t: float) -> tuple[float, float]:
        ta, vp, a, tt = self.t_acc, self.v_peak, self.a, self.duration
        if t < ta:
            return 0.5 * a * t * t, a * t
        if t < tt - ta:
            return 0.5 * a * ta * ta + vp * (t - ta), vp
        rest = tt - t
        return self.dist - 0.5 * a * rest * rest, a * rest


class Braking:
    """Decelerate from the current joint velocity qd0 (rad/s) at a (rad/s²) along the current direction."""

    def __init__(self, q0: Sequence[float], qd0: Sequence[float], a: float) -> None:
        self.q0, qd = np.asarray(q0, float), np.asarray(qd0, float)
        self.speed = float(np.max(np.abs(qd)))
        self.unit = qd / self.speed if self.speed > 0 else np.zeros_like(qd)
        self.a = max(float(a), 1e-6)
        self.duration = self.speed / self.a
        self.q1 = self.q0 + self.unit * self.speed * self.duration / 2

    def at(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        if t >= self.duration:
            return self.q1.copy(), np.zeros_like(self.q0)
        return self.q0 + self.unit * (self.speed * t - 0.5 * self.a * t * t), self.unit * (self.speed - self.a * t)


# --------------------------------------------------------------------------------------------- controller

@dataclass
class JointNoise:
    """Measurement noise on ``actual_q`` / ``actual_qd`` at standstill (rad, rad/s): white noise of std ``q_rad`` and
    ``qd_rad_s`` plus a decaying oscillation after each move (amplitude ``ring_rad``, ``ring_hz``, time constant
    ``ring_tau_s``) like a servo settling. Seeded; zero by default."""
    q_rad: float = 0.0
    qd_rad_s: float = 0.0
    ring_rad: float = 0.0
    ring_hz: float = 7.0
    ring_tau_s: float = 0.15
    seed: int = 0

    def __post_init__(self) -> None:
        self.rng = np.random.default_rng(self.seed)

    def sample(self, t_since_stop_s: float) -> tuple[np.ndarray, np.ndarray]:
        """(dq, dqd) for one sample, ``t_since_stop_s`` after the last motion ended."""
        dq = self.rng.normal(0.0, self.q_rad, 6) if self.q_rad else np.zeros(6)
        dqd = self.rng.normal(0.0, self.qd_rad_s, 6) if self.qd_rad_s else np.zeros(6)
        if self.ring_rad and t_since_stop_s >= 0:
            w, decay = 2 * np.pi * self.ring_hz, np.exp(-t_since_stop_s / self.ring_tau_s)
            weights = np.array([1.0, 1.0, 0.8, 0.5, 0.5, 0.3])
            dq = dq + weights * self.ring_rad * decay * np.cos(w * t_since_stop_s)
            dqd = dqd - weights * self.ring_rad * decay * (w * np.sin(w * t_since_stop_s)
                                                           + np.cos(w * t_since_stop_s) / self.ring_tau_s)
        return dq, dqd


@dataclass
class ScriptState:
    """The emulated rtde_control script: register offsets, command handshake, pending completion."""
    int_offset: int = 0
    double_offset: int = 0
    executing: bool = False
    pending: Callable[[], bool] | None = None
    async_running: bool = False
    async_writes: int = 0
    async_op_id: int = 0


@dataclass
class ArmedFault:
    kind: str
    delay_s: float
    fire_at: float | None = None


class Controller:
    """Emulated controller state: joints (rad), modes, registers, the control-script emulation. Thread-safe."""

    def __init__(self, version: Sequence[int], q0: Sequence[float], robot_mode: int = RUNNING,
                 safety_mode: int = NORMAL, noise: "JointNoise | None" = None, unlock_delay_s: float = 5.0,
                 remote_control: bool = True) -> None:
        self.lock = threading.RLock()
        self.noise = noise or JointNoise()
        self.unlock_delay_s, self.remote_control = unlock_delay_s, remote_control
        self.pstop_at: float | None = None
        self.payload_kg, self.payload_cog = 0.0, [0.0, 0.0, 0.0]
        self.movej_speeds: list[float] = []          # the v argument of every movej the script ran (rad/s)
        self.max_tcp_speed = 0.0                     # highest TCP speed seen while moving (m/s)
        self._last_tcp: tuple[float, np.ndarray] | None = None
        self.motion_end = -1e9                       # controller time the last motion ended (s)
        self.version = tuple(version)
        self.t_start = time.monotonic()
        self.q = np.asarray(q0, float)
        self.qd = np.zeros(6)
        self.target_q = self.q.copy()
        self.motion: JointMove | Braking | None = None
        self.motion_t0 = 0.0
        self.robot_mode, self.safety_mode = robot_mode, safety_mode
        self.tcp = [0.0] * 6
        self.in_int, self.in_double = [0] * 48, [0.0] * 48
        self.out_int, self.out_double = [0] * 48, [0.0] * 48
        self.in_bits = [False] * 128
        self.script: ScriptState | None = None
        self.program_name = ""
        self.faults: list[ArmedFault] = []
        self.hung = False
        self.log: list[str] = []
        self.on_fault: Callable[[str], None] = lambda kind: None
        self._pose_cache: tuple[tuple, list[float]] | None = None

    # ---- state read by the RTDE streams
    def now(self) -> float:
        return time.monotonic() - self.t_start

    @property
    def playing(self) -> bool:
        return self.script is not None

    def safety_status_bits(self) -> int:
        """bit0 normal, bit1 reduced, bit2 protective stopped, bit4 safeguard, bit5/6/7 emergency, bit9 fault."""
        bit = {1: 0, 2: 1, 3: 2, 4: 3, 5: 4, 6: 5, 7: 6, 8: 8, 9: 9, 12: 4, 13: 4}.get(self.safety_mode)
        bits = 0 if bit is None else (1 << bit)
        return bits | ((1 << 7) if self.safety_mode in (6, 7) else 0)

    def robot_status_bits(self) -> int:
        """bit0 power on, bit1 program running."""
        return (1 if self.robot_mode in (4, 5, 6, 7) else 0) | (2 if self.playing else 0)

    def tcp_pose(self) -> list[float]:
        key = (tuple(self.q), tuple(self.tcp))
        if self._pose_cache is None or self._pose_cache[0] != key:
            self._pose_cache = (key, tcp_pose(self.q, self.tcp))
        return self._pose_cache[1]

    def outputs(self, names: Iterable[str]) -> dict[str, Any]:
        """Current values of the requested output variables (units as on a real controller: rad, m, s)."""
        with self.lock:
            live = self._live_values()
            return {n: live[n] if n in live else self._register_value(n) for n in names}

    def _live_values(self) -> dict[str, Any]:
        now = self.now()
        dq, dqd = self.noise.sample(now - self.motion_end) if self.motion is None else (0.0, 0.0)
        q, qd = (self.q + dq).tolist(), (self.qd + dqd).tolist()
        pose = self.tcp_pose()
        return {"timestamp": now, "actual_q": q, "target_q": self.target_q.tolist(), "actual_qd": qd,
                "target_qd": self.qd.tolist(), "payload": self.payload_kg, "payload_cog": list(self.payload_cog), "actual_TCP_pose": pose, "target_TCP_pose": pose, "robot_mode": self.robot_mode,
                "safety_mode": self.safety_mode, "safety_status": self.safety_mode,
                "safety_status_bits": self.safety_status_bits(), "robot_status_bits": self.robot_status_bits(),
                "runtime_state": RUNTIME_PLAYING if self.playing else RUNTIME_STOPPED,
                "joint_mode": [JOINT_RUNNING_MODE] * 6, "joint_temperatures": [31.5] * 6, "speed_scaling": 1.0,
                "target_speed_fraction": 1.0, "actual_main_voltage": 48.0, "actual_robot_voltage": 48.0,
                "tcp_offset": list(self.tcp), "actual_execution_time": 0.05}

    def _register_value(self, name: str) -> Any:
        m = re.match(r"^(input|output)_(int|double|bit)_register_(\d+)$", name)
        if not m:
            return None
        bank = {("input", "int"): self.in_int, ("input", "double"): self.in_double,
                ("output", "int"): self.out_int, ("output", "double"): self.out_double}.get(m.group(1, 2))
        i = int(m.group(3))
        return self.in_bits[i] if bank is None else bank[i]

    # ---- inputs written by an RTDE client
    def write_inputs(self, values: dict[str, Any]) -> None:
        with self.lock:
            for name, value in values.items():
                m = re.match(r"^input_(int|double|bit)_register_(\d+)$", name)
                if m:
                    bank = {"int": self.in_int, "double": self.in_double, "bit": self.in_bits}[m.group(1)]
                    bank[int(m.group(2))] = value

    # ---- programs arriving on the script ports
    def start_program(self, name: str, text: str) -> None:
        """A URScript program arrived: ``rtde_control`` starts the control-script emulation."""
        with self.lock:
            self.log.append(f"program {name}")
            if self.robot_mode != RUNNING or self.safety_mode not in (1, 2):
                self.log.append(f"program {name} not started: robot mode {self.robot_mode}, safety {self.safety_mode}")
                return
            self.program_name = name
            if name != "rtde_control":
                self.script = None
                return
            offsets = dict(re.findall(r"reg_offset_(int|float)\s*=\s*(?:#[^\n]*\n)?\s*(\d+)", text))
            self.script = ScriptState(int(offsets.get("int", 0)), int(offsets.get("float", 0)))
            self._async_progress(self.script, -1)
            self.out_int[self.script.int_offset] = 1

    def stop_program(self, reason: str) -> None:
        with self.lock:
            if self.script is not None:
                self.log.append(f"program stopped: {reason}")
            self.script = None
            self._brake(10.0)

    # ---- the control loop
    def step(self) -> None:
        """One controller cycle: faults, motion, control-script emulation."""
        with self.lock:
            now = self.now()
            self._fire_faults(now)
            self._advance_motion(now)
            if self.script is not None:
                self._script_cycle(self.script)

    def _advance_motion(self, now: float) -> None:
        if self.motion is None:
            self._last_tcp = None
            return
        self.q, self.qd = self.motion.at(now - self.motion_t0)
        p = np.asarray(self.tcp_pose()[:3])
        if self._last_tcp is not None and now > self._last_tcp[0]:
            speed = float(np.linalg.norm(p - self._last_tcp[1])) / (now - self._last_tcp[0])
            self.max_tcp_speed = max(self.max_tcp_speed, speed)
        self._last_tcp = (now, p)
        if now - self.motion_t0 >= self.motion.duration:
            self.motion, self.motion_end = None, now
            if self.script is not None and self.script.async_running:
                self._async_progress(self.script, -1)

    def _async_progress(self, s: ScriptState, value: int) -> None:
        """output_int_register_2 as the control script writes it: op id (bits 24-30), write count (16-23),
        running (bit 15) and progress (0-14); value 0 starts an operation, negative ends it."""
        s.async_writes = (s.async_writes + 1) % 128
        if value == 0:
            s.async_op_id = (s.async_op_id + 1) % 128
        s.async_running = value >= 0
        reg = s.async_writes * 65536 + s.async_op_id * 16777216
        self.out_int[s.int_offset + 2] = reg + min(value, 32767) + ASYNC_RUNNING_BIT if value >= 0 else reg

    def _fire_faults(self, now: float) -> None:
        for fault in [f for f in self.faults if f.fire_at is not None and now >= f.fire_at]:
            self.faults.remove(fault)
            self.log.append(f"fault {fault.kind}")
            if fault.kind == "pstop":
                self.protective_stop()
            else:
                self.on_fault(fault.kind)

    def protective_stop(self) -> None:
        """Protective stop: the arm halts where it is and the script program ends (an external script cannot be
        resumed: ur_rtde's ``reuploadScript`` starts it again once the stop is unlocked)."""
        with self.lock:
            self.safety_mode = PROTECTIVE_STOP
            self.motion, self.qd, self.motion_end = None, np.zeros(6), self.now()
            self.pstop_at = self.now()
            if self.script is not None:
                self.log.append("program stopped: protective stop")
            self.script = None

    def unlock_protective_stop(self) -> str:
        """Dashboard ``unlock protective stop``: refused until ``unlock_delay_s`` after the stop (UR: 5 s)."""
        with self.lock:
            if self.safety_mode != PROTECTIVE_STOP:
                return "Protective stop releasing"
            if self.pstop_at is not None and self.now() - self.pstop_at < self.unlock_delay_s:
                return ("Cannot unlock protective stop until 5s after occurrence. Always inspect cause of "
                        "protective stop before unlocking")
            self.safety_mode = NORMAL
            return "Protective stop releasing"

    def _start_motion(self, motion: JointMove | Braking, target: np.ndarray) -> None:
        self.motion, self.motion_t0, self.target_q = motion, self.now(), target
        for fault in self.faults:
            if fault.fire_at is None:
                fault.fire_at = self.motion_t0 + fault.delay_s

    def _brake(self, decel: float) -> None:
        if self.motion is not None:
            self._start_motion(Braking(self.q, self.qd, decel), self.target_q)

    def _script_cycle(self, s: ScriptState) -> None:
        """Mirror of rtde_control.script's loop: 0 -> ready (1); a new command -> execute, then done (2)."""
        if self.safety_mode not in (1, 2) or self.hung:
            return                                   # paused by the safety system, or hung (fault injection)
        cmd = self.in_int[s.int_offset]
        if cmd == CMD_NO_CMD:
            s.executing, s.pending = False, None
            self.out_int[s.int_offset] = 1
            return
        if s.executing:
            if s.pending is not None and s.pending():
                s.pending = None
                self.out_int[s.int_offset] = 2
            return
        s.executing = True
        self.log.append(f"cmd {cmd}")
        s.pending = self._execute(cmd, s)
        if s.pending is None and self.script is s:
            self.out_int[s.int_offset] = 2

    def _args(self, s: ScriptState, n: int, first: int = 0) -> list[float]:
        return self.in_double[s.double_offset + first:s.double_offset + first + n]

    def _execute(self, cmd: int, s: ScriptState) -> Callable[[], bool] | None:
        """Run one command; return a completion test for commands that take time, None if done now."""
        asynchronous = self.in_int[s.int_offset + 1] == 1
        if cmd in (CMD_MOVEJ, CMD_MOVEL_FK):
            d = self._args(s, 8)
            target = np.asarray(d[:6], float)
            self.movej_speeds.append(float(d[6]))
            if s.async_running:
                self._async_progress(s, -1)          # a new move kills the running async move
            self._start_motion(JointMove(self.q, target, d[6], d[7]), target)
            if asynchronous:
                self._async_progress(s, 0)
            return None if asynchronous else (lambda: self.motion is None)
        if cmd in (CMD_STOPJ, CMD_STOPL):
            if s.async_running:
                self._async_progress(s, -1)
            self._brake(self._args(s, 1)[0] or 2.0)
            return None if asynchronous else (lambda: self.motion is None)
        return self._execute_query(cmd, s)

    def _execute_query(self, cmd: int, s: ScriptState) -> None:
        if cmd == CMD_SET_PAYLOAD:
            mass, *cog = self._args(s, 4)
            self.payload_kg = float(mass)
            if any(cog):                             # the script keeps the current CoG for [0, 0, 0]
                self.payload_cog = [float(v) for v in cog]
        elif cmd == CMD_SET_TCP:
            self.tcp = list(self._args(s, 6))
        elif cmd in (CMD_GET_TCP_OFFSET, CMD_FK_DEFAULT, CMD_FK_ARGS):
            result = {CMD_GET_TCP_OFFSET: lambda: list(self.tcp), CMD_FK_DEFAULT: self.tcp_pose,
                      CMD_FK_ARGS: lambda: tcp_pose(self._args(s, 6), self._args(s, 6, 6))}[cmd]()
            self.out_double[s.double_offset:s.double_offset + 6] = result
        elif cmd == CMD_IS_STEADY:
            self.out_int[s.int_offset + 1] = int(self.motion is None)
        elif cmd == CMD_PROTECTIVE_STOP:
            self.protective_stop()
        elif cmd == CMD_STOP_SCRIPT:
            self.stop_program("stop script command")
        else:                                        # not emulated: fail loudly like a script runtime error
            self.stop_program(f"command {cmd} is not emulated")
        return None

    def set_joints(self, q: Sequence[float]) -> None:
        with self.lock:
            self.q, self.qd, self.target_q, self.motion = np.asarray(q, float), np.zeros(6), np.asarray(q, float), None

    def summary(self) -> dict[str, Any]:
        with self.lock:
            return {"q": self.q.tolist(), "qd": self.qd.tolist(), "robot_mode": self.robot_mode,
                    "safety_mode": self.safety_mode, "playing": self.playing, "program": self.program_name,
                    "out_int_0": self.out_int[0], "in_int_0": self.in_int[0], "moving": self.motion is not None,
                    "tcp_pose": self.tcp_pose(), "payload_kg": self.payload_kg, "payload_cog": self.payload_cog,
                    "movej_speeds": self.movej_speeds[-200:], "max_tcp_speed_mm_s": 1000.0 * self.max_tcp_speed}


# --------------------------------------------------------------------------------------------- sessions

class Session(threading.Thread):
    """One client connection; subclasses implement ``serve``. Closing the socket ends the thread."""
    service = "?"

    def __init__(self, emulator: "Emulator", sock: socket.socket) -> None:
        super().__init__(daemon=True, name=f"{self.service}-session")
        self.emulator, self.sock = emulator, sock
        self.controller = emulator.controller
        self.send_lock = threading.Lock()       # packets from other threads (text messages) must not interleave

    def send(self, data: bytes) -> None:
        with self.send_lock:
            self.sock.sendall(data)

    def run(self) -> None:
        try:
            self.serve()
        except (OSError, ValueError, struct.error) as exc:
            self.emulator.debug(f"{self.service}: {type(exc).__name__}: {exc}")
        finally:
            self.emulator.forget(self)
            _close(self.sock)

    def serve(self) -> None:
        raise NotImplementedError

    def close(self) -> None:
        try:
            self.sock.shutdown(socket.SHUT_RDWR)
        except OSError:
            pass
        _close(self.sock)


class RtdeSession(Session):
    """RTDE protocol server for one client: handshake, recipes, streaming outputs, receiving inputs."""
    service = "rtde"

    def serve(self) -> None:
        self.protocol = 1
        self.output: proto.Recipe | None = None
        self.inputs: dict[int, proto.Recipe] = {}
        self.period, self.streaming, self.next_send = 1 / 125, False, 0.0
        reader = proto.PacketReader()
        while True:
            timeout = max(0.0, self.next_send - time.monotonic()) if self.streaming else 0.2
            if select.select([self.sock], [], [], timeout)[0]:
                data = self.sock.recv(65536)
                if not data:
                    return
                if not self.emulator.frozen:
                    for ptype, payload in reader.feed(data):
                        self.handle(ptype, payload)
            self._stream()

    def _stream(self) -> None:
        now = time.monotonic()
        if not self.streaming or now < self.next_send or self.emulator.frozen or self.output is None:
            return
        self.send(proto.frame(proto.DATA_PACKAGE, self.output.pack(self.controller.outputs(self.output.names))))
        self.next_send = max(self.next_send + self.period, now + 0.2 * self.period)

    def reply(self, ptype: int, payload: bytes) -> None:
        self.send(proto.frame(ptype, payload))

    def handle(self, ptype: int, payload: bytes) -> None:
        handler = {proto.REQUEST_PROTOCOL_VERSION: self.on_version, proto.GET_URCONTROL_VERSION: self.on_urcontrol,
                   proto.CONTROL_PACKAGE_SETUP_OUTPUTS: self.on_outputs,
                   proto.CONTROL_PACKAGE_SETUP_INPUTS: self.on_inputs, proto.CONTROL_PACKAGE_START: self.on_start,
                   proto.CONTROL_PACKAGE_PAUSE: self.on_pause, proto.DATA_PACKAGE: self.on_data,
                   proto.TEXT_MESSAGE: self.on_text}.get(ptype)
        self.emulator.count_packet(chr(ptype) if 32 <= ptype < 127 else str(ptype))
        if handler is None:
            self.emulator.debug(f"rtde: unknown packet type {ptype}")
            return
        handler(payload)

    def on_version(self, payload: bytes) -> None:
        (version,) = struct.unpack_from(">H", payload)
        accepted = version in (1, 2)
        if accepted:
            self.protocol = version
        self.reply(proto.REQUEST_PROTOCOL_VERSION, struct.pack(">B", int(accepted)))

    def on_urcontrol(self, payload: bytes) -> None:
        self.reply(proto.GET_URCONTROL_VERSION, proto.version_reply(self.controller.version))

    def on_outputs(self, payload: bytes) -> None:
        freq, names = proto.parse_setup_outputs(payload, self.protocol)
        types = [proto.output_type(n) or "NOT_FOUND" for n in names]
        self.output = proto.make_recipe(1, names, types)
        rate = min(freq if freq > 0 else 125.0, self.emulator.max_rate_hz)
        self.period = 1.0 / rate
        self.reply(proto.CONTROL_PACKAGE_SETUP_OUTPUTS, proto.setup_reply(self.output))

    def on_inputs(self, payload: bytes) -> None:
        names = proto.parse_names(payload)
        types = [proto.input_type(n) or "NOT_FOUND" for n in names]
        types = ["IN_USE" if t != "NOT_FOUND" and self.emulator.in_use(self, n) else t for n, t in zip(names, types)]
        recipe_id = len(self.inputs) + 1 if all(t not in ("NOT_FOUND", "IN_USE") for t in types) else 0
        recipe = proto.make_recipe(recipe_id, names, types)
        if recipe_id:
            self.inputs[recipe_id] = recipe
        self.reply(proto.CONTROL_PACKAGE_SETUP_INPUTS, proto.setup_reply(recipe))

    def input_names(self) -> set[str]:
        return {n for r in self.inputs.values() for n in r.names}

    def on_start(self, payload: bytes) -> None:
        ok = self.output is not None and self.output.valid
        self.reply(proto.CONTROL_PACKAGE_START, struct.pack(">B", int(ok)))
        self.streaming, self.next_send = ok, time.monotonic()

    def on_pause(self, payload: bytes) -> None:
        self.streaming = False
        self.reply(proto.CONTROL_PACKAGE_PAUSE, struct.pack(">B", 1))

    def on_data(self, payload: bytes) -> None:
        recipe = self.inputs.get(payload[0]) if payload else None
        if recipe is None:
            self.emulator.debug(f"rtde: data package for unknown input recipe {payload[:1].hex()}")
            return
        self.controller.write_inputs(recipe.unpack(payload[1:]))

    def on_text(self, payload: bytes) -> None:
        self.emulator.debug("rtde: text message from client: %s (%s, level %d)" % proto.parse_text_message(payload))

    def send_text(self, message: str, level: int = 3) -> None:
        self.reply(proto.TEXT_MESSAGE, proto.text_message(message, "emulator", level))


class DashboardSession(Session):
    """Dashboard server (29999): one reply line per command line."""
    service = "dashboard"

    def serve(self) -> None:
        self.sock.sendall(b"Connected: Universal Robots Dashboard Server\n")
        for line in _recv_lines(self.sock):
            if self.emulator.frozen:
                continue
            answer = self.emulator.dashboard_reply(line)
            self.sock.sendall(answer.encode() + b"\n")
            if answer == "Disconnected":
                return


def _recv_lines(sock: socket.socket):
    """Yield the stripped text lines a client sends until it closes the connection."""
    buf = b""
    while True:
        data = sock.recv(4096)
        if not data:
            return
        buf += data
        while b"\n" in buf:
            line, buf = buf.split(b"\n", 1)
            yield line.decode("utf-8", "replace").strip()


class ScriptSession(Session):
    """Primary/secondary/real-time interface: accepts URScript, never replies."""
    service = "script"
    PROGRAM = re.compile(r"^(?:def|sec)\s+(\w+)\s*\(\s*\)\s*:\s*$(.*?)^end\s*$", re.M | re.S)

    def serve(self) -> None:
        text = ""
        while True:
            data = self.sock.recv(65536)
            if not data:
                return
            text += data.decode("utf-8", "replace")
            programs = list(self.PROGRAM.finditer(text))
            for m in programs:
                self.emulator.debug(f"script port {self.sock.getsockname()[1]}: program {m.group(1)}")
                self.controller.start_program(m.group(1), m.group(0))
            text = self._unfinished(text[programs[-1].end():] if programs else text)

    @staticmethod
    def _unfinished(text: str) -> str:
        """Keep only a program that has started but not ended yet (single script lines are ignored)."""
        starts = list(re.finditer(r"^(?:def|sec)\s", text, re.M))
        return text[starts[-1].start():] if starts else ""


class ControlSession(Session):
    """Test back door: one command line in, one ``OK ...`` / ``ERR ...`` line out."""
    service = "control"

    def serve(self) -> None:
        for line in _recv_lines(self.sock):
            self.sock.sendall(self.emulator.control_reply(line).encode() + b"\n")


# --------------------------------------------------------------------------------------------- emulator

class Emulator:
    """Listening sockets, client sessions, the controller loop, fault injection."""

    def __init__(self, host: str, controller: Controller, *, control_port: int = 0, max_rate_hz: float = 500.0,
                 cycle_hz: float = 500.0, verbose: bool = False) -> None:
        self.host, self.controller = host, controller
        self.max_rate_hz, self.cycle_s, self.verbose = max_rate_hz, 1.0 / cycle_hz, verbose
        self.frozen = self.offline = False
        self.stopped = threading.Event()
        self.sessions: set[Session] = set()
        self.sessions_lock = threading.Lock()
        self.packets: dict[str, int] = {}
        controller.on_fault = self.inject
        kinds = {DASHBOARD_PORT: DashboardSession, RTDE_PORT: RtdeSession, **{p: ScriptSession for p in SCRIPT_PORTS}}
        self.listeners = {port: (_listen(host, port), kind) for port, kind in kinds.items()}
        self.control_listener = _listen(host, control_port)
        self.ports = {"host": host, "dashboard": DASHBOARD_PORT, "primary": 30001, "secondary": 30002,
                      "realtime": 30003, "rtde": RTDE_PORT, "control": self.control_listener.getsockname()[1]}

    def debug(self, message: str) -> None:
        if self.verbose:
            print(f"[emulator {self.controller.now():8.3f}] {message}", file=sys.stderr, flush=True)

    def count_packet(self, kind: str) -> None:
        self.packets[kind] = self.packets.get(kind, 0) + 1

    # ---- threads
    def serve_forever(self) -> None:
        for sock, kind in self.listeners.values():
            threading.Thread(target=self._accept_loop, args=(sock, kind), daemon=True).start()
        threading.Thread(target=self._accept_loop, args=(self.control_listener, ControlSession, True),
                         daemon=True).start()
        next_t = time.monotonic()
        while not self.stopped.is_set():
            self.controller.step()
            next_t += self.cycle_s
            self.stopped.wait(max(0.0, next_t - time.monotonic()))
        self.shutdown()

    def _accept_loop(self, listener: socket.socket, kind: type[Session], always: bool = False) -> None:
        while not self.stopped.is_set():
            try:
                sock, _ = listener.accept()
            except OSError:
                return
            if self.offline and not always:
                _close(sock)
                continue
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            session = kind(self, sock)
            with self.sessions_lock:
                self.sessions.add(session)
            session.start()

    def forget(self, session: Session) -> None:
        with self.sessions_lock:
            self.sessions.discard(session)

    def in_use(self, owner: Session, name: str) -> bool:
        """An input variable is owned by another live RTDE session."""
        with self.sessions_lock:
            others = [s for s in self.sessions if isinstance(s, RtdeSession) and s is not owner]
        return any(name in s.input_names() for s in others if hasattr(s, "inputs"))

    def client_sessions(self) -> list[Session]:
        with self.sessions_lock:
            return [s for s in self.sessions if not isinstance(s, ControlSession)]

    def shutdown(self) -> None:
        self.stopped.set()
        for sock, _ in self.listeners.values():
            _close(sock)
        _close(self.control_listener)
        for s in self.client_sessions():
            s.close()

    # ---- faults
    def inject(self, kind: str) -> None:
        """``drop``: close every client connection and refuse new ones; ``freeze``: go silent, keep sockets."""
        self.debug(f"fault {kind}")
        if kind == "drop":
            self.offline = True
            for s in self.client_sessions():
                s.close()
        elif kind == "freeze":
            self.frozen = True

    # ---- line protocols
    def dashboard_reply(self, line: str) -> str:
        """Answer of the dashboard server to one command line."""
        c = self.controller
        cmd = line.lower()
        with c.lock:
            c.log.append(f"dashboard {line}")
        version = ".".join(str(v) for v in c.version)
        fixed = {"polyscopeversion": f"URSoftware {version} (Jan 01 2024)", "get serial number": "20185500000",
                 "get robot model": "UR10", "is in remote control": "true" if c.remote_control else "false",
                 "quit": "Disconnected",
                 "close popup": "closing popup", "close safety popup": "closing safety popup",
                 "get loaded program": f"Loaded program: {c.program_name or '<unnamed>'}",
                 "isprogramsaved": f"true {c.program_name or '<unnamed>'}", "restart safety": "Restarting safety",
                 "get operational mode": "NONE", "version": version}
        if cmd in fixed:
            return fixed[cmd]
        state = self._dashboard_state(cmd)
        if state is not None:
            return state
        action = self._dashboard_action(cmd)
        return action if action is not None else f"could not understand: '{line}'"

    def _dashboard_state(self, cmd: str) -> str | None:
        c = self.controller
        name = c.program_name or "<unnamed>"
        return {"robotmode": f"Robotmode: {ROBOT_MODES.get(c.robot_mode, c.robot_mode)}",
                "safetymode": f"Safetymode: {SAFETY_MODES.get(c.safety_mode, c.safety_mode)}",
                "safetystatus": f"Safetystatus: {SAFETY_MODES.get(c.safety_mode, c.safety_mode)}",
                "programstate": f"{'PLAYING' if c.playing else 'STOPPED'} {name}",
                "running": f"Program running: {'true' if c.playing else 'false'}"}.get(cmd)

    def _dashboard_action(self, cmd: str) -> str | None:
        c = self.controller
        with c.lock:
            if cmd == "stop":
                c.stop_program("dashboard stop")
                return "Stopped"
            if cmd == "play":
                return "Failed to execute: play" if not c.program_name else "Starting program"
            if cmd == "pause":
                return "Pausing program"
            if cmd == "power on":
                c.robot_mode = 5
                return "Powering on"
            if cmd == "power off":
                c.robot_mode = 3
                c.stop_program("power off")
                return "Powering off"
            if cmd == "brake release":
                c.robot_mode = RUNNING if c.robot_mode in (4, 5, 7) else c.robot_mode
                return "Brake releasing"
            if cmd == "unlock protective stop":
                return c.unlock_protective_stop()
        return None

    def control_reply(self, line: str) -> str:
        """Back-door commands for tests (angles in rad)."""
        words = line.split()
        if not words:
            return "ERR empty"
        op, args = words[0].upper(), words[1:]
        try:
            return "OK " + self._control(op, args)
        except (ValueError, IndexError, KeyError) as exc:
            return f"ERR {type(exc).__name__}: {exc}"

    def _control(self, op: str, args: list[str]) -> str:
        c = self.controller
        if op == "PING":
            return "pong"
        if op == "STATE":
            return json.dumps({**c.summary(), "frozen": self.frozen, "offline": self.offline,
                               "clients": sorted(s.service for s in self.client_sessions())})
        if op == "SETQ":
            c.set_joints([float(a) for a in args[:6]])
            return "set"
        if op in ("MODE", "SAFETY"):
            with c.lock:
                setattr(c, "robot_mode" if op == "MODE" else "safety_mode", int(args[0]))
                if op == "SAFETY" and int(args[0]) == PROTECTIVE_STOP:
                    c.protective_stop()
            return args[0]
        return self._control_faults(op, args)

    def _control_faults(self, op: str, args: list[str]) -> str:
        c = self.controller
        if op in ("DROP", "FREEZE"):
            self.inject(op.lower())
            return op.lower()
        if op == "ONLINE":
            self.frozen = self.offline = c.hung = False
            return "online"
        if op == "HANG":
            c.hung = True
            return "hung"
        if op == "ARM":
            if args[0] not in ("drop", "freeze", "pstop"):
                raise ValueError(f"unknown fault {args[0]!r}")
            with c.lock:
                c.faults.append(ArmedFault(args[0], float(args[1]) if len(args) > 1 else 0.0))
            return "armed"
        if op == "TEXT":
            for s in self.client_sessions():
                if isinstance(s, RtdeSession) and getattr(s, "streaming", False):
                    s.send_text(" ".join(args))
            return "sent"
        if op == "LOG":
            with c.lock:
                return json.dumps({"log": c.log[-200:], "packets": self.packets})
        if op == "QUIT":
            self.stopped.set()
            return "bye"
        raise ValueError(f"unknown command {op!r}")


def _listen(host: str, port: int) -> socket.socket:
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    sock.bind((host, port))
    sock.listen(16)
    return sock


def _close(sock: socket.socket) -> None:
    try:
        sock.close()
    except OSError:
        pass


# --------------------------------------------------------------------------------------------- CLI

def parse_args(argv: Sequence[str] | None = None) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="python -m drivers.emulators.rtde_server", description=__doc__.split("\n")[0])
    p.add_argument("--host", default="127.0.0.1", help="loopback address to bind (fixed UR ports)")
    p.add_argument("--control-port", type=int, default=0, help="test back-door port (0: ephemeral)")
    p.add_argument("--print-ports", action="store_true", help="print one JSON line with the ports once bound")
    p.add_argument("--version", default=".".join(map(str, CB3_VERSION)), help="controller version a.b.c.d")
    p.add_argument("--q0", type=float, nargs=6, default=[0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0],
                   metavar="RAD", help="initial joints (rad)")
    p.add_argument("--robot-mode", type=int, default=RUNNING)
    p.add_argument("--safety-mode", type=int, default=NORMAL)
    p.add_argument("--max-rate", type=float, default=500.0, help="cap of the RTDE output rate (Hz)")
    p.add_argument("--q-noise-rad", type=float, default=0.0, help="white noise std on actual_q at standstill (rad)")
    p.add_argument("--qd-noise-rad-s", type=float, default=0.0, help="white noise std on actual_qd (rad/s)")
    p.add_argument("--ring-rad", type=float, default=0.0, help="post-move oscillation amplitude (rad), decays")
    p.add_argument("--seed", type=int, default=0, help="noise seed")
    p.add_argument("--unlock-delay", type=float, default=5.0,
                   help="protective stop cannot be unlocked before this many seconds (UR: 5)")
    p.add_argument("--no-remote-control", action="store_true", help="dashboard answers 'is in remote control' false")
    p.add_argument("--verbose", action="store_true", help="log protocol events to stderr")
    return p.parse_args(argv)


def main(argv: Sequence[str] | None = None) -> int:
    args = parse_args(argv)
    version = [int(v) for v in args.version.split(".")]
    noise = JointNoise(args.q_noise_rad, args.qd_noise_rad_s, args.ring_rad, seed=args.seed)
    controller = Controller(version, args.q0, args.robot_mode, args.safety_mode, noise, args.unlock_delay,
                            not args.no_remote_control)
    emulator = Emulator(args.host, controller, control_port=args.control_port, max_rate_hz=args.max_rate,
                        verbose=args.verbose)
    if args.print_ports:
        print(json.dumps(emulator.ports), flush=True)
    try:
        emulator.serve_forever()
    except KeyboardInterrupt:
        emulator.shutdown()
    return 0


# --------------------------------------------------------------------------------------------- helper

@dataclass
class EmulatorProcess:
    """A running emulator subprocess: its ports, a back-door client, and ``stop()`` (always call it)."""
    host: str
    ports: dict[str, Any]
    process: subprocess.Popen
    log_path: str
    _stopped: bool = field(default=False, repr=False)

    def command(self, line: str, timeout_s: float = 2.0) -> str:
        """Send one back-door command; return the text after ``OK`` (raise RuntimeError on ``ERR``)."""
        with socket.create_connection((self.host, self.ports["control"]), timeout=timeout_s) as sock:
            sock.sendall(line.encode() + b"\n")
            reply = b""
            while not reply.endswith(b"\n"):
                chunk = sock.recv(65536)
                if not chunk:
                    break
                reply += chunk
        text = reply.decode().strip()
        if not text.startswith("OK"):
            raise RuntimeError(f"emulator {self.host}: {line!r} -> {text!r}")
        return text[3:]

    def state(self) -> dict[str, Any]:
        return json.loads(self.command("STATE"))

    def log(self) -> dict[str, Any]:
        return json.loads(self.command("LOG"))

    def stderr_tail(self, n: int = 20) -> str:
        try:
            with open(self.log_path, encoding="utf-8", errors="replace") as f:
                return "".join(f.readlines()[-n:])
        except OSError:
            return ""

    def stop(self, timeout_s: float = 3.0) -> None:
        """Ask the emulator to quit, then terminate / kill it; idempotent."""
        if self._stopped:
            return
        self._stopped = True
        if self.process.poll() is None:
            try:
                self.command("QUIT", timeout_s=0.5)
            except (OSError, RuntimeError):
                pass
        _reap(self.process, timeout_s)
        try:
            os.unlink(self.log_path)
        except OSError:
            pass

    def __enter__(self) -> "EmulatorProcess":
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()


def _reap(process: subprocess.Popen, timeout_s: float) -> None:
    for action in (None, process.terminate, process.kill):
        if action is not None and process.poll() is None:
            action()
        try:
            process.wait(timeout=timeout_s)
            return
        except subprocess.TimeoutExpired:
            continue


def free_loopback_host(attempts: int = 50) -> str:
    """A random 127.x.y.z on which all fixed UR ports are free (Linux routes all of 127/8 to lo)."""
    rng = random.Random()
    for _ in range(attempts):
        host = f"127.{rng.randint(1, 254)}.{rng.randint(0, 255)}.{rng.randint(1, 254)}"
        try:
            for sock in [_listen(host, p) for p in FIXED_PORTS]:
                sock.close()
            return host
        except OSError:
            continue
    raise RuntimeError("no free loopback address for the UR emulator")


def start_emulator(host: str | None = None, extra_args: Sequence[str] = (), timeout_s: float = 10.0) -> EmulatorProcess:
    """Start the emulator as a subprocess on ``host`` (default: a free random loopback address)."""
    host = host or free_loopback_host()
    fd, log_path = tempfile.mkstemp(prefix="rtde_emulator_", suffix=".log")
    cmd = [sys.executable, "-m", "drivers.emulators.rtde_server", "--host", host, "--print-ports", *extra_args]
    with os.fdopen(fd, "w") as log:
        process = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=log, stdin=subprocess.DEVNULL)
    handle = EmulatorProcess(host, {}, process, log_path)
    try:
        handle.ports = _read_ports(process, timeout_s)
    except BaseException:
        tail = handle.stderr_tail()
        handle.stop()
        raise RuntimeError(f"UR emulator on {host} did not start: {tail.strip()[-500:]}") from None
    return handle


def _read_ports(process: subprocess.Popen, timeout_s: float) -> dict[str, Any]:
    assert process.stdout is not None
    deadline = time.monotonic() + timeout_s
    line = b""
    while not line.endswith(b"\n"):
        remaining = deadline - time.monotonic()
        if remaining <= 0 or not select.select([process.stdout], [], [], remaining)[0]:
            raise TimeoutError("no ports line")
        chunk = os.read(process.stdout.fileno(), 4096)
        if not chunk:
            raise EOFError("emulator exited")
        line += chunk
    return json.loads(line.decode())


if __name__ == "__main__":
    raise SystemExit(main())
