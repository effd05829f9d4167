"""Native Leica emScon tracker driver (AT9x0 / AT40x, binary C structs over TCP port 700): ``emscon://HOST[:PORT]``.

Byte layout in ``drivers.emscon_protocol`` (from the public header ``ES_C_API_Def.h``). ``connect()`` opens the socket,
reads GetSystemStatus and runs Initialize if the tracker is not initialised (``init_timeout_s``, default 90 s), then
sets units (mm, degrees, deg C, mbar, %RH), the right-handed Cartesian system, stationary mode with
``meas_time_ms``, the system settings (weather monitor, keep last position, unsolicited messages on), the
statistic mode (extended: results with covariances), the reflector (``reflector`` option) and, for manual meteo,
the environment. ``measure()`` sends StartMeasurement and returns the ``SingleMeasResult`` as a ``TrackerReading``:
xyz in mm (tracker frame) with ``extra`` std_x/y/z_mm, cov_xy/xz/yz_mm2 (extended mode) and the temp_c,
pressure_hpa, humidity_pct the tracker used.

Faults: a broken beam or lost target (status MeasurementStatusNotReady / SystemNotReadyForMeasurement /
NoStationaryResult, as a command status or an unsolicited error packet) -> ``BeamBroken``; ``reacquire(p)`` then
aims (GoPosition) and searches (FindReflector) -> ``TargetNotFound`` if it fails. "Not initialised" -> Initialize and
one more attempt, inside ``measure()``. A lost connection -> one reconnect (full setup) and one more attempt; bytes
that are not emScon packets -> ``GarbageReply`` and the connection is reopened on the next call. No reply before
the deadline -> ``TrackerTimeout``; a late result is recognised (it precedes the next command's reply) and dropped.
Every recovery step is queued as an event (``drain_events()``) for the run log. Every call is bounded in time.
"""
from __future__ import annotations

import math
import select
import socket
import time
from dataclasses import dataclass
from typing import Any, Mapping, Sequence
from urllib.parse import urlsplit

from . import emscon_protocol as P
from .base import (BeamBroken, ConnectionLost, DriverConfigError, DriverError, GarbageReply, TargetNotFound, TrackerError, TrackerReading,
                   TrackerTimeout, Unstable)

POLL_S = 0.02


class NotInitialised(TrackerError):
    kind = "not_initialised"


class NotReady(TrackerError):
    """Warming up, not levelled, busy: the device may be ready later."""
    kind = "not_ready"


BEAM_STATUSES = {P.RS_MEASUREMENT_STATUS_NOT_READY, P.RS_SYSTEM_NOT_READY_FOR_MEASUREMENT, P.RS_NO_STATIONARY_RESULT}
NOT_READY_STATUSES = {P.RS_SERVER_BUSY, P.RS_SENSOR_NOT_WARMED_UP, P.RS_SENSOR_NOT_LEVELED}


def status_error(status: int, where: str) -> TrackerError:
    """The exception for a non-OK ``ES_ResultStatus`` (one-line message naming it)."""
    text = f"{where}: {P.status_name(status)}"
    if status in BEAM_STATUSES:
        return BeamBroken(text)
    if status == P.RS_TRACKER_NOT_INITIALIZED:
        return NotInitialised(text)
    if status == P.RS_SENSOR_NOT_STABLE:
        return Unstable(text)
    if status in NOT_READY_STATUSES:
        return NotReady(text)
    return TrackerError(text)


@dataclass(frozen=True)
class EmsconSettings:
    """Validated driver options (see ``from_options``)."""
    timeout_s: float = 5.0
    init_timeout_s: float = 90.0
    connect_timeout_s: float = 5.0
    meas_time_ms: int = 2000
    use_adm: bool = True
    reflector: str | int | None = None
    weather: str = "station"                  # station | manual
    environment: tuple[float, float, float] | None = None   # manual temp_c, pressure_hpa, humidity_pct
    statistic: str = "extended"               # extended | standard
    search_timeout_s: float = 20.0
    move_timeout_s: float = 10.0
    reconnect: bool = True

    @classmethod
    def from_options(cls, options: Mapping[str, Any] | None) -> "EmsconSettings":
        """``tracker.options`` -> settings; ``DriverError`` naming the first bad option."""
        opts = dict(options or {})
        unknown = set(opts) - set(cls.__dataclass_fields__)
        if unknown:
            raise DriverConfigError(f"emscon option {sorted(unknown)[0]!r}: unknown "
                              f"(expected one of {', '.join(cls.__dataclass_fields__)})")
        out = {}
        for key in ("timeout_s", "init_timeout_s", "connect_timeout_s", "search_timeout_s", "move_timeout_s"):
            if key in opts:
                out[key] = _positive(key, opts[key])
        if "meas_time_ms" in opts:
            value = opts["meas_time_ms"]
            if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= 100000:
                raise DriverConfigError(f"emscon option 'meas_time_ms': expected an integer in [1, 100000], got {value!r}")
            out["meas_time_ms"] = value
        for key in ("use_adm", "reconnect"):
            if key in opts:
                if not isinstance(opts[key], bool):
                    raise DriverConfigError(f"emscon option {key!r}: expected true or false, got {opts[key]!r}")
                out[key] = opts[key]
        if opts.get("reflector") is not None:
            if isinstance(opts["reflector"], bool) or not isinstance(opts["reflector"], (str, int)):
                raise DriverConfigError("emscon option 'reflector': expected a reflector id or name, "
                                  f"got {opts['reflector']!r}")
            out["reflector"] = opts["reflector"]
        env = opts.get("environment", "station")
        if env == "station":
            out["weather"] = "station"
        elif isinstance(env, Mapping) and set(env) == {"temp_c", "pressure_hpa", "humidity_pct"}:
            out["weather"] = "manual"
            out["environment"] = tuple(_finite(f"environment.{k}", env[k]) for k in ("temp_c", "pressure_hpa",
                                                                                   "humidity_pct"))
        else:
            raise DriverConfigError("emscon option 'environment': expected 'station' or {temp_c, pressure_hpa, "
                              f"humidity_pct}}, got {env!r}")
        if opts.get("statistic", "extended") not in ("extended", "standard"):
            raise DriverConfigError(f"emscon option 'statistic': expected extended or standard, got {opts['statistic']!r}")
        out["statistic"] = opts.get("statistic", "extended")
        return cls(**out)


def _finite(key: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise DriverConfigError(f"emscon option {key!r}: expected a number, got {value!r}")
    return float(value)


def _positive(key: str, value: Any) -> float:
    v = _finite(key, value)
    if v <= 0:
        raise DriverConfigError(f"emscon option {key!r}: expected a number > 0, got {value!r}")
    return v


def parse_url(url: str) -> tuple[str, int]:
    """``emscon://HOST[:PORT]`` -> (host, port); port 700 by default."""
    parts = urlsplit(url)
    if parts.scheme != "emscon" or not parts.hostname:
        raise DriverConfigError(f"tracker url {url!r}: expected emscon://HOST[:PORT]")
    try:
        return parts.hostname, parts.port or P.DEFAULT_PORT
    except ValueError:
        raise DriverConfigError(f"tracker url {url!r}: bad port") from None


class EmsconTracker:
    """A Leica tracker through emScon; implements ``drivers.base.Tracker`` plus ``reacquire``, ``identity``,
    ``drain_events``. ``stale_discarded`` counts late packets dropped."""

    def __init__(self, url: str, settings: EmsconSettings, *, clock: Any = None) -> None:
        self.url, self.settings = url, settings
        self.host, self.port = parse_url(url)
        self._clock = clock
        self._sock: socket.socket | None = None
        self._reader = P.PacketReader()
        self._connected_once = False
        self._events: list[dict] = []
        self._env: dict[str, float] = {}
        self._identity: dict[str, str] = {}
        self.meas_ready = True
        self.stale_discarded = 0
        self.reflector_name = ""

    # ------------------------------------------------------------------------------------------ Tracker protocol
    def connect(self) -> None:
        """Open, initialise if needed, configure. ``ConnectionLost`` / ``TrackerError`` with the reason."""
        self._open()
        try:
            status = self._system_status()
            if status[1] != P.TPS_INITIALIZED:
                self._initialize()
            self._configure()
        except Exception:
            self._drop()
            raise
        self._connected_once = True

    def measure(self) -> TrackerReading:
        """One stationary measurement (mm, tracker frame) with the device's std devs and environment."""
        for attempt in (0, 1):
            try:
                if self._sock is None and self._connected_once:
                    self._note("reconnect", reason="connection was reset (garbage or lost link)")
                    self.connect()
                return self._measure_once()
            except NotInitialised as exc:
                if attempt:
                    raise
                self._note("initialize", reason=str(exc))
                self._initialize()
                self._configure()
            except ConnectionLost as exc:
                if attempt or not self.settings.reconnect:
                    raise
                self._note("reconnect", reason=str(exc))
                self.connect()
        raise AssertionError("unreachable")

    def environment(self) -> dict[str, float]:
        """temp_c, pressure_hpa, humidity_pct used by the last measurement (else read with GetEnvironmentParams)."""
        if not self._env and self._sock is not None:
            reply = self._command(P.C_GET_ENVIRONMENT_PARAMS, timeout_s=self.settings.timeout_s)
            t, p, h = P.RESULTS[P.C_GET_ENVIRONMENT_PARAMS].unpack_from(reply.payload)
            self._env = {"temp_c": t, "pressure_hpa": p, "humidity_pct": h}
        return dict(self._env)

    def reacquire(self, p_tracker_mm_guess: Sequence[float]) -> None:
        """Aim at the predicted SMR position (GoPosition, mm) and search (FindReflector); ``TargetNotFound`` if not."""
        x, y, z = (float(v) for v in p_tracker_mm_guess)
        if self._sock is None:
            self.connect()
        self._note("go_position", p_tracker_mm=[round(x, 3), round(y, 3), round(z, 3)])
        try:
            self._command(P.C_GO_POSITION, x, y, z, int(self.settings.use_adm), timeout_s=self.settings.move_timeout_s)
            self._note("find_reflector", approx_distance_mm=round(math.sqrt(x * x + y * y + z * z), 3))
            self._command(P.C_FIND_REFLECTOR, math.sqrt(x * x + y * y + z * z),
                          timeout_s=self.settings.search_timeout_s)
        except TrackerError as exc:
            self._note("reacquire_failed", reason=str(exc))
            raise TargetNotFound(f"{self.url}: reflector not found near the predicted position "
                                 f"({x:.1f}, {y:.1f}, {z:.1f}) mm: {exc}") from None
        self.meas_ready = True
        self._note("reacquired")

    def identity(self) -> dict[str, str]:
        return dict(self._identity)

    def drain_events(self) -> list[dict]:
        """Recovery steps since the last call (``{"step": ..., ...}``), oldest first."""
        events, self._events = self._events, []
        return events

    def close(self) -> None:
        self._drop()

    def __enter__(self) -> "EmsconTracker":
        self.connect()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------------------------------- session setup
    def _system_status(self) -> tuple:
        reply = self._command(P.C_GET_SYSTEM_STATUS, timeout_s=self.settings.timeout_s)
        values = P.RESULTS[P.C_GET_SYSTEM_STATUS].unpack_from(reply.payload)
        self._identity = {"vendor": "Leica", "model": "emScon tracker", "serial": str(values[9]),
                          "firmware": f"emScon {values[4]}.{values[5]}.{values[6]}"}
        return values

    def _initialize(self) -> None:
        self._command(P.C_INITIALIZE, timeout_s=self.settings.init_timeout_s)

    def _configure(self) -> None:
        s, t = self.settings, self.settings.timeout_s
        self._command(P.C_SET_UNITS, P.LU_MILLIMETER, P.AU_DEGREE, P.TU_CELSIUS, P.PU_MBAR, P.HU_RH, timeout_s=t)
        self._command(P.C_SET_COORDINATE_SYSTEM_TYPE, P.CS_RHR, timeout_s=t)
        self._command(P.C_SET_MEASUREMENT_MODE, P.MM_STATIONARY, timeout_s=t)
        self._command(P.C_SET_STATIONARY_MODE_PARAMS, s.meas_time_ms, int(s.use_adm), timeout_s=t)
        current = P.RESULTS[P.C_GET_SYSTEM_SETTINGS].unpack_from(
            self._command(P.C_GET_SYSTEM_SETTINGS, timeout_s=t).payload)
        wms = P.WMS_READ_AND_CALCULATE if s.weather == "station" else P.WMS_NOT_CONNECTED
        # weather monitor, apply transformation 0, apply station orientation 0, keep last position 1,
        # unsolicited messages 1, reflector position stream 0, try mode 0, then the read-only nivel/camera flags
        self._command(P.C_SET_SYSTEM_SETTINGS, wms, 0, 0, 1, 1, 0, 0, current[7], current[8], timeout_s=t)
        if s.weather == "manual":
            self._command(P.C_SET_ENVIRONMENT_PARAMS, *s.environment, timeout_s=t)
        try:
            mode = P.SM_EXTENDED if s.statistic == "extended" else P.SM_STANDARD
            self._command(P.C_SET_STATISTIC_MODE, mode, P.SM_STANDARD, timeout_s=t)
        except TrackerError as exc:                  # older servers: standard results without covariances
            self._note("statistic_mode_unavailable", reason=str(exc))
        if s.reflector is not None:
            self._set_reflector(s.reflector)

    def _set_reflector(self, wanted: str | int) -> None:
        t = self.settings.timeout_s
        replies = self._command(P.C_GET_REFLECTORS, timeout_s=t, all_replies=True)
        table = []
        for reply in replies:
            total, rid, ttype, offset, raw = P.RESULTS[P.C_GET_REFLECTORS].unpack_from(reply.payload)
            name = raw.decode("utf-16-le", errors="replace").split("\x00", 1)[0]
            table.append((rid, P.TARGET_TYPES.get(ttype, str(ttype)), offset, name))
        match = [r for r in table if wanted in (r[0], r[1], r[3]) or str(wanted) in (str(r[0]), r[1], r[3])]
        if not match:
            raise DriverConfigError(f"{self.url}: reflector {wanted!r} not known to the tracker (it has: "
                              f"{', '.join(f'{r[0]} {r[3]} ({r[1]})' for r in table)})")
        rid, ttype, offset, name = match[0]
        self._command(P.C_SET_REFLECTOR, rid, timeout_s=t)
        self.reflector_name = f"{name} ({ttype}, surface offset {offset:g} mm)"

    # ------------------------------------------------------------------------------------------- measurement
    def _measure_once(self) -> TrackerReading:
        self._command(P.C_START_MEASUREMENT, timeout_s=self.settings.timeout_s)
        wait_s = self.settings.meas_time_ms / 1000.0 + self.settings.timeout_s
        deadline = time.monotonic() + wait_s
        while True:
            packet = self._next(deadline)
            if packet is None:
                raise TrackerTimeout(f"{self.url}: no measurement result within {wait_s:g} s")
            if isinstance(packet, P.MeasResult):
                if packet.status != P.RS_ALL_OK:
                    raise status_error(packet.status, f"{self.url}: measurement")
                return self._reading(packet)
            if isinstance(packet, P.ErrorPacket):
                raise status_error(packet.status, f"{self.url}: unsolicited error during the measurement")

    def _reading(self, r: P.MeasResult) -> TrackerReading:
        t_s = self._clock.now() if self._clock is not None else time.time()
        if not all(math.isfinite(v) for v in r.values):
            raise GarbageReply(f"{self.url}: non-finite coordinates {r.values}")
        extra = {"std_x_mm": r.std[0], "std_y_mm": r.std[1], "std_z_mm": r.std[2]}
        if r.extended:
            extra.update({"cov_xy_mm2": r.covar[0], "cov_xz_mm2": r.covar[1], "cov_yz_mm2": r.covar[2]})
        self._env = {"temp_c": r.environment[0], "pressure_hpa": r.environment[1], "humidity_pct": r.environment[2]}
        extra.update(self._env)
        return TrackerReading(tuple(float(v) for v in r.values), t_s, extra)

    # ------------------------------------------------------------------------------------------- transport
    def _open(self) -> None:
        self._drop()
        try:
            sock = socket.create_connection((self.host, self.port), timeout=self.settings.connect_timeout_s)
        except OSError as exc:
            raise ConnectionLost(f"{self.url}: cannot connect to {self.host}:{self.port}: {exc}") from exc
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        sock.settimeout(self.settings.timeout_s)
        self._sock = sock
        self._reader.clear()

    def _drop(self) -> None:
        sock, self._sock = self._sock, None
        self._reader.clear()
        if sock is not None:
            try:
                sock.close()
            except OSError:
                pass

    def _send(self, data: bytes) -> None:
        if self._sock is None:
            raise ConnectionLost(f"{self.url}: not connected (call connect())")
        try:
            self._sock.sendall(data)
        except OSError as exc:
            self._drop()
            raise ConnectionLost(f"{self.url}: {exc}") from exc

    def _next(self, deadline: float | None) -> P.Packet | None:
        """The next packet (``None`` at ``deadline``; ``deadline`` None: only what is already received).
        Status changes update ``meas_ready``; framing errors drop the connection (``GarbageReply``)."""
        while True:
            try:
                raw = self._reader.next_packet()
                if raw is not None:
                    packet = P.decode_packet(raw)
                    if isinstance(packet, P.StatusChange):
                        if packet.code in (P.SSC_MEAS_STATUS_NOT_READY, P.SSC_MEAS_STATUS_READY):
                            self.meas_ready = packet.code == P.SSC_MEAS_STATUS_READY
                    return packet
            except P.FramingError as exc:
                self._drop()
                raise GarbageReply(f"{self.url}: {exc}") from None
            if self._sock is None:
                raise ConnectionLost(f"{self.url}: not connected (call connect())")
            wait = 0.0 if deadline is None else deadline - time.monotonic()
            if deadline is not None and wait <= 0:
                return None
            try:
                ready = select.select([self._sock], [], [], min(max(wait, 0.0), POLL_S))[0]
                data = self._sock.recv(65536) if ready else None
            except OSError as exc:
                self._drop()
                raise ConnectionLost(f"{self.url}: {exc}") from exc
            if data is None:
                if deadline is None:
                    return None
                continue
            if not data:
                self._drop()
                raise ConnectionLost(f"{self.url}: the tracker closed the connection")
            self._reader.feed(data)

    def _drain(self) -> None:
        """Consume everything already received: late results (counted), unsolicited errors (noted)."""
        while (packet := self._next(None)) is not None:
            if isinstance(packet, (P.MeasResult, P.CommandReply)):
                self.stale_discarded += 1
            elif isinstance(packet, P.ErrorPacket):
                self._note("unsolicited_error", status=P.status_name(packet.status))

    def _command(self, command: int, *params, timeout_s: float, all_replies: bool = False):
        """Send one command and return its reply (``all_replies``: the list of a multi-packet answer).
        Non-OK status -> the mapped ``TrackerError``; nothing before ``timeout_s`` -> ``TrackerTimeout``."""
        self._drain()
        self._send(P.encode_command(command, *params))
        deadline = time.monotonic() + timeout_s
        replies: list[P.CommandReply] = []
        while True:
            packet = self._next(deadline)
            if packet is None:
                raise TrackerTimeout(f"{self.url}: no reply to command {command} within {timeout_s:g} s")
            if isinstance(packet, P.CommandReply) and packet.command == command:
                if packet.status != P.RS_ALL_OK:
                    raise status_error(packet.status, f"{self.url}: command {command}")
                if not all_replies:
                    return packet
                replies.append(packet)
                total = P.RESULTS[command].unpack_from(packet.payload)[0] if packet.payload else 0
                if len(replies) >= total:
                    return replies
            elif isinstance(packet, P.ErrorPacket) and packet.command == command:
                raise status_error(packet.status, f"{self.url}: command {command}")
            elif isinstance(packet, (P.MeasResult, P.CommandReply)):
                self.stale_discarded += 1             # a late answer to an earlier request

    def _note(self, step: str, **fields: Any) -> None:
        self._events.append({"step": step, **fields})


def open_tracker(url: str, options: Mapping[str, Any] | None = None, **context: Any) -> EmsconTracker:
    """Registry factory: an ``EmsconTracker`` for ``url`` (not yet connected); context ``clock`` stamps readings."""
    return EmsconTracker(url, EmsconSettings.from_options(options), clock=context.get("clock"))


def validate_options(url: str, options: Mapping[str, Any] | None = None, **context: Any) -> None:
    """What ``open_tracker`` checks, without connecting: the url (host[:port]) and the options."""
    parse_url(url)
    EmsconSettings.from_options(options)
