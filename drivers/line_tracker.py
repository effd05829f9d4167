"""Generic line-protocol laser-tracker driver on pyserial (``serial.serial_for_url``).

One transport for TCP (``tracker+socket://host:port``), native serial (``tracker+serial:///dev/ttyUSB0?baudrate=115200``),
RFC 2217 serial-over-LAN (``tracker+rfc2217://host:port``) and the in-memory loopback (``tracker+loop://``), and one
declarative line protocol configured by the cell YAML's ``tracker.options`` (see ``docs/drivers_tracker.md``). The built-in default profile speaks the sample protocol of
``drivers.emulators.line_tracker_server``, so ``options: {}`` works against the emulator.

Layers: ``LineProfile`` (validated options, ``drivers.line_profile``), ``TrackerCodec`` (pure: command bytes,
line -> ``Reply``; unit-tested on strings, ``drivers.line_codec``), and here ``LinePort`` (framing and timeouts
over a pyserial port; maps transport failures to ``ConnectionLost``), ``LineTracker`` (the ``Tracker`` protocol) and
``LineSensor`` (an optional ASCII weather station).

Units: positions leave this module in mm in the tracker frame; angles are converted to radians internally;
environment values are ``temp_c`` (deg C), ``pressure_hpa`` (hPa), ``humidity_pct`` (% RH); times in s.
"""
from __future__ import annotations

import re
import time
from typing import Any, Callable, Mapping, Sequence

import serial

from .base import (ConnectionLost, DriverError, GarbageReply, TargetNotFound, TrackerError, TrackerReading,
                   TrackerTimeout)
from .line_codec import Reply, TrackerCodec, group_float, match_groups, average_readings, spherical_to_xyz  # noqa: F401
from .line_profile import (DEFAULT_OPTIONS, ENV_GROUPS, URL_SCHEMES, LineProfile, PortSpec, SensorProfile, port_spec,
                           show, uses_seq)

MAX_LINE_BYTES = 4096
POLL_S = 0.02




# ------------------------------------------------------------------------------------------------------ transport

class LinePort:
    """A pyserial port read as lines, every read bounded by a deadline; failures raise ``ConnectionLost``."""

    def __init__(self, name: str, spec: PortSpec, terminator: bytes, *,
                 opener: Callable[..., Any] = serial.serial_for_url) -> None:
        self.name, self.spec, self.terminator, self._opener = name, spec, terminator, opener
        self._port: Any = None
        self._buf = bytearray()

    @property
    def is_open(self) -> bool:
        return self._port is not None

    def open(self, write_timeout_s: float) -> None:
        """Open the port (socket:// connects with pyserial's own 5 s connect timeout)."""
        self.close()
        try:
            self._port = self._opener(self.spec.url, timeout=POLL_S, write_timeout=write_timeout_s,
                                      **dict(self.spec.settings))
        except (serial.SerialException, OSError, ValueError) as exc:
            raise ConnectionLost(f"{self.name}: cannot open {self.spec.url}: {exc}") from exc

    def close(self) -> None:
        """Close the port; idempotent, never raises."""
        port, self._port = self._port, None
        self._buf.clear()
        if port is not None:
            try:
                port.close()
            except Exception:  # noqa: BLE001 - closing is best effort
                pass

    def flush(self) -> None:
        """Drop everything received so far (late replies to earlier requests)."""
        self._buf.clear()
        self._guard(lambda p: p.reset_input_buffer())

    def write(self, data: bytes) -> None:
        self._guard(lambda p: p.write(data))

    def read_line(self, deadline: float) -> bytes | None:
        """The next complete line (terminator removed), or ``None`` at ``deadline`` (``time.monotonic()``)."""
        while True:
            i = self._buf.find(self.terminator)
            if i >= 0:
                line = bytes(self._buf[:i])
                del self._buf[:i + len(self.terminator)]
                return line
            if len(self._buf) > MAX_LINE_BYTES:
                raise GarbageReply(f"{self.name}: no line terminator in {len(self._buf)} bytes: {show(bytes(self._buf))}")
            if time.monotonic() >= deadline:
                return None
            self._buf += self._guard(_read_available)

    def _guard(self, action: Callable[[Any], Any]) -> Any:
        if self._port is None:
            raise ConnectionLost(f"{self.name}: not connected (call connect())")
        try:
            return action(self._port)
        except (serial.SerialException, OSError) as exc:
            self.close()
            raise ConnectionLost(f"{self.name}: {exc}") from exc


def _read_available(port: Any) -> bytes:
    """Wait up to the port's poll timeout for one byte, then take whatever else is already buffered."""
    data = port.read(1)
    if data:
        waiting = port.in_waiting
        if waiting:
            data += port.read(waiting)
    return data


# --------------------------------------------------------------------------------------------------------- driver

class NoReply(TrackerTimeout):
    """No complete reply line before the deadline (retried by ``LineTracker``, unlike a device-reported timeout)."""


class LineTracker:
    """A laser tracker (or vendor bridge) speaking the configured line protocol; implements ``drivers.base.Tracker``.

    ``measure()`` returns one reading, xyz in mm in the tracker frame, ``t_s`` from ``clock.now()`` when the reply
    arrived. ``stale_discarded`` counts replies dropped because their echoed seq belonged to an earlier request.
    """

    def __init__(self, url: str, profile: LineProfile, *, clock: Any = None,
                 opener: Callable[..., Any] = serial.serial_for_url) -> None:
        self.url, self.profile, self.codec = url, profile, TrackerCodec(profile)
        self._clock = clock
        self._link = LinePort(url, port_spec(url, profile.serial), self.codec.rx_terminator, opener=opener)
        self._sensor = LineSensor(profile.sensor, opener=opener) if profile.sensor else None
        self._seq = 0
        self._last_env: dict[str, float] = {}
        self.stale_discarded = 0

    def __enter__(self) -> "LineTracker":
        self.connect()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def connect(self) -> None:
        """(Re)open the port, send the init commands and check each reply (``init_regex``; null: no reply awaited)."""
        self._link.open(self.profile.timeout_s)
        try:
            for template in self.profile.init:
                self._init(template)
            if self._sensor:
                self._sensor.connect()
        except Exception:
            self.close()
            raise

    def _init(self, template: str) -> None:
        if self.profile.init_regex is None:
            self._link.write(self.codec.command(template, self._next_seq()))
            return
        self._request(template, self.profile.init_regex, self.profile.init_timeout_s)

    def measure(self) -> TrackerReading:
        """One reading of the SMR (mm, tracker frame), or a ``TrackerError``/``ConnectionLost``.

        No reply or an unparseable one is retried ``retries`` times (so at most ``(retries + 1) * timeout_s``).
        """
        reply = self._with_retries(lambda: self._request(self.profile.measure, self.profile.measure_regex,
                                                         self.profile.timeout_s))
        t_s = self._now()
        try:
            xyz, extra = self.codec.reading(reply.groups)
            self._last_env.update(self.codec.environment(reply.groups))
        except ValueError as exc:
            raise GarbageReply(f"{self.url}: bad reading {show(reply.line)}: {exc}") from None
        return TrackerReading(xyz, t_s, extra)

    def environment(self) -> dict[str, float]:
        """temp_c / pressure_hpa / humidity_pct from the environment query (or the last measure line) plus the sensor."""
        env = dict(self._last_env)
        if self.profile.environment:
            reply = self._with_retries(lambda: self._request(self.profile.environment, self.profile.environment_regex,
                                                             self.profile.timeout_s))
            try:
                env.update(self.codec.environment(reply.groups))
            except ValueError as exc:
                raise GarbageReply(f"{self.url}: bad environment reply {show(reply.line)}: {exc}") from None
        if self._sensor:
            env.update(self._sensor.read())
        return env

    @property
    def can_reacquire(self) -> bool:
        """Whether the profile has a ``goto`` or ``find`` command (the runner reacquires only then)."""
        return bool(self.profile.goto or self.profile.find)

    def reacquire(self, p_tracker_mm_guess: Sequence[float]) -> None:
        """Aim at the predicted SMR position (``goto``, mm converted to the length unit) and search (``find``);
        each request awaits ``ack_regex`` within ``reacquire_timeout_s``. ``TargetNotFound`` if either fails."""
        p = self.profile
        if not self.can_reacquire:
            raise TrackerError(f"{self.url}: no goto/find commands configured; cannot reacquire")
        try:
            if p.goto:
                x, y, z = (float(v) / p.length_to_mm for v in p_tracker_mm_guess)
                self._request(p.goto.format(seq="{seq}", x=x, y=y, z=z), p.ack_regex, p.reacquire_timeout_s)
            if p.find:
                self._request(p.find, p.ack_regex, p.reacquire_timeout_s)
        except TrackerError as exc:
            raise TargetNotFound(f"{self.url}: reflector not found near the predicted position: {exc}") from None

    def close(self) -> None:
        """Send the stop command (best effort, no reply awaited) and close; idempotent, never raises."""
        if self.profile.stop and self._link.is_open:
            try:
                self._link.write(self.codec.command(self.profile.stop, self._next_seq()))
            except DriverError:  # the link is going away anyway
                pass
        self._link.close()
        if self._sensor:
            self._sensor.close()

    # -- internals

    def _next_seq(self) -> int:
        self._seq += 1
        return self._seq

    def _now(self) -> float:
        return self._clock.now() if self._clock is not None else time.time()

    def _with_retries(self, request: Callable[[], Reply]) -> Reply:
        for attempt in range(self.profile.retries + 1):
            try:
                return request()
            except (NoReply, GarbageReply):
                if attempt == self.profile.retries:
                    raise
        raise AssertionError("unreachable")

    def _request(self, template: str, regex: re.Pattern[str] | None, timeout_s: float) -> Reply:
        """Flush, send the filled template, read lines until the reply matching ``regex`` (and seq) arrives."""
        seq = self._next_seq()
        if self.profile.flush:
            self._link.flush()
        command = self.codec.command(template, seq)
        self._link.write(command)
        where = f"{self.url}: {show(command.decode(self.profile.encoding).strip())}"
        deadline = time.monotonic() + timeout_s
        while True:
            raw = self._link.read_line(deadline)
            if raw is None:
                raise NoReply(f"{where}: no reply within {timeout_s:g} s")
            reply = self.codec.classify(self.codec.decode(raw), regex, seq if uses_seq(template) else None)
            if reply.kind == "ok":
                return reply
            if reply.kind == "stale":
                self.stale_discarded += 1
            elif reply.kind != "ignore":
                raise self.codec.error(reply, where)


class LineSensor:
    """An ASCII environment sensor on its own port (same URL forms as the tracker), e.g. a PTU answering ``SEND``.

    ``read()`` sends ``command`` (if any) and returns the first line matching ``regex`` as normalised environment
    values (temp_c, pressure_hpa, humidity_pct; other numeric groups under their own names), keys prefixed.
    """

    def __init__(self, profile: SensorProfile, *, opener: Callable[..., Any] = serial.serial_for_url) -> None:
        self.profile = profile
        self._link = LinePort(profile.url, port_spec(profile.url), profile.terminator.encode(profile.encoding),
                              opener=opener)

    def connect(self) -> None:
        self._link.open(self.profile.timeout_s)

    def read(self) -> dict[str, float]:
        """One sensor reading; ``TrackerTimeout`` if none within ``timeout_s``, ``GarbageReply`` if unparseable."""
        p = self.profile
        self._link.flush()
        if p.command:
            text = p.command.format(seq=0)
            self._link.write((text if text.endswith(p.terminator) else text + p.terminator).encode(p.encoding))
        deadline = time.monotonic() + p.timeout_s
        while True:
            raw = self._link.read_line(deadline)
            if raw is None:
                raise TrackerTimeout(f"{p.url}: no sensor reading within {p.timeout_s:g} s")
            line = raw.decode(p.encoding, errors="replace").strip()
            if line:
                return self._values(line)

    def _values(self, line: str) -> dict[str, float]:
        m = self.profile.regex.search(line)
        if not m:
            raise GarbageReply(f"{self.profile.url}: unparseable sensor reply {show(line)}")
        groups = match_groups(m)
        try:
            values = TrackerCodec.environment(groups)
            values.update({k: group_float(k, v) for k, v in groups.items() if k not in ENV_GROUPS})
        except ValueError as exc:
            raise GarbageReply(f"{self.profile.url}: bad sensor reply {show(line)}: {exc}") from None
        return {self.profile.prefix + k: v for k, v in values.items()}

    def close(self) -> None:
        self._link.close()


def open_tracker(url: str, options: Mapping[str, Any] | None = None, **context: Any) -> LineTracker:
    """Registry factory: a ``LineTracker`` for ``url`` (not yet connected).

    ``options`` are the cell YAML's ``tracker.options``; context ``clock`` (with ``now()``, s) timestamps readings.
    Raises ``ValueError`` naming the bad option or url.
    """
    profile = LineProfile.from_options(options)
    port_spec(url, profile.serial)
    return LineTracker(url, profile, clock=context.get("clock"))


def validate_options(url: str, options: Mapping[str, Any] | None = None, **context: Any) -> None:
    """What ``open_tracker`` checks, without opening anything: the options and the url (host:port, device)."""
    profile = LineProfile.from_options(options)
    port_spec(url, profile.serial)
