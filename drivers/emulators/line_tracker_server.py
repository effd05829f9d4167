"""TCP laser-tracker emulator speaking the sample line protocol of ``drivers.line_tracker`` (its default profile).

Sample protocol (ASCII, one request per line, ``\\r\\n`` terminated both ways; ``<seq>`` is echoed, and omitted from
the reply if the request has none):

====================  ==========================================================================================
request               reply
====================  ==========================================================================================
``INIT``              ``READY``
``MEAS <seq>``        ``OK <seq> <x> <y> <z> <sx> <sy> <sz>`` (mm, tracker frame; device std in mm), or in
                      ``spherical`` mode ``OK <seq> <r_mm> <az_deg> <zen_deg>`` (az ccw from +x, zen from +z)
                      errors: ``ERR <seq> BEAM_BROKEN``, ``ERR <seq> NO_TARGET``, ``ERR <seq> UNSTABLE``
``ENV``               ``ENV <temp_c> <pressure_hpa> <humidity_pct>``
``STOP``              ``STOPPED``
anything else         ``ERR - UNKNOWN_COMMAND``
====================  ==========================================================================================

Faults (per ``MEAS``; probabilities drawn from a seeded RNG, or queued one-shot with ``inject``): ``beam_break``,
``no_target``, ``unstable`` (error replies), ``garbage`` (a line of junk), ``drop`` (no reply), ``delay`` (the reply
is sent ``delay_s`` later, after the client's timeout: a stale late reply), ``disconnect`` (the server closes the
connection). One client is served at a time, on 127.0.0.1 only.

Run standalone: ``python -m drivers.emulators.line_tracker_server --port 0 --print-port`` prints the bound port as the
first stdout line and serves until killed, interrupted, or its stdin is closed (``--ignore-stdin`` to disable that).
"""
from __future__ import annotations

import argparse
import math
import random
import socket
import sys
import threading
from collections import deque
from dataclasses import dataclass, fields, replace
from typing import Callable, Mapping, Sequence

from .faults import FaultDeck
from .tcp import TcpServer, wait_for_shutdown

HOST = "127.0.0.1"
POLL_S = 0.05
DEFAULT_POINT_MM = (1500.0, -250.0, 1200.0)
GARBAGE = b"\xa7#%!?@@ \x01garbage\r\n"
ERROR_WORDS = {"beam_break": "BEAM_BROKEN", "no_target": "NO_TARGET", "unstable": "UNSTABLE"}
FAULT_ORDER = ("disconnect", "drop", "delay", "garbage", "beam_break", "no_target", "unstable")

PositionSource = Callable[[], Sequence[float]]


@dataclass(frozen=True)
class Faults:
    """Per-``MEAS`` fault probabilities in [0, 1] (checked in ``FAULT_ORDER``); ``delay_s`` (s) for ``delay``."""
    beam_break: float = 0.0
    no_target: float = 0.0
    unstable: float = 0.0
    garbage: float = 0.0
    drop: float = 0.0
    delay: float = 0.0
    disconnect: float = 0.0
    delay_s: float = 0.5

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name != "delay_s" and not 0.0 <= value <= 1.0:
                raise ValueError(f"fault {f.name!r}: probability {value!r} not in [0, 1]")
        if not self.delay_s >= 0.0:
            raise ValueError(f"fault 'delay_s': expected >= 0 s, got {self.delay_s!r}")


def _faults(value: Faults | Mapping[str, float] | None) -> Faults:
    if isinstance(value, Faults):
        return value
    unknown = set(value or {}) - {f.name for f in fields(Faults)}
    if unknown:
        raise ValueError(f"unknown faults {sorted(unknown)} (expected {', '.join(f.name for f in fields(Faults))})")
    return Faults(**dict(value or {}))


@dataclass(frozen=True)
class Response:
    """What to do with one request: send ``data`` after ``delay_s`` s (nothing if empty), or drop the connection."""
    data: bytes = b""
    delay_s: float = 0.0
    disconnect: bool = False


class SampleDevice:
    """The sample protocol without I/O: ``respond(line) -> Response``. Thread-safe fault settings."""

    def __init__(self, position_source: PositionSource | None = None,
                 faults: Faults | Mapping[str, float] | None = None, *, mode: str = "cartesian", seed: int = 0,
                 noise_mm: float = 0.002, std_mm: float = 0.005,
                 environment: tuple[float, float, float] = (20.0, 1013.25, 45.0)) -> None:
        if mode not in ("cartesian", "spherical"):
            raise ValueError(f"mode: expected cartesian or spherical, got {mode!r}")
        self.mode, self.noise_mm, self.std_mm, self.environment = mode, noise_mm, std_mm, environment
        self._noise_rng = random.Random(seed)
        self._deck = FaultDeck(FAULT_ORDER, random.Random(seed + 7919))
        self._position = position_source or self._default_position
        self._lock = threading.Lock()
        self._faults = _faults(faults)
        self.requests: deque[str] = deque(maxlen=1000)

    @property
    def faults(self) -> Faults:
        return self._faults

    def set_faults(self, **changes: float) -> None:
        """Change fault probabilities (or ``delay_s``) at runtime."""
        with self._lock:
            self._faults = replace(self._faults, **changes)

    def inject(self, *names: str) -> None:
        """Queue one-shot faults, consumed by the next ``MEAS`` requests in order (before any random draw)."""
        self._deck.inject(*names)

    def respond(self, line: str) -> Response:
        """The response to one request line (terminator already stripped)."""
        self.requests.append(line)
        tokens = line.split()
        command, args = (tokens[0].upper(), tokens[1:]) if tokens else ("", [])
        if command == "MEAS" and len(args) <= 1:
            return self._measure(args[0] if args else None)
        simple = {"INIT": "READY", "STOP": "STOPPED", "ENV": self._environment_line()}
        if command in simple and not args:
            return Response(encode_line(simple[command]))
        return Response(encode_line("ERR - UNKNOWN_COMMAND"))

    def _measure(self, seq: str | None) -> Response:
        fault = self._draw_fault()
        forced = fault_response(fault, seq)
        if forced is not None:
            return forced
        data = encode_line(join_with_seq("OK", seq, *self._fields()))
        return Response(data, delay_s=self._faults.delay_s if fault == "delay" else 0.0)

    def _draw_fault(self) -> str | None:
        faults = self._faults
        return self._deck.draw(lambda name: getattr(faults, name))

    def _fields(self) -> list[str]:
        x, y, z = (float(v) for v in self._position())
        if self.mode == "spherical":
            r = math.sqrt(x * x + y * y + z * z)
            zen = math.degrees(math.acos(z / r)) if r > 0 else 0.0
            return [f"{r:.5f}", f"{math.degrees(math.atan2(y, x)):.9f}", f"{zen:.9f}"]
        return [f"{v:.5f}" for v in (x, y, z)] + [f"{self.std_mm:.5f}"] * 3

    def _default_position(self) -> tuple[float, float, float]:
        """A fixed point (mm) plus Gaussian noise of ``noise_mm`` per axis."""
        return tuple(c + self._noise_rng.gauss(0.0, self.noise_mm) for c in DEFAULT_POINT_MM)

    def _environment_line(self) -> str:
        t, p, h = self.environment
        return f"ENV {t:.2f} {p:.2f} {h:.1f}"


def fault_response(fault: str | None, seq: str | None) -> Response | None:
    """The reply a ``MEAS`` fault forces instead of a reading; ``None`` for no fault or ``delay`` (reply, later)."""
    if fault == "disconnect":
        return Response(disconnect=True)
    if fault == "drop":
        return Response()
    if fault == "garbage":
        return Response(GARBAGE)
    if fault in ERROR_WORDS:
        return Response(encode_line(join_with_seq("ERR", seq, ERROR_WORDS[fault])))
    return None


def join_with_seq(word: str, seq: str | None, *rest: str) -> str:
    """``word [seq] rest...`` separated by spaces (the seq only when the request carried one)."""
    return " ".join([word] + ([seq] if seq is not None else []) + list(rest))


def encode_line(text: str) -> bytes:
    """One ASCII reply line with its ``\\r\\n`` terminator."""
    return text.encode("ascii") + b"\r\n"


class TrackerEmulator(TcpServer):
    """The sample device served over TCP on 127.0.0.1 by one background thread; use as a context manager.

    ``port=0`` picks a free port (read it from ``.port``; ``.url`` is the driver URL). ``stop()`` joins the thread.
    ``connections`` and ``replies_sent`` count accepted clients and reply lines sent (for tests).
    Keyword arguments after ``port`` go to ``SampleDevice`` (``mode``, ``seed``, ``noise_mm``, ``std_mm``, ...).
    """
    thread_name, label = "tracker-emulator", "tracker emulator"
    poll_s = POLL_S

    def __init__(self, position_source: PositionSource | None = None,
                 faults: Faults | Mapping[str, float] | None = None, port: int = 0, **device_options) -> None:
        super().__init__(HOST, port)
        self.device = SampleDevice(position_source, faults, **device_options)
        self.replies_sent = 0

    @property
    def url(self) -> str:
        return f"tracker+socket://{HOST}:{self.port}"

    def set_faults(self, **changes: float) -> None:
        self.device.set_faults(**changes)

    def inject(self, *names: str) -> None:
        self.device.inject(*names)

    def _serve_client(self, conn: socket.socket) -> None:
        conn.settimeout(1.0)
        for line in self._lines(conn):
            if not self._answer(conn, line):
                return

    def _answer(self, conn: socket.socket, raw: bytes) -> bool:
        """Handle one request; ``False`` when the connection must end."""
        response = self.device.respond(raw.decode("ascii", errors="replace").strip())
        if not self._deliver(conn, response.data, response.delay_s, response.disconnect):
            return False
        self.replies_sent += bool(response.data)
        return True


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m drivers.emulators.line_tracker_server",
                                description="Laser-tracker emulator (sample line protocol) on 127.0.0.1.")
    p.add_argument("--port", type=int, default=0, help="TCP port (0: any free port)")
    p.add_argument("--print-port", action="store_true", help="print the bound port as the first stdout line")
    p.add_argument("--mode", choices=("cartesian", "spherical"), default="cartesian")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--ignore-stdin", action="store_true", help="keep serving when stdin is closed")
    for name in FAULT_ORDER:
        p.add_argument(f"--{name.replace('_', '-')}", type=float, default=0.0, metavar="P",
                       help=f"probability of a {name} fault per MEAS")
    p.add_argument("--delay-s", type=float, default=0.5, help="delay of a delayed reply (s)")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    faults = {name: getattr(args, name) for name in FAULT_ORDER} | {"delay_s": args.delay_s}
    with TrackerEmulator(faults=faults, port=args.port, mode=args.mode, seed=args.seed) as emulator:
        if args.print_port:
            print(emulator.port, flush=True)
        print(f"tracker emulator ({args.mode}) on {HOST}:{emulator.port}", file=sys.stderr, flush=True)
        wait_for_shutdown(watch_stdin=not args.ignore_stdin)
    return 0


if __name__ == "__main__":
    sys.exit(main())
