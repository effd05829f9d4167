"""Line-protocol tracker profile: the option tables, their validation (``LineProfile``, ``SensorProfile``) and ports.

Pure (no I/O); used by ``drivers.line_tracker`` (transport and driver) and ``drivers.line_codec``.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping, Sequence
from urllib.parse import parse_qsl, urlencode, urlsplit

from .base import BeamBroken, TargetNotFound, TrackerError, TrackerTimeout, Unstable


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
