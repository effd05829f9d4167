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
import tempfile
import threading
import time
from dataclasses import asdict
from typing import Any, Mapping, Sequence
from urllib.parse import urlsplit

from .base import ConnectionLost, DriverError, MotionError, MotionLimits, Payload, RobotError, RobotNotReady
from .ur_options import (BOOL_OPTIONS, JOINT_ACCELERATION_MAX_RAD_S2, JOINT_SPEED_MAX_RAD_S,  # noqa: F401
                         ROBOT_MODES, SAFETY_MODES, UR_DH, InvalidTarget, UROptions, validate_options)
from .ur_worker import dh_points, Settle, Worker, worker_main  # noqa: F401  (re-exported for tests)


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
        self._proc = ctx.Process(target=worker_main, args=(child, self.host, asdict(self.options), self._log_path),
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
