"""UR worker process: owns the ur_rtde interfaces, serves ``(id, op, args)`` requests, settles moves.

Runs in a ``multiprocessing`` spawn child started by ``drivers.ur.URRobot``; radians throughout.
"""
from __future__ import annotations

import math
import os
import re
import time
from collections import deque
from typing import Any, Mapping, Sequence

import numpy as np

from .ur_options import (PROTECTIVE_STOP, RATED_JOINT_SPEED_RAD_S, RECEIVE_VARIABLES, ROBOT_MODE_IDLE,
                         ROBOT_MODE_POWER_OFF, ROBOT_MODE_RUNNING, ROBOT_MODES, SAFETY_MODE_NORMAL, SAFETY_MODES,
                         TCP_MARGIN, TCP_SAMPLES, UR_DH, UR_DH_ALPHA, UROptions)


class _Failure(Exception):
    """A worker-side failure with its kind: lost, not_ready, motion, robot."""

    def __init__(self, kind: str, message: str) -> None:
        super().__init__(message)
        self.kind = kind


def worker_main(conn: Any, host: str, options: dict[str, Any], log_path: str | None) -> None:
    """Worker process entry: redirect the library's output, then serve requests until close or EOF."""
    _redirect_output(log_path)
    Worker(conn, host, UROptions(**options)).serve()


def _redirect_output(log_path: str | None) -> None:
    """Send fd 1 and 2 (ur_rtde prints with std::cout / std::cerr) to the worker log."""
    fd = os.open(log_path or os.devnull, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o644)
    os.dup2(fd, 1)
    os.dup2(fd, 2)
    os.close(fd)


class Worker:
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
        return Settle(self, q).wait(), capped

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
        points = np.stack([dh_points(q, self.dh, np.asarray(self.tcp_offset[:3]) + d) for d in offsets])
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

    def _check_motion_state(self) -> None:
        """Raise MotionError-kind failures for safety stops, robot mode or a dead control script. The control
        interface's stream can see the script end before the receive stream shows why, and under load the receive
        side may still hold older samples: a dead script is explained from fresh samples for up to
        ``stale_after_s`` before it is reported as such."""
        self._check_modes()
        if self._controller().isProgramRunning():
            return
        deadline = time.monotonic() + self.o.stale_after_s
        while time.monotonic() < deadline:
            self._fresh_timestamp()
            self._check_modes()
        raise _Failure("motion", "the rtde_control script is not running")

    def _check_modes(self) -> None:
        """Raise for a safety mode other than NORMAL/REDUCED or a robot mode other than RUNNING."""
        status = self.op_status()
        self.pstop_seen = self.pstop_seen or status["safety_mode"] == PROTECTIVE_STOP
        if status["safety_mode"] not in (1, 2):
            raise _Failure("motion", f"safety mode {status['safety_mode']} ({status['safety_mode_name']})")
        if status["robot_mode"] != ROBOT_MODE_RUNNING:
            raise _Failure("motion", f"robot mode {status['robot_mode']} ({status['robot_mode_name']})")

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


class Settle:
    """Wait for a move to settle in position (rad, rad/s) over a sliding window; see the module docstring."""

    def __init__(self, worker: Worker, target: Sequence[float]) -> None:
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


def dh_points(q: np.ndarray, dh: tuple, tcp_m: Sequence[float]) -> np.ndarray:
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
