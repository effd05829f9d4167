"""RWS emulator: fault injection and operator actions (a mixin of ``RwsEmulator``)."""

from __future__ import annotations

import logging
from datetime import datetime

from .rws_http import Fault, Holder, domain_key

log = logging.getLogger("drivers.emulators.rws_server")


class FaultsMixin:
    """Test hooks that change the emulated controller as an operator or a fault would."""

    # -- fault injection and operator actions

    def inject_503(self, count: int) -> None:
        """The next ``count`` requests answer 503 (session pool exhausted)."""
        with self._lock:
            self._fail_503 = count

    def inject_401(self, count: int = 1) -> None:
        """The next ``count`` requests answer 401 and their session expires (cookies and nonces forgotten)."""
        with self._lock:
            self._fail_401 = count

    def expire_sessions(self) -> None:
        """Drop every session and nonce (as after a controller-side timeout)."""
        with self._lock:
            for sid in list(self._sessions):
                self._drop_session(sid)
            self._nonces.clear()

    def fail_next_move(self, kind: str, *, message: str = "", code: int = 0, after_s: float = 0.0) -> None:
        """Make the next CalServer motion request fail: ``error`` (cal_err_seq with ``message``), ``motors_off``
        (guard stop: motors off, RAPID stopped), ``rapid_stop`` (execution error ``code`` in the elog, RAPID
        stopped) or ``hang`` (acknowledged, never done); applied ``after_s`` after the acknowledgement."""
        if kind not in ("error", "motors_off", "rapid_stop", "hang"):
            raise ValueError(f"unknown fault kind {kind!r}")
        with self._lock:
            self._faults.append(Fault(kind, message, code, after_s))

    def set_opmode(self, mode: str) -> None:
        """Turn the mode key (AUTO, MANR, MANF)."""
        with self._lock:
            self.opmode = mode
            if mode != "AUTO" and self.execution == "running":
                self._stop_program(1, 10125, "Program stopped", "mode change")

    def set_ctrlstate(self, state: str) -> None:
        """Operator / safety change of the controller state; leaving motoron stops RAPID."""
        with self._lock:
            self.ctrlstate = state
            if state != "motoron" and self.execution == "running":
                self._stop_program(1, 10010, "Motors OFF state", f"ctrlstate {state}")

    def set_execution(self, running: bool) -> None:
        """Operator start/stop from the FlexPendant (no rule checks)."""
        with self._lock:
            if running:
                self.execution = "running"
            else:
                self._stop_program(1, 10125, "Program stopped", "stopped by operator")
        self._wake.set()

    def hold_mastership(self, domain: str, application: str = "RobotStudio", location: str = "local",
                        release_after: int | None = None) -> None:
        """A foreign client (RobotStudio, FlexPendant editor) takes mastership of ``domain``; with
        ``release_after`` it lets go after refusing that many mastership requests (a short edit)."""
        with self._lock:
            self.mastership[domain_key(domain)] = Holder(None, application, location)
            if release_after is not None:
                self._foreign_refusals[domain_key(domain)] = release_after

    def release_foreign_mastership(self, domain: str) -> None:
        with self._lock:
            self.mastership.pop(domain_key(domain), None)

    def add_elog(self, msgtype: int, code: int, title: str, desc: str = "") -> int:
        """Append an event log entry; returns its sequence number."""
        with self._lock:
            self._elog_seq = (self._elog_seq + 1) % 65536
            self.elog.append({"seqnum": self._elog_seq, "msgtype": msgtype, "code": code, "title": title,
                              "desc": desc, "tstamp": datetime.now().strftime("%Y-%m-%d T %H:%M:%S")})
            return self._elog_seq
