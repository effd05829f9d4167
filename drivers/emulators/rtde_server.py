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
import socket
import sys
import threading
import time
from typing import Sequence

from drivers.ur_options import ROBOT_MODES, SAFETY_MODES

from .rtde_controller import CB3_VERSION, NORMAL, PROTECTIVE_STOP, RUNNING, ArmedFault, Controller, JointNoise
from .rtde_protocol import DASHBOARD_PORT, RTDE_PORT, SCRIPT_PORTS
from .rtde_sessions import ControlSession, DashboardSession, RtdeSession, ScriptSession, Session
from .tcp import close_quietly, listen


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
        self.listeners = {port: (listen(host, port), kind) for port, kind in kinds.items()}
        self.control_listener = listen(host, control_port)
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
                close_quietly(sock)
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
            close_quietly(sock)
        close_quietly(self.control_listener)
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


if __name__ == "__main__":
    raise SystemExit(main())
