"""Reference bridge: serves the tracker line protocol (docs/drivers_tracker.md, "Bridge contract") over TCP from a
pluggable back end, so a tracker without a public wire protocol (FARO, API, Leica LMF, SpatialAnalyzer) can be
driven by ``tracker+socket://HOST:PORT`` with ``options: {}`` plus ``goto``/``find`` if the back end can aim.

Standard library only, nothing to pip install, but not a single file: it uses the TCP plumbing, fault deck and
reply encoding of ``drivers/emulators/``. Copy the repository's whole ``drivers/`` folder next to the vendor SDK
(usually on the Windows PC that runs it) and run the module from the folder that holds ``drivers/`` as below
(``python drivers/bridge/line_bridge.py`` does not find the package). ``tests/test_structure.py`` keeps the import
closure free of third-party packages; ``tests/drivers/test_line_bridge.py`` runs such a copy with ``python -S``.

Back ends implement ``Backend``: ``open()``, ``measure() -> Measurement`` (xyz mm in the tracker frame, optional
1-sigma std devs in mm, optional environment), ``environment()``, ``close()``, and optionally ``goto(x, y, z)`` and
``find()``. They signal a failed reading with ``BackendError(kind, text)``, kind one of ``beam_broken``,
``no_target``, ``unstable``, ``timeout``, ``error``.

* ``ReplayBackend`` (tested): replays a CSV ``x,y,z[,sx,sy,sz][,temp_c,pressure_hpa,humidity_pct][,error]``
  (``error``: a kind word for a recorded failure), in order, looping.
* ``FaroSdkBackend``, ``SpatialAnalyzerBackend``: UNTESTED SKELETONS showing where the vendor calls go. They were
  written without access to either SDK and have never run against a device; they raise until completed.

Run: ``python -m drivers.bridge.line_bridge --backend replay --csv session.csv --port 7000`` (``--port 0
--print-port`` prints the bound port). One client at a time; binds 127.0.0.1 unless ``--host`` is given.
"""
from __future__ import annotations

import argparse
import csv
import random
import socket
import sys
from collections import deque
from dataclasses import dataclass
from typing import Mapping, Protocol, Sequence

from drivers.emulators.faults import FaultDeck
from drivers.emulators.tcp import TcpServer, wait_for_shutdown
from drivers.emulators.line_tracker_server import FAULT_ORDER, encode_line, fault_response, join_with_seq
from drivers.emulators.line_tracker_server import Response as Reply  # the sample protocol's reply (one owner)

ERROR_WORDS = {"beam_broken": "BEAM_BROKEN", "no_target": "NO_TARGET", "unstable": "UNSTABLE", "timeout": "TIMEOUT",
               "error": "DEVICE_ERROR"}
POLL_S = 0.05


class BackendError(Exception):
    """A failed device request; ``kind`` is one of ``ERROR_WORDS``."""

    def __init__(self, kind: str, text: str = "") -> None:
        if kind not in ERROR_WORDS:
            raise ValueError(f"unknown error kind {kind!r} (expected one of {', '.join(ERROR_WORDS)})")
        super().__init__(text or kind)
        self.kind = kind


@dataclass(frozen=True)
class Measurement:
    """One SMR reading: xyz (mm, tracker frame), 1-sigma std devs (mm) if known, (temp_c, pressure_hpa,
    humidity_pct) if known."""
    xyz_mm: tuple[float, float, float]
    std_mm: tuple[float, float, float] | None = None
    environment: tuple[float, float, float] | None = None


class Backend(Protocol):
    def open(self) -> None: ...
    def measure(self) -> Measurement: ...
    def environment(self) -> tuple[float, float, float] | None: ...
    def close(self) -> None: ...
    # optional: def goto(self, x_mm: float, y_mm: float, z_mm: float) -> None; def find(self) -> None


# ---------------------------------------------------------------------------------------------------- back ends

class ReplayBackend:
    """Replays recorded readings from a CSV (header row required; see the module docstring), looping."""

    def __init__(self, rows: Sequence[Mapping[str, str]], source: str = "<rows>") -> None:
        if not rows:
            raise ValueError(f"{source}: no rows to replay")
        self.source = source
        self._rows = [self._parse(i + 2, row) for i, row in enumerate(rows)]
        self._next = 0
        self._env = next((r[2] for r in self._rows if r[2] is not None), None)
        self.aim_mm: tuple[float, float, float] | None = None

    @classmethod
    def from_csv(cls, path: str) -> "ReplayBackend":
        with open(path, newline="", encoding="utf-8") as f:
            return cls(list(csv.DictReader(f)), path)

    def _parse(self, line: int, row: Mapping[str, str]):
        def num(key: str) -> float | None:
            text = (row.get(key) or "").strip()
            if not text:
                return None
            try:
                return float(text)
            except ValueError:
                raise ValueError(f"{self.source} line {line} column {key!r}: not a number: {text!r}") from None

        error = (row.get("error") or "").strip()
        if error and error not in ERROR_WORDS:
            raise ValueError(f"{self.source} line {line} column 'error': {error!r} is not one of "
                             f"{', '.join(ERROR_WORDS)}")
        xyz = tuple(num(k) for k in ("x", "y", "z"))
        if not error and None in xyz:
            raise ValueError(f"{self.source} line {line}: x, y, z are required")
        std = tuple(num(k) for k in ("sx", "sy", "sz"))
        env = tuple(num(k) for k in ("temp_c", "pressure_hpa", "humidity_pct"))
        return (xyz, None if None in std else std, None if None in env else env, error)

    def open(self) -> None:
        pass

    def measure(self) -> Measurement:
        xyz, std, env, error = self._rows[self._next]
        self._next = (self._next + 1) % len(self._rows)
        if error:
            raise BackendError(error, f"replayed {error}")
        if env is not None:
            self._env = env
        return Measurement(xyz, std, env)

    def environment(self) -> tuple[float, float, float] | None:
        return self._env

    def goto(self, x_mm: float, y_mm: float, z_mm: float) -> None:
        self.aim_mm = (x_mm, y_mm, z_mm)

    def find(self) -> None:
        pass

    def close(self) -> None:
        pass


class FaroSdkBackend:
    """UNTESTED SKELETON for a FARO tracker through the FARO Tracker SDK (Windows, .NET; e.g. via pythonnet).

    Never run against a device or the SDK: complete and validate it before use (compare with a known artefact).
    """

    def __init__(self, address: str) -> None:
        self.address = address

    def open(self) -> None:
        # import clr; clr.AddReference("FARO.LaserTracker") ; connect to self.address, start up, set SMR type,
        # set units to mm and the measure mode (stationary, averaging time) here.
        raise BackendError("error", "FaroSdkBackend is an untested skeleton: complete open() with the FARO SDK")

    def measure(self) -> Measurement:
        # a stationary measurement; return xyz in mm (tracker frame), the SDK's std devs, the weather values;
        # map "beam broken"/"target not found" SDK errors to BackendError("beam_broken"/"no_target").
        raise BackendError("error", "FaroSdkBackend.measure() not implemented")

    def environment(self) -> tuple[float, float, float] | None:
        return None

    def goto(self, x_mm: float, y_mm: float, z_mm: float) -> None:
        raise BackendError("error", "FaroSdkBackend.goto() not implemented (the SDK's point-at command goes here)")

    def find(self) -> None:
        raise BackendError("error", "FaroSdkBackend.find() not implemented (the SDK's search command goes here)")

    def close(self) -> None:
        pass


class SpatialAnalyzerBackend:
    """UNTESTED SKELETON for New River Kinematics SpatialAnalyzer through its SDK / remote-control interface
    (Windows). SA owns the instrument connection; the bridge asks SA to measure a point and reads it back.

    Never run against SA: complete and validate it before use.
    """

    def __init__(self, collection: str = "A", instrument_id: int = 0) -> None:
        self.collection, self.instrument_id = collection, instrument_id

    def open(self) -> None:
        # connect to SA's SDK, check the instrument (self.instrument_id) is running, set units to mm.
        raise BackendError("error", "SpatialAnalyzerBackend is an untested skeleton: complete open() with the SA SDK")

    def measure(self) -> Measurement:
        # measure a single point into self.collection, read its coordinates in the instrument frame (mm)
        raise BackendError("error", "SpatialAnalyzerBackend.measure() not implemented")

    def environment(self) -> tuple[float, float, float] | None:
        return None

    def close(self) -> None:
        pass


# ------------------------------------------------------------------------------------------------------ protocol

class LineBridge(TcpServer):
    """Serves the line protocol from ``backend`` over TCP (one client at a time, one background thread).

    Test hooks (to check a driver against the contract): ``inject(*faults)`` queues one-shot faults for the next
    MEAS requests (``FAULT_ORDER``); ``probabilities`` draws them at random with ``seed``; ``delay_s`` for ``delay``.
    ``requests``, ``connections`` and ``replies_sent`` count what happened.
    """
    thread_name, label = "line-bridge", "line bridge"
    poll_s = POLL_S

    def __init__(self, backend: Backend, port: int = 0, host: str = "127.0.0.1", *, seed: int = 0,
                 probabilities: Mapping[str, float] | None = None, delay_s: float = 0.5) -> None:
        bad = set(probabilities or {}) - set(FAULT_ORDER)
        if bad:
            raise ValueError(f"unknown faults {sorted(bad)} (expected {', '.join(FAULT_ORDER)})")
        super().__init__(host, port)
        self.backend = backend
        self.probabilities, self.delay_s = dict(probabilities or {}), delay_s
        self._deck = FaultDeck(FAULT_ORDER, random.Random(seed + 7919))
        self.requests: deque[str] = deque(maxlen=1000)
        self.replies_sent = 0

    @property
    def url(self) -> str:
        return f"tracker+socket://{self.host}:{self.port}"

    def inject(self, *faults: str) -> None:
        self._deck.inject(*faults)

    # -- the contract
    def respond(self, line: str) -> Reply:
        """The reply to one request line (terminator stripped)."""
        self.requests.append(line)
        tokens = line.split()
        command, args = (tokens[0].upper(), tokens[1:]) if tokens else ("", [])
        seq = args[0] if (command in ("MEAS", "FIND") and args) or (command == "GOTO" and len(args) == 4) else None
        try:
            if command == "MEAS" and len(args) <= 1:
                return self._measure(seq)
            if command == "INIT" and not args:
                self.backend.open()
                return Reply(encode_line("READY"))
            if command == "ENV" and not args:
                env = self.backend.environment()
                if env is None:
                    return Reply(encode_line("ERR - NO_ENVIRONMENT"))
                return Reply(encode_line(f"ENV {env[0]:.2f} {env[1]:.2f} {env[2]:.1f}"))
            if command == "GOTO" and len(args) in (3, 4) and hasattr(self.backend, "goto"):
                self.backend.goto(*(float(v) for v in args[-3:]))
                return Reply(encode_line(join_with_seq("OK", seq)))
            if command == "FIND" and len(args) <= 1 and hasattr(self.backend, "find"):
                self.backend.find()
                return Reply(encode_line(join_with_seq("OK", seq)))
            if command == "STOP" and not args:
                return Reply(encode_line("STOPPED"))
        except BackendError as exc:
            return Reply(encode_line(join_with_seq("ERR", seq, ERROR_WORDS[exc.kind])))
        except ValueError:
            return Reply(encode_line("ERR - BAD_ARGUMENT"))
        return Reply(encode_line("ERR - UNKNOWN_COMMAND"))

    def _measure(self, seq: str | None) -> Reply:
        fault = self._draw_fault()
        forced = fault_response(fault, seq)
        if forced is not None:
            return forced
        try:
            m = self.backend.measure()
        except BackendError as exc:
            return Reply(encode_line(join_with_seq("ERR", seq, ERROR_WORDS[exc.kind])))
        fields = [f"{v:.5f}" for v in m.xyz_mm] + ([f"{v:.5f}" for v in m.std_mm] if m.std_mm else [])
        return Reply(encode_line(join_with_seq("OK", seq, *fields)), delay_s=self.delay_s if fault == "delay" else 0.0)

    def _draw_fault(self) -> str | None:
        return self._deck.draw(lambda name: self.probabilities.get(name, 0.0))

    # -- transport
    def stop(self, timeout_s: float = 2.0) -> None:
        self._join(timeout_s)
        self.backend.close()

    def _serve_client(self, conn: socket.socket) -> None:
        for raw in self._lines(conn):
            reply = self.respond(raw.decode("ascii", errors="replace").strip())
            if not self._deliver(conn, reply.data, reply.delay_s, reply.disconnect):
                return
            self.replies_sent += bool(reply.data)


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="line_bridge", description="Serve the tracker line protocol from a back end.")
    p.add_argument("--backend", choices=("replay", "faro", "spatialanalyzer"), default="replay")
    p.add_argument("--csv", help="replay: the CSV to replay")
    p.add_argument("--address", default="", help="faro: the tracker's address")
    p.add_argument("--host", default="127.0.0.1", help="address to bind (default 127.0.0.1)")
    p.add_argument("--port", type=int, default=7000, help="TCP port (0: any free port)")
    p.add_argument("--print-port", action="store_true", help="print the bound port as the first stdout line")
    p.add_argument("--ignore-stdin", action="store_true", help="keep serving when stdin is closed")
    args = p.parse_args(argv)
    if args.backend == "replay":
        if not args.csv:
            p.error("--backend replay needs --csv FILE")
        try:
            backend: Backend = ReplayBackend.from_csv(args.csv)
        except (OSError, ValueError) as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 2
    elif args.backend == "faro":
        backend = FaroSdkBackend(args.address)
    else:
        backend = SpatialAnalyzerBackend()
    with LineBridge(backend, args.port, args.host) as bridge:
        if args.print_port:
            print(bridge.port, flush=True)
        print(f"line bridge ({args.backend}) on {args.host}:{bridge.port}", file=sys.stderr, flush=True)
        wait_for_shutdown(watch_stdin=not args.ignore_stdin)
    return 0


if __name__ == "__main__":
    sys.exit(main())
