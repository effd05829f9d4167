"""Universal Robots driver (``ur-rtde://host``) on the ur_rtde library, run in a supervised worker process.

ur_rtde holds the Python interpreter while its constructors connect and can block for minutes in
``moveJ`` after a lost connection (see ``docs/drivers_ur.md``). So every library call
runs in a worker process (``multiprocessing`` spawn context) that owns the ``RTDEControlInterface`` and
``RTDEReceiveInterface``; the parent talks to it over a pipe with a small request/response protocol
``(id, op, args) -> (id, status, payload)`` and puts a hard wall-clock timeout on every call. When a call
times out, or the worker reports a lost link, the parent kills the worker and raises ``ConnectionLost``.

Units: radians (rad/s, rad/s²) inside the worker and in the options, degrees at the ``Robot`` protocol
boundary (``move_joints`` / ``read_joints``); TCP positions are reported in mm.

Moves use ``moveJ(q, speed, acceleration, asynchronous=True)``; the worker then watches the robot
itself until it has settled over a sliding window of ``settle_hold_s``: the window's mean ``|actual_q - target|``
within ``in_position_tol_deg``, each joint's drift (least-squares slope of ``actual_q``) below ``settle_qd_rad_s``
and its spread (max - min) within ``settle_band_deg``, so encoder noise and a decaying servo oscillation neither block nor fake
the settle. While waiting it checks that RTDE data keep arriving (controller timestamp advancing), the safety
and robot modes, the control script, and whether ``stop()`` asked for a ``stopJ``.

The Dashboard server (29999) is used through ur_rtde's ``DashboardClient``: PolyScope version, serial number
(PolyScope >= 5.6), robot model and remote-control state for ``identity()``; power on and brake release at
connect (``power_on``); after a protective stop, ``unlock protective stop`` (``unlock_protective_stop``, never
earlier than the controller allows), ``close safety popup`` and ``reuploadScript()``, so the run continues
without a reconnect. Speed caps (``set_motion_limits``) bound the moveJ speed that reaches the control script:
a percentage of the rated joint speed, and the TCP speed along the joint-interpolated path (sampled with the
controller's own forward kinematics). ``set_payload`` calls ``setPayload(mass, CoG)``.
"""
from __future__ import annotations

import itertools
import math
import multiprocessing
import os
import re
import tempfile
import threading
import time
from collections import deque
from dataclasses import asdict, dataclass, fields
from typing import Any, Mapping, Sequence
from urllib.parse import urlsplit

import numpy as np

from .base import ConnectionLost, DriverError, MotionError, MotionLimits, Payload, RobotError, RobotNotReady

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

class URRobot:
    """A UR arm behind ur_rtde; implements the ``Robot`` protocol (degrees at this boundary)."""
    n_joints = 6
    DEFAULT_LIMITS = MotionLimits()      # 250 mm/s, 100 %: in force until ``set_motion_limits``

    def __init__(self, url: str, host: str, options: UROptions) -> None:
        self.url, self.host, self.options = url, host, options
        self._proc: multiprocessing.process.BaseProcess | None = None
        self._conn: Any = None
        self._ids = itertools.count(1)
        self._call_lock = threading.Lock()
        self._send_lock = threading.Lock()
        self._log_path: str | None = None
        self._own_log = False
        self.last_settled_deg: tuple[float, ...] | None = None
        self.last_speed_rad_s: float | None = None     # the moveJ speed actually sent for the last move
        self._limits = self.DEFAULT_LIMITS             # safe default until the runner sets the campaign's caps
        self._identity: dict[str, str] | None = None
        self._payload: tuple[float, list[float]] | None = None   # sent at connect when set before it

    def __repr__(self) -> str:
        return f"URRobot({self.url!r}, worker={'alive' if self.worker_alive else 'none'})"

    # ---- Robot protocol
    def connect(self) -> None:
        """Start the worker, connect RTDE receive, run the preflight, connect RTDE control (uploads the script).

        Raises RobotNotReady (robot mode not RUNNING, safety mode not NORMAL, control script not running) or
        ConnectionLost (controller unreachable, no data, timeout). A failed connect leaves no worker behind.
        """
        if self.worker_alive:
            return
        try:
            self._start_worker()
            status = self._call("connect", (), self.options.connect_timeout_s)
            self._identity = dict(status.get("identity", {}))
            if self._payload is not None:
                self._call("set_payload", self._payload, self.options.call_timeout_s)
        except BaseException:
            self.close()
            raise

    def move_joints(self, q_deg: Sequence[float]) -> None:
        """Move to the joint target (deg) with moveJ and return once settled in position, or raise.

        InvalidTarget (not 6 finite values), MotionError (refused, protective stop, stopped, stalled),
        ConnectionLost (link lost or ``move_timeout_s`` exceeded; the worker is killed).
        """
        q_rad = [math.radians(v) for v in self._validate_target(q_deg)]
        o, lim = self.options, self._limits
        settled, speed = self._call("move", (q_rad, o.speed_rad_s, o.acceleration_rad_s2,
                                             lim.max_tcp_speed_mm_s / 1000.0, lim.max_joint_speed_pct),
                                    o.move_timeout_s)
        self.last_settled_deg = tuple(math.degrees(v) for v in settled)
        self.last_speed_rad_s = speed

    def read_joints(self) -> tuple[float, ...]:
        """Actual joint values (deg) from a fresh RTDE sample."""
        return tuple(math.degrees(v) for v in self._call("read_q", (), self.options.call_timeout_s))

    def stop(self) -> None:
        """stopJ in the worker if it is alive (bounded by ``call_timeout_s``); never raises.

        If another thread is waiting on a move, the stop request is sent alongside and the worker's move
        loop executes it; the waiting ``move_joints`` then raises MotionError.
        """
        if not self.worker_alive:
            return
        decel = self.options.stop_deceleration_rad_s2
        if not self._call_lock.acquire(timeout=0.05):
            self._send_quietly((next(self._ids), "stop", (decel,)))
            return
        self._call_lock.release()
        try:
            self._call("stop", (decel,), self.options.call_timeout_s)
        except Exception:   # noqa: BLE001 - stop is best effort by contract
            pass

    def close(self) -> None:
        """Stop the control script, disconnect, end the worker (killed if it does not exit); idempotent."""
        closed = False
        try:
            if self.worker_alive:
                self._call("close", (), self.options.call_timeout_s)
                closed = True
        except Exception:   # noqa: BLE001 - close never raises
            pass
        finally:
            self._reap(grace_s=2.0 if closed else 0.0)
            self._remove_log()

    # ---- optional capabilities (drivers/base.py)
    def set_motion_limits(self, limits: MotionLimits) -> None:
        """Caps for every later move: the moveJ speed is reduced to ``max_joint_speed_pct`` of the rated joint
        speed and so that the TCP stays under ``max_tcp_speed_mm_s`` along the path (checked in the worker)."""
        tcp, pct = float(limits.max_tcp_speed_mm_s), float(limits.max_joint_speed_pct)
        if not (math.isfinite(tcp) and tcp > 0 and math.isfinite(pct) and 0 < pct <= 100):
            raise RobotError(f"{self.url}: motion limits need a positive TCP speed (mm/s) and 0 < joint % <= 100, "
                             f"got {tcp} mm/s, {pct} %")
        self._limits = MotionLimits(tcp, pct)

    def set_payload(self, payload: Payload) -> None:
        """``setPayload(mass kg, CoG m)`` with the CoG given in mm in the flange frame. UR's control script keeps the
        previous CoG when it receives [0, 0, 0], so a zero CoG is sent as 1 µm along z."""
        mass = float(payload.mass_kg)
        cog_m = [float(v) / 1000.0 for v in payload.cog_flange_mm]
        if not (math.isfinite(mass) and mass >= 0 and len(cog_m) == 3 and all(math.isfinite(v) for v in cog_m)):
            raise RobotError(f"{self.url}: payload needs a mass >= 0 kg and a finite CoG (mm), got {payload}")
        if not any(cog_m):
            cog_m[2] = 1e-6
        self._payload = (mass, cog_m)
        if self.worker_alive:
            self._call("set_payload", self._payload, self.options.call_timeout_s)

    def identity(self) -> dict[str, str]:
        """vendor, model, controller_type (CB3 / e-Series), serial, software_version (PolyScope), remote_control;
        read from the Dashboard at connect."""
        if self._identity is None:
            raise RobotError(f"{self.url}: identity is read at connect(); not connected")
        return dict(self._identity)

    def speed_override_pct(self) -> float | None:
        """The speed slider (``target_speed_fraction``) in percent."""
        return self._call("speed_fraction", (), self.options.call_timeout_s) * 100.0

    # ---- extras
    def read_tcp_pose(self) -> tuple[float, ...]:
        """Actual TCP pose: x, y, z (mm, robot base frame) and the UR rotation vector rx, ry, rz (rad)."""
        pose = self._call("read_pose", (), self.options.call_timeout_s)
        return (*(v * 1000.0 for v in pose[:3]), *pose[3:])

    def read_status(self) -> dict[str, Any]:
        """Controller state: robot/safety mode (code and name), runtime state, timestamp (s), joint temps (°C)."""
        return self._call("status", (), self.options.call_timeout_s)

    @property
    def worker_alive(self) -> bool:
        return self._proc is not None and self._proc.is_alive()

    @property
    def worker_pid(self) -> int | None:
        return self._proc.pid if self._proc is not None else None

    def __enter__(self) -> "URRobot":
        self.connect()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ---- worker management
    def _validate_target(self, q_deg: Sequence[float]) -> list[float]:
        try:
            q = [float(v) for v in q_deg]
        except (TypeError, ValueError) as exc:
            raise InvalidTarget(f"{self.url}: joint target must be {self.n_joints} numbers (deg): {exc}") from None
        if len(q) != self.n_joints or not all(math.isfinite(v) for v in q):
            raise InvalidTarget(f"{self.url}: joint target must be {self.n_joints} finite values (deg), got {q}")
        return q

    def _start_worker(self) -> None:
        self._own_log = self.options.worker_log is None
        if self._own_log:
            fd, self._log_path = tempfile.mkstemp(prefix="ur_rtde_worker_", suffix=".log")
            os.close(fd)
        else:
            self._log_path = self.options.worker_log
        ctx = multiprocessing.get_context("spawn")
        self._conn, child = ctx.Pipe(duplex=True)
        self._proc = ctx.Process(target=_worker_main, args=(child, self.host, asdict(self.options), self._log_path),
                                 name=f"ur-rtde-worker[{self.host}]", daemon=True)
        self._proc.start()
        child.close()

    def _call(self, op: str, args: tuple, timeout_s: float) -> Any:
        """One request/response with a hard timeout; maps worker failures to the driver error tree."""
        if not self.worker_alive:
            raise ConnectionLost(f"{self.url}: not connected (no ur_rtde worker; call connect())")
        with self._call_lock:
            rid = next(self._ids)
            self._send(rid, op, args)
            status, payload = self._wait_reply(rid, op, timeout_s)
        return self._unwrap(op, status, payload)

    def _send(self, rid: int, op: str, args: tuple) -> None:
        try:
            with self._send_lock:
                self._conn.send((rid, op, args))
        except (OSError, ValueError) as exc:
            self._lost(f"{op}: worker pipe broken ({exc})")

    def _send_quietly(self, message: tuple) -> None:
        try:
            with self._send_lock:
                self._conn.send(message)
        except (OSError, ValueError, AttributeError):
            pass

    def _wait_reply(self, rid: int, op: str, timeout_s: float) -> tuple[str, Any]:
        deadline = time.monotonic() + timeout_s
        while True:
            remaining = deadline - time.monotonic()
            try:
                if remaining <= 0 or not self._conn.poll(remaining):
                    self._lost(f"{op} timed out after {timeout_s:.1f} s")
                reply_id, status, payload = self._conn.recv()
            except (EOFError, OSError) as exc:
                self._lost(f"{op}: worker exited ({type(exc).__name__}, exit code {self._exitcode()})")
            if reply_id == rid:
                return status, payload

    def _unwrap(self, op: str, status: str, payload: Any) -> Any:
        if status == "ok":
            return payload
        if status == "lost":
            self._lost(f"{op}: {payload}")
        error = {"not_ready": RobotNotReady, "motion": MotionError, "robot": RobotError}.get(status, DriverError)
        raise error(f"{self.url}: {op}: {payload}")

    def _lost(self, reason: str) -> None:
        """Kill the worker and raise ConnectionLost with a one-line reason (and the library's last word)."""
        tail = self._library_tail()
        self._reap(grace_s=0.0)
        said = f" (library: {tail})" if tail else ""
        raise ConnectionLost(f"{self.url}: {reason}; worker killed{said}")

    def _exitcode(self) -> int | None:
        if self._proc is not None:
            self._proc.join(0.2)
            return self._proc.exitcode
        return None

    def _reap(self, grace_s: float) -> None:
        proc, self._proc = self._proc, None
        if proc is not None:
            proc.join(grace_s)
            if proc.is_alive():
                proc.kill()
                proc.join(2.0)
        if self._conn is not None:
            self._conn.close()
            self._conn = None

    def _library_tail(self) -> str:
        """Last non-empty line the worker/library printed, shortened, for error messages."""
        try:
            with open(self._log_path or "", encoding="utf-8", errors="replace") as f:
                lines = [ln.strip() for ln in f.readlines()[-20:] if ln.strip()]
        except OSError:
            return ""
        return lines[-1][:160] if lines else ""

    def _remove_log(self) -> None:
        if self._own_log and self._log_path:
            try:
                os.unlink(self._log_path)
            except OSError:
                pass
        self._log_path = None


def open_robot(url: str, options: Mapping[str, Any], **context: Any) -> URRobot:
    """Registry factory for ``ur-rtde://host`` (not yet connected); ``context`` is not used."""
    parts = urlsplit(url)
    if parts.scheme != "ur-rtde" or not parts.hostname:
        raise DriverError(f"{url}: expected ur-rtde://<controller host>")
    if parts.port is not None or parts.path not in ("", "/"):
        raise DriverError(f"{url}: ur_rtde uses the controller's fixed ports (29999, 30003, 30004); "
                          "give only the host")
    return URRobot(url, parts.hostname, UROptions.from_mapping(url, options))


# ================================================================================================ worker

class _Failure(Exception):
    """A worker-side failure with its kind: lost, not_ready, motion, robot."""

    def __init__(self, kind: str, message: str) -> None:
        super().__init__(message)
        self.kind = kind


def _worker_main(conn: Any, host: str, options: dict[str, Any], log_path: str | None) -> None:
    """Worker process entry: redirect the library's output, then serve requests until close or EOF."""
    _redirect_output(log_path)
    _Worker(conn, host, UROptions(**options)).serve()


def _redirect_output(log_path: str | None) -> None:
    """Send fd 1 and 2 (ur_rtde prints with std::cout / std::cerr) to the worker log."""
    fd = os.open(log_path or os.devnull, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o644)
    os.dup2(fd, 1)
    os.dup2(fd, 2)
    os.close(fd)


class _Worker:
    """Owns the ur_rtde interfaces; every op_* runs one request. Radians throughout."""

    def __init__(self, conn: Any, host: str, options: UROptions) -> None:
        self.conn, self.host, self.o = conn, host, options
        self.rtde_r: Any = None
        self.rtde_c: Any = None
        self.dash: Any = None
        self.rated_rad_s = min(RATED_JOINT_SPEED_RAD_S.values())
        self.tcp_offset: list[float] = [0.0] * 6
        self.dh: tuple | None = None            # nominal DH of the model, None = ask the controller's FK
        self.pstop_seen = False                 # a protective stop happened: re-upload the script after unlock

    def serve(self) -> None:
        while True:
            try:
                rid, op, args = self.conn.recv()
            except (EOFError, OSError):
                return
            self.conn.send((rid, *self._dispatch(op, args)))
            if op == "close":
                os._exit(0)     # skip the interfaces' destructors: each disconnect() sleeps 0.5 s

    def _dispatch(self, op: str, args: tuple) -> tuple[str, Any]:
        handler = getattr(self, f"op_{op}", None)
        if handler is None:
            return "error", f"unknown request {op!r}"
        try:
            return "ok", handler(*args)
        except _Failure as f:
            return f.kind, str(f)
        except Exception as exc:  # noqa: BLE001 - reported to the parent as one line
            return "robot", f"{type(exc).__name__}: {exc}"

    # ---- connect and preflight
    def op_connect(self) -> dict[str, Any]:
        """Dashboard (identity, remote control, power on) -> receive interface -> preflight (modes) -> control
        interface (uploads the control script)."""
        try:
            import dashboard_client
            import rtde_control
            import rtde_receive
        except ImportError as exc:
            raise _Failure("robot", f"ur_rtde is not installed ({exc})") from None
        self.dash = self._construct("Dashboard", lambda: self._dashboard(dashboard_client))
        identity = self._identity()
        if identity["remote_control"] == "false":
            raise _Failure("not_ready", "the robot is in local control: switch it to Remote Control on the teach "
                                        "pendant")
        self.rtde_r = self._construct("RTDE receive", lambda: rtde_receive.RTDEReceiveInterface(
            self.host, self.o.frequency_hz, RECEIVE_VARIABLES))
        if not self.rtde_r.isConnected():
            raise _Failure("lost", f"RTDE receive interface got no data from {self.host}:30004")
        self._fresh_timestamp()
        if self.o.power_on:
            self._power_on()
        status = self.op_status()
        self._preflight(status)
        flags = rtde_control.RTDEControlInterface.FLAG_UPLOAD_SCRIPT
        self.rtde_c = self._construct("RTDE control", lambda: rtde_control.RTDEControlInterface(
            self.host, self.o.frequency_hz, flags))
        if not self.rtde_c.isProgramRunning():
            raise _Failure("not_ready", "the rtde_control script is not running after upload")
        self.tcp_offset = _six(self.rtde_c.getTCPOffset(), "TCP offset")
        return {**status, "identity": identity}

    def _dashboard(self, module: Any) -> Any:
        dash = module.DashboardClient(self.host)
        dash.connect(int(1000 * min(self.o.call_timeout_s, 10.0)))
        return dash

    def _identity(self) -> dict[str, str]:
        """Model, PolyScope version, serial number (PolyScope >= 5.6) and remote-control state from the Dashboard."""
        version = str(self.dash.polyscopeVersion())
        major = int(version.split(".")[0]) if version.split(".")[0].isdigit() else 0
        modern = tuple(int(v) for v in version.split(".")[:2] if v.isdigit()) >= (5, 6)
        model = self._dashboard_text(self.dash.getRobotModel)
        family = re.match(r"UR\d+", model)
        if family and family.group(0) in RATED_JOINT_SPEED_RAD_S:
            self.rated_rad_s = RATED_JOINT_SPEED_RAD_S[family.group(0)]
            self.dh = UR_DH.get(family.group(0) + ("e" if major >= 5 else ""))
        serial = self._dashboard_text(self.dash.getSerialNumber) if modern else "unknown (PolyScope < 5.6)"
        remote = ("true" if self.dash.isInRemoteControl() else "false") if modern else "n/a"
        return {"vendor": "Universal Robots", "model": model, "controller_type": "e-Series" if major >= 5 else "CB3",
                "serial": serial, "software_version": f"PolyScope {version}", "remote_control": remote}

    @staticmethod
    def _dashboard_text(query: Any) -> str:
        """A Dashboard answer as text, or ``unknown`` if this PolyScope does not support the query."""
        try:
            return str(query()).strip() or "unknown"
        except RuntimeError:
            return "unknown"

    def _power_on(self) -> None:
        """Dashboard power on (-> IDLE) and brake release (-> RUNNING), bounded by ``connect_timeout_s``."""
        deadline = time.monotonic() + self.o.connect_timeout_s
        mode = int(self.rtde_r.getRobotMode())
        if mode in (ROBOT_MODE_POWER_OFF, 4):
            self.dash.powerOn()
            while int(self.rtde_r.getRobotMode()) not in (ROBOT_MODE_IDLE, ROBOT_MODE_RUNNING):
                if time.monotonic() > deadline:
                    raise _Failure("not_ready", "power on did not reach IDLE")
                time.sleep(0.05)
        if int(self.rtde_r.getRobotMode()) == ROBOT_MODE_IDLE:
            self.dash.brakeRelease()
            while int(self.rtde_r.getRobotMode()) != ROBOT_MODE_RUNNING:
                if time.monotonic() > deadline:
                    raise _Failure("not_ready", "brake release did not reach RUNNING")
                time.sleep(0.05)

    @staticmethod
    def _construct(what: str, make: Any) -> Any:
        try:
            return make()
        except Exception as exc:  # noqa: BLE001 - classify the library's RuntimeError text
            text = f"{what}: {type(exc).__name__}: {exc}".replace("\n", " ")
            lowered = text.lower()
            if "remote control" in lowered or "control script" in lowered or "program is not running" in lowered:
                raise _Failure("not_ready", text) from None
            raise _Failure("lost", text) from None

    @staticmethod
    def _preflight(status: Mapping[str, Any]) -> None:
        if status["robot_mode"] != ROBOT_MODE_RUNNING:
            raise _Failure("not_ready", f"robot mode {status['robot_mode']} ({status['robot_mode_name']}), "
                                        "expected 7 (RUNNING): power on and release the brakes")
        if status["safety_mode"] != SAFETY_MODE_NORMAL:
            raise _Failure("not_ready", f"safety mode {status['safety_mode']} ({status['safety_mode_name']}), "
                                        "expected 1 (NORMAL)")

    # ---- reads
    def op_status(self) -> dict[str, Any]:
        r = self._receiver()
        mode, safety = int(r.getRobotMode()), int(r.getSafetyMode())
        return {"robot_mode": mode, "robot_mode_name": ROBOT_MODES.get(mode, "UNKNOWN"), "safety_mode": safety,
                "safety_mode_name": SAFETY_MODES.get(safety, "UNKNOWN"), "runtime_state": int(r.getRuntimeState()),
                "timestamp_s": float(r.getTimestamp()), "joint_temperatures_c": list(r.getJointTemperatures())}

    def op_read_q(self) -> list[float]:
        """Actual q (rad) from a sample newer than the request."""
        self._fresh_timestamp()
        return _six(self.rtde_r.getActualQ(), "actual_q")

    def op_speed_fraction(self) -> float:
        return float(self._receiver().getTargetSpeedFraction())

    def op_set_payload(self, mass: float, cog_m: list[float]) -> None:
        self._recover()
        if not self._controller().setPayload(mass, cog_m):
            raise self._motion_failure("setPayload was refused")

    def op_read_pose(self) -> list[float]:
        """Actual TCP pose [x, y, z (m), rx, ry, rz (rad)] from a fresh sample."""
        self._fresh_timestamp()
        return _six(self.rtde_r.getActualTCPPose(), "actual_TCP_pose")

    def _receiver(self) -> Any:
        if self.rtde_r is None:
            raise _Failure("lost", "not connected")
        if not self.rtde_r.isConnected():
            raise _Failure("lost", "RTDE receive connection closed")
        return self.rtde_r

    def _fresh_timestamp(self) -> float:
        """Wait until the controller timestamp advances (a new RTDE sample), at most ``stale_after_s``."""
        r = self._receiver()
        t0, deadline = r.getTimestamp(), time.monotonic() + self.o.stale_after_s
        while time.monotonic() < deadline:
            ts = r.getTimestamp()
            if ts != t0 and ts > 0:
                return ts
            time.sleep(0.001)
        raise _Failure("lost", f"no fresh RTDE data for {self.o.stale_after_s:.1f} s "
                               f"(controller timestamp stuck at {t0:.3f} s)")

    # ---- motion
    def op_move(self, q: list[float], speed: float, acceleration: float, tcp_cap_m_s: float,
                joint_pct: float) -> tuple[list[float], float]:
        """moveJ (asynchronous) to q (rad) at the capped speed, then wait until settled in position; returns the
        settled q (rad) and the speed sent (rad/s). Recovers from an unlocked protective stop first."""
        self._fresh_timestamp()
        self._recover()
        self._check_motion_state()
        capped = self._capped_speed(_six(self.rtde_r.getActualQ(), "actual_q"), q, speed, tcp_cap_m_s, joint_pct)
        if not self._controller().moveJ(q, capped, acceleration, True):
            raise self._motion_failure("moveJ was refused")
        return _Settle(self, q).wait(), capped

    def _capped_speed(self, q0: list[float], q1: list[float], speed: float, tcp_cap_m_s: float,
                      joint_pct: float) -> float:
        """Leading-joint speed (rad/s) under the joint cap and the TCP cap: along the joint-interpolated path a point
        moves |dp/ds| * omega / lead (s in [0, 1]), so omega <= cap * lead / max |dp/ds| (with a 0.9 margin)."""
        omega = min(speed, joint_pct / 100.0 * self.rated_rad_s)
        lead = max(abs(a - b) for a, b in zip(q0, q1))
        if lead < 1e-9:
            return omega
        path_per_s = self._max_path_rate(np.asarray(q0), np.asarray(q1))
        return omega if path_per_s < 1e-12 else min(omega, TCP_MARGIN * tcp_cap_m_s * lead / path_per_s)

    def _max_path_rate(self, q0: np.ndarray, q1: np.ndarray) -> float:
        """max |dp/ds| (m per unit path parameter) of the TCP and of points ``tool_radius_mm`` from it along the
        flange axes, from the nominal DH of the model (48 samples); unknown model: the TCP only, from the
        controller's forward kinematics (13 samples)."""
        if self.dh is None:
            s = np.linspace(0.0, 1.0, TCP_SAMPLES // 4 + 1)
            fk = self._controller().getForwardKinematics
            points = np.array([fk(list(q0 + si * (q1 - q0)), self.tcp_offset)[:3] for si in s])
            return float(np.max(np.linalg.norm(np.diff(points, axis=0), axis=1)) * (len(s) - 1))
        s = np.linspace(0.0, 1.0, TCP_SAMPLES + 1)[:, None]
        q = q0 + s * (q1 - q0)                                                      # (K, 6) rad
        r = self.o.tool_radius_mm / 1000.0
        offsets = [np.zeros(3)] + [sign * r * axis for axis in np.eye(3) for sign in (1.0, -1.0)]
        points = np.stack([_dh_points(q, self.dh, np.asarray(self.tcp_offset[:3]) + d) for d in offsets])
        return float(np.linalg.norm(np.diff(points, axis=1), axis=2).max()) * TCP_SAMPLES

    def _recover(self) -> None:
        """Protective stop: unlock it through the Dashboard if allowed (else ask the operator), close the safety
        popup; then re-upload the control script if it is not running. Bounded by ``protective_stop_wait_s``."""
        status = self.op_status()
        if status["safety_mode"] == PROTECTIVE_STOP:
            self.pstop_seen = True
            if not self.o.unlock_protective_stop:
                raise _Failure("motion", "safety mode 3 (PROTECTIVE_STOP): inspect the cause, then unlock it on the "
                                         "teach pendant (or set options.unlock_protective_stop)")
            deadline = time.monotonic() + self.o.protective_stop_wait_s
            while int(self.rtde_r.getSafetyMode()) == PROTECTIVE_STOP:
                if time.monotonic() > deadline:
                    raise _Failure("motion", f"protective stop not unlocked within {self.o.protective_stop_wait_s:g} s")
                try:
                    self.dash.unlockProtectiveStop()
                except RuntimeError as exc:        # "Cannot unlock protective stop until 5s after occurrence"
                    if "cannot unlock" not in str(exc).lower():
                        raise
                time.sleep(0.2)
            self.dash.closeSafetyPopup()
            status = self.op_status()
        if self.pstop_seen and status["safety_mode"] in (1, 2) and status["robot_mode"] == ROBOT_MODE_RUNNING and \
                not self._controller().isProgramRunning():
            self.pstop_seen = False
            if not self.rtde_c.reuploadScript():
                raise _Failure("motion", "reuploadScript failed after the protective stop")
            deadline = time.monotonic() + self.o.call_timeout_s
            while not self.rtde_c.isProgramRunning():
                if time.monotonic() > deadline:
                    raise _Failure("motion", "the re-uploaded control script did not start")
                time.sleep(0.01)

    def op_stop(self, deceleration: float) -> None:
        if self.rtde_c is not None:
            self.rtde_c.stopJ(deceleration, False)

    def op_close(self) -> None:
        """Stop the control script; the sockets close when the worker exits right after replying."""
        if self.rtde_c is not None and self.rtde_c.isConnected() and self.rtde_c.isProgramRunning():
            self.rtde_c.stopScript()

    def _controller(self) -> Any:
        if self.rtde_c is None:
            raise _Failure("lost", "not connected")
        if not self.rtde_c.isConnected():
            raise _Failure("lost", "RTDE control connection closed")
        return self.rtde_c

    def _check_motion_state(self, *, fresh: bool = False) -> None:
        """Raise MotionError-kind failures for safety stops, robot mode or a dead control script. The control
        interface's stream can see the script end before the receive stream shows why: a dead script is
        re-checked against one fresh receive sample."""
        if fresh:
            self._fresh_timestamp()
        status = self.op_status()
        self.pstop_seen = self.pstop_seen or status["safety_mode"] == PROTECTIVE_STOP
        if status["safety_mode"] not in (1, 2):
            raise _Failure("motion", f"safety mode {status['safety_mode']} ({status['safety_mode_name']})")
        if status["robot_mode"] != ROBOT_MODE_RUNNING:
            raise _Failure("motion", f"robot mode {status['robot_mode']} ({status['robot_mode_name']})")
        if not self._controller().isProgramRunning():
            if not fresh:
                return self._check_motion_state(fresh=True)
            raise _Failure("motion", "the rtde_control script is not running")

    def _motion_failure(self, what: str) -> _Failure:
        try:
            self._check_motion_state()
        except _Failure as f:
            return _Failure(f.kind, f"{what}: {f}")
        return _Failure("motion", what)

    def poll_stop_request(self) -> None:
        """Handle a request that arrived during a move: ``stop`` -> stopJ, then fail the move."""
        if not self.conn.poll(0):
            return
        rid, op, args = self.conn.recv()
        if op != "stop":
            self.conn.send((rid, "robot", f"busy with a move; {op} refused"))
            return
        self.rtde_c.stopJ(args[0], False)
        self.conn.send((rid, "ok", None))
        raise _Failure("motion", "move stopped by stop()")


class _Settle:
    """Wait for a move to settle in position (rad, rad/s) over a sliding window; see the module docstring."""

    def __init__(self, worker: _Worker, target: Sequence[float]) -> None:
        self.w, self.o = worker, worker.o
        self.target = list(target)
        self.tol = math.radians(self.o.in_position_tol_deg)
        self.band = math.radians(self.o.settle_band_deg)
        self.last_ts, self.last_ts_change = worker.rtde_r.getTimestamp(), time.monotonic()
        self.window: deque[tuple[float, list[float], list[float]]] = deque()
        self.arrived_at: float | None = None
        self.still_since: float | None = None

    def wait(self) -> list[float]:
        while True:
            self.w.poll_stop_request()
            self._check_link()
            self.w._check_motion_state()
            done = self._evaluate(self.w.rtde_r.getActualQ(), self.w.rtde_r.getActualQd(), time.monotonic())
            if done is not None:
                return done
            self.w.conn.poll(0.002)     # sleep, but wake up at once for a stop request

    def _check_link(self) -> None:
        r = self.w._receiver()
        self.w._controller()
        ts, now = r.getTimestamp(), time.monotonic()
        if ts != self.last_ts:
            self.last_ts, self.last_ts_change = ts, now
        elif now - self.last_ts_change > self.o.stale_after_s:
            raise _Failure("lost", f"no RTDE data for {self.o.stale_after_s:.1f} s during the move "
                                   f"(controller timestamp stuck at {ts:.3f} s)")

    def _evaluate(self, q: Sequence[float], qd: Sequence[float], now: float) -> list[float] | None:
        """Settled: over a full window, mean q within ``tol`` of the target, each joint's drift (least-squares slope
        of q over time, insensitive to the differentiation noise of actual_qd) below ``settle_qd_rad_s`` and its
        spread within the band. Returns the window's mean q (rad)."""
        q, qd = _six(q, "actual_q"), _six(qd, "actual_qd")
        self.window.append((now, q, qd))
        while now - self.window[0][0] > self.o.settle_hold_s:
            self.window.popleft()
        t = np.array([w[0] for w in self.window])
        qs = np.array([w[1] for w in self.window])                       # (n, 6) rad
        mean_q = qs.mean(axis=0)
        error = float(np.max(np.abs(mean_q - self.target)))
        full = t[-1] - t[0] >= 0.9 * self.o.settle_hold_s
        dt = t - t.mean()
        slope = np.abs(dt @ (qs - mean_q)) / max(float(dt @ dt), 1e-12) if full else np.full(6, np.inf)
        spread = float(np.max(qs.max(axis=0) - qs.min(axis=0)))
        still = full and float(slope.max()) < self.o.settle_qd_rad_s and spread <= self.band
        self.still_since = (self.still_since or now) if still else None
        if error <= self.tol:
            self.arrived_at = self.arrived_at or now
            if still:
                return mean_q.tolist()
            if now - self.arrived_at > self.o.settle_timeout_s:
                raise _Failure("motion", f"in position but not settled (drift {float(slope.max()):.2g} rad/s, "
                                         f"spread {math.degrees(spread):.3g} deg) within {self.o.settle_timeout_s:.1f} s")
        elif still and now - self.still_since > self.o.stall_s:
            raise _Failure("motion", f"robot stopped {math.degrees(error):.4f} deg from the target")
        return None


def _dh_points(q: np.ndarray, dh: tuple, tcp_m: Sequence[float]) -> np.ndarray:
    """TCP positions (K, 3) m for joint rows q (K, 6) rad with standard DH (d, a) and ``UR_DH_ALPHA``."""
    t = np.broadcast_to(np.eye(4), (len(q), 4, 4)).copy()
    for i, (d, a, alpha) in enumerate(zip(dh[0], dh[1], UR_DH_ALPHA)):
        ct, st, ca, sa = np.cos(q[:, i]), np.sin(q[:, i]), math.cos(alpha), math.sin(alpha)
        link = np.zeros((len(q), 4, 4))
        link[:, 0, 0], link[:, 0, 1], link[:, 0, 2], link[:, 0, 3] = ct, -st * ca, st * sa, a * ct
        link[:, 1, 0], link[:, 1, 1], link[:, 1, 2], link[:, 1, 3] = st, ct * ca, -ct * sa, a * st
        link[:, 2, 1], link[:, 2, 2], link[:, 2, 3], link[:, 3, 3] = sa, ca, d, 1.0
        t = t @ link
    return t[:, :3, 3] + t[:, :3, :3] @ np.asarray(tcp_m, float)


def _six(values: Sequence[float], name: str) -> list[float]:
    vals = [float(v) for v in values]
    if len(vals) != 6 or not all(math.isfinite(v) for v in vals):
        raise _Failure("lost", f"{name} is not 6 finite values ({vals}); no valid RTDE data")
    return vals


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
