"""Generic line-protocol laser-tracker driver on pyserial (``serial.serial_for_url``).

One transport for TCP (``tracker+socket://host:port``), native serial (``tracker+serial:///dev/ttyUSB0?baudrate=115200``),
RFC 2217 serial-over-LAN (``tracker+rfc2217://host:port``) and the in-memory loopback (``tracker+loop://``), and one
declarative line protocol configured by the cell YAML's ``tracker.options`` (see ``docs/drivers_tracker.md``). The built-in default profile speaks the sample protocol of
``drivers.emulators.tracker_server``, so ``options: {}`` works against the emulator.

Layers: ``LineProfile`` (validated options), ``TrackerCodec`` (pure: command bytes, line -> ``Reply``; unit-tested on
strings), ``LinePort`` (framing and timeouts over a pyserial port; maps transport failures to ``ConnectionLost``),
``LineTracker`` (the ``Tracker`` protocol) and ``LineSensor`` (an optional ASCII weather station).

Units: positions leave this module in mm in the tracker frame; angles are converted to radians internally;
environment values are ``temp_c`` (deg C), ``pressure_hpa`` (hPa), ``humidity_pct`` (% RH); times in s.
"""
from __future__ import annotations

import math
import re
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping, Sequence
from urllib.parse import parse_qsl, urlencode, urlsplit

import serial

from .base import (BeamBroken, ConnectionLost, DriverError, GarbageReply, TargetNotFound, TrackerError, TrackerReading,
                   TrackerTimeout, Unstable)

NUM = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
"""Regex of a decimal number; ``{num}`` in any configured regex expands to it."""

LENGTH_TO_MM = {"mm": 1.0, "m": 1000.0, "um": 1e-3, "in": 25.4, "inch": 25.4, "ft": 304.8}
ANGLE_TO_RAD = {"rad": 1.0, "deg": math.pi / 180.0, "gon": math.pi / 200.0}

# environment group name -> (normalised key, conversion to deg C / hPa / % RH)
ENV_GROUPS: dict[str, tuple[str, Callable[[float], float]]] = {
    "temp_c": ("temp_c", lambda v: v), "temp_f": ("temp_c", lambda v: (v - 32.0) / 1.8),
    "temp_k": ("temp_c", lambda v: v - 273.15),
    "pressure_hpa": ("pressure_hpa", lambda v: v), "pressure_mbar": ("pressure_hpa", lambda v: v),
    "pressure_kpa": ("pressure_hpa", lambda v: v * 10.0), "pressure_pa": ("pressure_hpa", lambda v: v * 0.01),
    "pressure_mmhg": ("pressure_hpa", lambda v: v * 1.333224), "pressure_inhg": ("pressure_hpa", lambda v: v * 33.8639),
    "humidity_pct": ("humidity_pct", lambda v: v),
}
LENGTH_STD_GROUPS = ("sx", "sy", "sz", "sr")          # reported in the length unit -> extra "<g>_mm"
ANGLE_STD_GROUPS = ("saz", "szen", "shz", "sv")       # reported in the angle unit -> extra "<g>_deg"

ERROR_KINDS: dict[str, type[TrackerError]] = {
    "beam_broken": BeamBroken, "not_found": TargetNotFound, "unstable": Unstable, "timeout": TrackerTimeout,
    "error": TrackerError,
}
SERIAL_KEYS = {"baudrate": int, "bytesize": int, "parity": str, "stopbits": float, "xonxoff": bool, "rtscts": bool,
               "dsrdtr": bool}
URL_SCHEMES = {"tracker+socket": "socket", "tracker+serial": "serial", "tracker+rfc2217": "rfc2217",
               "tracker+loop": "loop"}

DEFAULT_OPTIONS: dict[str, Any] = {
    "terminator": "\r\n",
    "tx_terminator": None,            # None: same as terminator
    "rx_terminator": None,
    "encoding": "ascii",
    "init": ["INIT"],
    "init_regex": r"^READY$",
    "init_timeout_s": None,           # None: same as timeout_s
    "measure": "MEAS {seq}",
    "measure_regex": r"^OK (?P<seq>\d+) (?P<x>{num}) (?P<y>{num}) (?P<z>{num})"
                     r"(?: (?P<sx>{num}) (?P<sy>{num}) (?P<sz>{num}))?$",
    "coords": None,                   # None: inferred from the regex groups
    "length_unit": "mm",
    "angle_unit": None,               # None: deg (required explicitly with hz/v groups)
    "azimuth_sense": None,            # ccw | cw; only (and then required) with an hz group
    "vertical_zero": None,            # zenith | horizon; only (and then required) with a v group
    "errors": {"beam_broken": r"^ERR (?P<seq>\d+) BEAM_BROKEN\b", "not_found": r"^ERR (?P<seq>\d+) NO_TARGET\b",
               "unstable": r"^ERR (?P<seq>\d+) UNSTABLE\b", "timeout": r"^ERR (?P<seq>\d+) TIMEOUT\b",
               "error": [r"^ERR (?P<seq>\d+)\b", r"^ERR\b"]},
    "ignore": [],
    "environment": "ENV",
    "environment_regex": r"^ENV (?P<temp_c>{num}) (?P<pressure_hpa>{num}) (?P<humidity_pct>{num})$",
    "stop": None,
    "goto": None,                     # optional: aim at a point, e.g. "GOTO {seq} {x} {y} {z}" (length unit, tracker frame)
    "find": None,                     # optional: search for the SMR where the tracker points, e.g. "FIND {seq}"
    "ack_regex": r"^OK (?P<seq>\d+)$",  # reply to goto / find
    "reacquire_timeout_s": 30.0,      # per goto / find request
    "timeout_s": 2.0,
    "retries": 0,
    "flush": True,
    "serial": {},
    "sensor_url": None,
    "sensor_command": None,
    "sensor_regex": None,
    "sensor_terminator": "\r\n",
    "sensor_timeout_s": None,
    "sensor_prefix": "",
}

MAX_LINE_BYTES = 4096
POLL_S = 0.02


def _bad(key: str, problem: str) -> ValueError:
    return ValueError(f"tracker option {key!r}: {problem}")


def show(text: str | bytes, limit: int = 60) -> str:
    """One-line, truncated rendering of device text for error messages."""
    if isinstance(text, bytes):
        text = text.decode("ascii", errors="backslashreplace")
    return ascii(text[:limit]) + ("..." if len(text) > limit else "")


# ----------------------------------------------------------------------------------------------- option validation

def _string(opts: Mapping[str, Any], key: str, *, optional: bool = False, allow_empty: bool = False) -> str | None:
    value = opts[key]
    if value is None and optional:
        return None
    if not isinstance(value, str) or (not value and not allow_empty):
        raise _bad(key, f"expected a {'non-empty ' if not allow_empty else ''}string, got {value!r}")
    return value


def _number(opts: Mapping[str, Any], key: str, *, lo: float = 0.0, optional: bool = False) -> float | None:
    value = opts[key]
    if value is None and optional:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value <= lo:
        raise _bad(key, f"expected a finite number > {lo:g}, got {value!r}")
    return float(value)


def _integer(opts: Mapping[str, Any], key: str) -> int:
    value = opts[key]
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        raise _bad(key, f"expected an integer >= 0, got {value!r}")
    return value


def _choice(opts: Mapping[str, Any], key: str, choices: Sequence[str]) -> str | None:
    value = opts[key]
    if value is not None and value not in choices:
        raise _bad(key, f"expected one of {', '.join(choices)}, got {value!r}")
    return value


def _regex(key: str, value: Any) -> re.Pattern[str]:
    if not isinstance(value, str) or not value:
        raise _bad(key, f"expected a non-empty regex string, got {value!r}")
    try:
        return re.compile(value.replace("{num}", NUM))
    except re.error as exc:
        raise _bad(key, f"invalid regex {value!r}: {exc}") from None


def _template(opts: Mapping[str, Any], key: str, encoding: str, *, optional: bool = True) -> str | None:
    value = _string(opts, key, optional=optional)
    if value is None:
        return None
    try:
        value.format(seq=0).encode(encoding)
    except (KeyError, IndexError, ValueError) as exc:
        raise _bad(key, f"bad template {value!r} ({type(exc).__name__}: {exc}); only {{seq}} is a placeholder, "
                        "write literal braces as {{{{ }}}}") from None
    return value


def _templates(opts: Mapping[str, Any], key: str, encoding: str) -> tuple[str, ...]:
    value = opts[key]
    if value is None:
        return ()
    items = [value] if isinstance(value, str) else value
    if not isinstance(items, (list, tuple)):
        raise _bad(key, f"expected a command string or a list of them, got {value!r}")
    return tuple(_template({key: item}, key, encoding, optional=False) for item in items)


def _encoding(opts: Mapping[str, Any]) -> str:
    value = _string(opts, "encoding")
    try:
        "".encode(value)
    except LookupError:
        raise _bad("encoding", f"unknown encoding {value!r}") from None
    return value


def _error_patterns(opts: Mapping[str, Any]) -> tuple[tuple[str, re.Pattern[str]], ...]:
    value = opts["errors"] or {}
    if not isinstance(value, Mapping):
        raise _bad("errors", f"expected a mapping kind -> regex (or list of regexes), got {value!r}")
    out = []
    for kind, patterns in value.items():
        if kind not in ERROR_KINDS:
            raise _bad("errors", f"unknown error kind {kind!r} (expected one of {', '.join(ERROR_KINDS)})")
        for pattern in [patterns] if isinstance(patterns, str) else patterns or []:
            out.append((kind, _regex(f"errors.{kind}", pattern)))
    return tuple(out)


def _ignore_patterns(opts: Mapping[str, Any]) -> tuple[re.Pattern[str], ...]:
    value = opts["ignore"] or []
    if isinstance(value, str) or not isinstance(value, (list, tuple)):
        raise _bad("ignore", f"expected a list of regexes, got {value!r}")
    return tuple(_regex("ignore", p) for p in value)


def _serial_settings(opts: Mapping[str, Any]) -> dict[str, Any]:
    value = opts["serial"] or {}
    if not isinstance(value, Mapping):
        raise _bad("serial", f"expected a mapping of serial settings, got {value!r}")
    return {k: _serial_value(f"serial.{k}", k, v) for k, v in value.items()}


def _serial_value(where: str, key: str, value: Any) -> Any:
    if key not in SERIAL_KEYS:
        raise _bad(where, f"unknown serial setting (expected one of {', '.join(SERIAL_KEYS)})")
    kind = SERIAL_KEYS[key]
    if kind is bool and isinstance(value, str):
        if value.lower() not in ("1", "0", "true", "false", "yes", "no", "on", "off"):
            raise _bad(where, f"expected a boolean, got {value!r}")
        return value.lower() in ("1", "true", "yes", "on")
    try:
        out = kind(value)
    except (TypeError, ValueError):
        raise _bad(where, f"expected {kind.__name__}, got {value!r}") from None
    return out.upper() if key == "parity" else (int(out) if key == "stopbits" and out in (1, 2) else out)


# ----------------------------------------------------------------------------------------------------- URL mapping

@dataclass(frozen=True)
class PortSpec:
    """Where and how to open the pyserial port: ``serial_for_url(url, **settings)``."""
    url: str
    settings: Mapping[str, Any] = field(default_factory=dict)


def port_spec(url: str, serial_options: Mapping[str, Any] | None = None) -> PortSpec:
    """Map ``tracker+socket|serial|rfc2217|loop://...`` to a pyserial URL and serial settings.

    Serial settings (``baudrate``, ``bytesize``, ``parity``, ``stopbits``, ``xonxoff``, ``rtscts``, ``dsrdtr``) may come
    from the URL query or ``serial_options``, not both; other query items stay in the pyserial URL (e.g.
    ``?logging=debug``). ``tracker+serial:///dev/ttyUSB0`` -> ``/dev/ttyUSB0``; ``tracker+serial://COM3`` -> ``COM3``.
    """
    parts = urlsplit(url)
    if parts.scheme not in URL_SCHEMES:
        raise ValueError(f"tracker url {url!r}: expected one of {', '.join(s + '://' for s in URL_SCHEMES)}")
    settings, rest = dict(serial_options or {}), []
    for key, value in parse_qsl(parts.query, keep_blank_values=True):
        if key not in SERIAL_KEYS:
            rest.append((key, value))
        elif key in settings:
            raise ValueError(f"tracker url {url!r}: {key!r} given both in the url and in options.serial")
        else:
            settings[key] = _serial_value(f"url ?{key}", key, value)
    return PortSpec(_pyserial_url(url, parts, rest), settings)


def _pyserial_url(url: str, parts, query: list[tuple[str, str]]) -> str:
    kind = URL_SCHEMES[parts.scheme]
    suffix = f"?{urlencode(query)}" if query else ""
    if kind == "serial":
        device = parts.netloc + parts.path if parts.netloc else parts.path
        device = device[1:] if re.fullmatch(r"/COM\d+", device, re.I) else device
        if not device:
            raise ValueError(f"tracker url {url!r}: no serial device (e.g. tracker+serial:///dev/ttyUSB0)")
        if query:
            raise ValueError(f"tracker url {url!r}: unknown serial setting {query[0][0]!r} "
                             f"(expected one of {', '.join(SERIAL_KEYS)})")
        return device
    if kind in ("socket", "rfc2217") and (not parts.hostname or parts.port is None):
        raise ValueError(f"tracker url {url!r}: expected {parts.scheme}://host:port")
    return f"{kind}://{parts.netloc}{suffix}"


# -------------------------------------------------------------------------------------------------------- profile

@dataclass(frozen=True)
class LineProfile:
    """Validated line-protocol options (see ``DEFAULT_OPTIONS`` and docs/drivers_tracker.md)."""
    tx_terminator: str
    rx_terminator: str
    encoding: str
    init: tuple[str, ...]
    init_regex: re.Pattern[str] | None
    init_timeout_s: float
    measure: str
    measure_regex: re.Pattern[str]
    coords: str
    length_to_mm: float
    angle_to_rad: float
    azimuth_sign: float
    vertical_zero: str
    errors: tuple[tuple[str, re.Pattern[str]], ...]
    ignore: tuple[re.Pattern[str], ...]
    environment: str | None
    environment_regex: re.Pattern[str] | None
    stop: str | None
    timeout_s: float
    retries: int
    goto: str | None
    find: str | None
    ack_regex: re.Pattern[str]
    reacquire_timeout_s: float
    flush: bool
    serial: Mapping[str, Any]
    sensor: "SensorProfile | None"

    @classmethod
    def from_options(cls, options: Mapping[str, Any] | None) -> "LineProfile":
        """Defaults overridden key by key by ``options``; raises ``ValueError`` naming the first bad option."""
        opts = _merged(options)
        enc = _encoding(opts)
        term = _string(opts, "terminator")
        measure_regex = _regex("measure_regex", opts["measure_regex"])
        coords, angles = _geometry(opts, measure_regex)
        timeout_s = _number(opts, "timeout_s")
        env_regex = _optional_regex(opts, "environment_regex")
        profile = cls(
            tx_terminator=_string(opts, "tx_terminator", optional=True) or term,
            rx_terminator=_string(opts, "rx_terminator", optional=True) or term,
            encoding=enc, init=_templates(opts, "init", enc), init_regex=_optional_regex(opts, "init_regex"),
            init_timeout_s=_number(opts, "init_timeout_s", optional=True) or timeout_s,
            measure=_template(opts, "measure", enc, optional=False), measure_regex=measure_regex, coords=coords,
            length_to_mm=LENGTH_TO_MM[_choice(opts, "length_unit", list(LENGTH_TO_MM))], **angles,
            errors=_error_patterns(opts), ignore=_ignore_patterns(opts),
            environment=_template(opts, "environment", enc), environment_regex=env_regex,
            stop=_template(opts, "stop", enc), timeout_s=timeout_s, retries=_integer(opts, "retries"),
            goto=_goto_template(opts, enc), find=_template(opts, "find", enc),
            ack_regex=_regex("ack_regex", opts["ack_regex"]),
            reacquire_timeout_s=_number(opts, "reacquire_timeout_s"),
            flush=_flag(opts, "flush"), serial=_serial_settings(opts), sensor=SensorProfile.from_options(opts, enc))
        profile._check_pairs()
        return profile

    def _check_pairs(self) -> None:
        if self.environment and self.environment_regex is None:
            raise _bad("environment_regex", "required when 'environment' is set (or set environment: null)")
        if "seq" in self.measure_regex.groupindex and not uses_seq(self.measure):
            raise _bad("measure", "the measure_regex has a 'seq' group, so the template needs a {seq} placeholder")
        if self.sensor:
            self.sensor.check_keys(self.environment_keys())

    def environment_keys(self) -> set[str]:
        """Normalised environment keys the tracker itself can report (measure line or environment query)."""
        groups = set(self.measure_regex.groupindex)
        if self.environment and self.environment_regex is not None:
            groups |= set(self.environment_regex.groupindex)
        return {ENV_GROUPS[g][0] for g in groups if g in ENV_GROUPS}


def _goto_template(opts: Mapping[str, Any], encoding: str) -> str | None:
    """The goto template: ``{seq}`` (optional) and ``{x}``, ``{y}``, ``{z}`` (format specs allowed on x, y, z)."""
    value = _string(opts, "goto", optional=True)
    if value is None:
        return None
    try:
        filled = value.format(seq="{seq}", x=1.0, y=2.0, z=3.0)
        filled.format(seq=0).encode(encoding)
    except (KeyError, IndexError, ValueError) as exc:
        raise _bad("goto", f"bad template {value!r} ({type(exc).__name__}: {exc}); placeholders: {{seq}}, {{x}}, "
                           "{y}, {z}") from None
    if filled == value.format(seq="{seq}", x=4.0, y=5.0, z=6.0):
        raise _bad("goto", f"template {value!r} has no {{x}}, {{y}}, {{z}} placeholders")
    return value


def uses_seq(template: str) -> bool:
    """Whether a command template contains a ``{seq}`` field (in any format, e.g. ``{seq:04d}``)."""
    return template.format(seq=1) != template.format(seq=2)


def _merged(options: Mapping[str, Any] | None) -> dict[str, Any]:
    if options is not None and not isinstance(options, Mapping):
        raise ValueError(f"tracker options: expected a mapping, got {type(options).__name__}")
    unknown = sorted(set(options or {}) - set(DEFAULT_OPTIONS))
    if unknown:
        raise _bad(unknown[0], f"unknown option (expected one of {', '.join(DEFAULT_OPTIONS)})")
    return {**DEFAULT_OPTIONS, **(options or {})}


def _flag(opts: Mapping[str, Any], key: str) -> bool:
    if not isinstance(opts[key], bool):
        raise _bad(key, f"expected true or false, got {opts[key]!r}")
    return opts[key]


def _optional_regex(opts: Mapping[str, Any], key: str) -> re.Pattern[str] | None:
    return None if opts[key] is None else _regex(key, opts[key])


def _geometry(opts: Mapping[str, Any], regex: re.Pattern[str]) -> tuple[str, dict[str, Any]]:
    """Coordinate kind and angle conventions, checked against the measure regex's named groups."""
    groups = set(regex.groupindex)
    coords = _choice(opts, "coords", ("cartesian", "spherical")) or ("cartesian" if "x" in groups else "spherical")
    if coords == "cartesian":
        _require_groups(groups, ({"x"}, {"y"}, {"z"}), "cartesian")
        for key in ("azimuth_sense", "vertical_zero"):
            if opts[key] is not None:
                raise _bad(key, "only applies to spherical readings with hz/v groups")
        return coords, {"angle_to_rad": ANGLE_TO_RAD[_choice(opts, "angle_unit", list(ANGLE_TO_RAD)) or "deg"],
                        "azimuth_sign": 1.0, "vertical_zero": "zenith"}
    _require_groups(groups, ({"r"}, {"az", "hz"}, {"zen", "v"}), "spherical")
    return coords, _angle_conventions(opts, groups)


def _require_groups(groups: set[str], needed: Sequence[set[str]], coords: str) -> None:
    for alternatives in needed:
        if len(alternatives & groups) != 1:
            names = "|".join(sorted(alternatives))
            raise _bad("measure_regex", f"{coords} readings need exactly one named group ({names}), "
                                        f"got groups {sorted(groups)}")


def _angle_conventions(opts: Mapping[str, Any], groups: set[str]) -> dict[str, Any]:
    """``az``/``zen`` mean ccw azimuth and zenith angle; ``hz``/``v`` need declared unit, sense and zero."""
    surveying = bool({"hz", "v"} & groups)
    unit = _choice(opts, "angle_unit", list(ANGLE_TO_RAD))
    sense = _choice(opts, "azimuth_sense", ("ccw", "cw"))
    zero = _choice(opts, "vertical_zero", ("zenith", "horizon"))
    if surveying and unit is None:
        raise _bad("angle_unit", "required (deg, rad or gon) with hz/v groups")
    for key, value, group in (("azimuth_sense", sense, "hz"), ("vertical_zero", zero, "v")):
        if group in groups and value is None:
            raise _bad(key, f"required with a {group!r} group")
        if group not in groups and value is not None:
            raise _bad(key, f"only applies with a {group!r} group (az is ccw, zen is from the zenith)")
    return {"angle_to_rad": ANGLE_TO_RAD[unit or "deg"], "azimuth_sign": -1.0 if sense == "cw" else 1.0,
            "vertical_zero": zero or "zenith"}


@dataclass(frozen=True)
class SensorProfile:
    """Optional ASCII weather station / thermometer merged into ``environment()``."""
    url: str
    command: str | None
    regex: re.Pattern[str]
    terminator: str
    encoding: str
    timeout_s: float
    prefix: str

    @classmethod
    def from_options(cls, opts: Mapping[str, Any], encoding: str) -> "SensorProfile | None":
        url = _string(opts, "sensor_url", optional=True)
        if url is None:
            for key in ("sensor_command", "sensor_regex"):
                if opts[key] is not None:
                    raise _bad(key, "needs sensor_url")
            return None
        try:
            port_spec(url)
        except ValueError as exc:
            raise _bad("sensor_url", str(exc)) from None
        if opts["sensor_regex"] is None:
            raise _bad("sensor_regex", "required with sensor_url")
        return cls(url, _template(opts, "sensor_command", encoding), _regex("sensor_regex", opts["sensor_regex"]),
                   _string(opts, "sensor_terminator"), encoding,
                   _number(opts, "sensor_timeout_s", optional=True) or _number(opts, "timeout_s"),
                   _string(opts, "sensor_prefix", allow_empty=True))

    def check_keys(self, tracker_keys: set[str]) -> None:
        groups = set(self.regex.groupindex)
        clash = sorted({self.prefix + (ENV_GROUPS[g][0] if g in ENV_GROUPS else g) for g in groups} & tracker_keys)
        if clash:
            raise _bad("sensor_prefix", f"sensor keys {clash} collide with the tracker's environment keys; "
                                        "set a prefix such as 'air_'")


# ---------------------------------------------------------------------------------------------------------- codec

@dataclass(frozen=True)
class Reply:
    """One classified line: ``kind`` is ``ok``, ``ignore``, ``stale``, ``garbage`` or an error kind."""
    kind: str
    line: str
    groups: Mapping[str, str] = field(default_factory=dict)


class TrackerCodec:
    """Pure encode/parse of the configured line protocol (no I/O)."""

    def __init__(self, profile: LineProfile) -> None:
        self.profile = profile
        self.rx_terminator = profile.rx_terminator.encode(profile.encoding)

    def command(self, template: str, seq: int) -> bytes:
        """Bytes to send: the filled template plus the tx terminator (unless the template already ends with it)."""
        text = template.format(seq=seq)
        if not text.endswith(self.profile.tx_terminator):
            text += self.profile.tx_terminator
        return text.encode(self.profile.encoding)

    def decode(self, raw: bytes) -> str:
        """A received line (without terminator) as stripped text; undecodable bytes become U+FFFD."""
        return raw.decode(self.profile.encoding, errors="replace").strip()

    def classify(self, line: str, regex: re.Pattern[str] | None, seq: int | None) -> Reply:
        """Blank/ignored lines, then error patterns (first wins), then ``regex``; a mismatching ``seq`` is stale."""
        if not line or any(p.search(line) for p in self.profile.ignore):
            return Reply("ignore", line)
        for kind, pattern in self.profile.errors:
            m = pattern.search(line)
            if m:
                return self._checked(Reply(kind, line, _groups(m)), seq)
        m = regex.search(line) if regex is not None else None
        return self._checked(Reply("ok", line, _groups(m)), seq) if m else Reply("garbage", line)

    @staticmethod
    def _checked(reply: Reply, seq: int | None) -> Reply:
        echoed = reply.groups.get("seq")
        if seq is None or echoed is None:
            return reply
        try:
            return reply if int(echoed) == seq else Reply("stale", reply.line, reply.groups)
        except ValueError:
            return Reply("garbage", reply.line)

    def parse_measure(self, line: str, seq: int | None = None) -> Reply:
        return self.classify(line, self.profile.measure_regex, seq)

    def reading(self, groups: Mapping[str, str]) -> tuple[tuple[float, float, float], dict[str, float]]:
        """xyz (mm, tracker frame) and extras (device std in mm/deg, environment, other numeric groups).

        Raises ``ValueError`` if a coordinate is not a finite number.
        """
        values = {k: _float(k, v) for k, v in groups.items() if v is not None and k != "seq"}
        xyz = self._xyz(values)
        return xyz, self._extra(values)

    def _xyz(self, v: Mapping[str, float]) -> tuple[float, float, float]:
        k = self.profile.length_to_mm
        if self.profile.coords == "cartesian":
            out = (v["x"] * k, v["y"] * k, v["z"] * k)
        else:
            out = spherical_to_xyz(v["r"] * k, self._azimuth(v), self._zenith(v))
        if not all(math.isfinite(c) for c in out):
            raise ValueError(f"non-finite coordinates {out}")
        return out

    def _azimuth(self, v: Mapping[str, float]) -> float:
        a = self.profile.angle_to_rad
        return v["az"] * a if "az" in v else self.profile.azimuth_sign * v["hz"] * a

    def _zenith(self, v: Mapping[str, float]) -> float:
        a = self.profile.angle_to_rad
        if "zen" in v:
            return v["zen"] * a
        return v["v"] * a if self.profile.vertical_zero == "zenith" else math.pi / 2 - v["v"] * a

    def _extra(self, v: Mapping[str, float]) -> dict[str, float]:
        skip = {"x", "y", "z", "r", "az", "hz", "zen", "v"}
        extra = self.environment(v)
        for name, value in v.items():
            if name in LENGTH_STD_GROUPS:
                extra[f"{name}_mm"] = value * self.profile.length_to_mm
            elif name in ANGLE_STD_GROUPS:
                extra[f"{name}_deg"] = math.degrees(value * self.profile.angle_to_rad)
            elif name not in skip and name not in ENV_GROUPS:
                extra[name] = value
        return extra

    @staticmethod
    def environment(values: Mapping[str, Any]) -> dict[str, float]:
        """Environment groups normalised to ``temp_c``, ``pressure_hpa``, ``humidity_pct``; other keys dropped."""
        out = {}
        for name, value in values.items():
            if name in ENV_GROUPS and value is not None:
                key, convert = ENV_GROUPS[name]
                out[key] = convert(_float(name, value))
        return out

    def error(self, reply: Reply, where: str) -> TrackerError:
        """The exception for a classified error or garbage line (message: one line, device text truncated)."""
        if reply.kind == "garbage":
            return GarbageReply(f"{where}: unparseable reply {show(reply.line)}")
        return ERROR_KINDS[reply.kind](f"{where}: device reports {reply.kind}: {show(reply.line)}")


def _groups(m: re.Match[str]) -> dict[str, str]:
    return {k: v for k, v in m.groupdict().items() if v is not None}


def _float(name: str, text: Any) -> float:
    if isinstance(text, (int, float)):
        return float(text)
    try:
        return float(text)
    except ValueError:
        raise ValueError(f"group {name!r} is not a number: {show(text)}") from None


def spherical_to_xyz(r: float, az_rad: float, zen_rad: float) -> tuple[float, float, float]:
    """x = r sin(zen) cos(az), y = r sin(zen) sin(az), z = r cos(zen); r and xyz in the same length unit."""
    s = math.sin(zen_rad)
    return (r * s * math.cos(az_rad), r * s * math.sin(az_rad), r * math.cos(zen_rad))


def average_readings(readings: Sequence[TrackerReading | Sequence[float]],
                     stability_mm: float) -> tuple[tuple[float, float, float], float]:
    """Mean xyz (mm) and spread (mm, max distance of a sample from the mean).

    Raises ``Unstable`` if the spread exceeds ``stability_mm``, ``ValueError`` if there are no readings.
    """
    points = [tuple(r.xyz_mm if isinstance(r, TrackerReading) else r) for r in readings]
    if not points:
        raise ValueError("average_readings: no readings")
    mean = tuple(sum(p[i] for p in points) / len(points) for i in range(3))
    spread = max(math.dist(p, mean) for p in points)
    if spread > stability_mm:
        raise Unstable(f"{len(points)} readings spread {spread:.4f} mm > stability {stability_mm:g} mm")
    return mean, spread


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
        groups = _groups(m)
        try:
            values = TrackerCodec.environment(groups)
            values.update({k: _float(k, v) for k, v in groups.items() if k not in ENV_GROUPS})
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
