"""State of the emulated UR controller: nominal UR10 kinematics, joint moves, braking, standstill noise, the
control-script emulation (ur_rtde's command registers) and armed faults. No sockets (``rtde_server`` serves it).
"""
from __future__ import annotations

import re
import threading
import time
from dataclasses import dataclass
from typing import Any, Callable, Iterable, Sequence

import numpy as np

CB3_VERSION = (3, 15, 7, 106331)
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

