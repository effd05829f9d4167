"""ABB robot driver over Robot Web Services (``abb-rws://host[:port]``): IRC5 (RWS 1.0) and OmniCore (RWS 2.0).

Motion goes through our RAPID module ``drivers/rapid/CalServer.mod`` running in ``T_ROB1``: the driver writes the
target and then ``cal_req_seq`` (the trigger); RAPID answers ``cal_ack_seq`` when it takes the request and
``cal_done_seq`` when the robot stands still at the fine point after ``cal_settle_s``; a recoverable RAPID error
sets ``cal_err_seq``/``cal_err_msg`` instead. Failures that stop RAPID (reach/limit errors, guard stop, motors
off) are detected from the execution state, the controller state and the event log. See ``docs/drivers_abb.md``.

Units at this boundary: joints in degrees, positions in mm, quaternions w-first, times in seconds.
"""
from __future__ import annotations

import logging
import math
import os
import random
import re
import stat
import time
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from importlib import resources
from typing import Any, Callable, Iterator, Mapping, Sequence
from urllib.parse import urlsplit

import httpx

from .base import DriverError, MotionError, MotionLimits, Payload, RobotError, RobotNotReady
from .rws_client import (E_MASTER_REJECT, E_RESOURCE_HELD, Credentials, RetryPolicy, Routes, RwsError, RwsSession,
                         Timeouts, first)

log = logging.getLogger(__name__)

DEFAULT_USER, DEFAULT_PASSWORD = "Default User", "robotics"   # ABB's documented factory account
CALSERVER_VERSION = 2                                          # cal_version expected in CalServer.mod
ENTRY_ROUTINE = "cal_run"                                      # CalServer's entry procedure (no main of its own)
_CACHED = ("cal_speed", "cal_settle_s", "cal_vmax", "cal_override", "cal_tool", "cal_epoch")
UNUSED_AXIS = 9e9
KIND_PING, KIND_MOVEABSJ, KIND_MOVEL = 0, 1, 2
_IDENT = re.compile(r"^[A-Za-z][A-Za-z0-9_]{0,31}$")


# --------------------------------------------------------------------------- RAPID literals


def fmt_num(value: float) -> str:
    """RAPID num literal: fixed point, at most 6 decimals, ``9E9`` for unused axes, no ``-0``."""
    value = float(value)
    if not math.isfinite(value):
        raise ValueError(f"not a finite number: {value}")
    if abs(value) >= 1e9:
        return "9E9" if value > 0 else "-9E9"
    text = f"{value:.6f}".rstrip("0").rstrip(".")
    return "0" if text in ("", "-0") else text


def fmt_jointtarget(q_deg: Sequence[float], ext: Sequence[float] = ()) -> str:
    """``[[j1..j6],[e1..e6]]`` (deg); missing robot axes are 0, missing external axes 9E9."""
    rob = list(q_deg) + [0.0] * (6 - len(q_deg))
    eax = list(ext) + [UNUSED_AXIS] * (6 - len(ext))
    return f"[[{','.join(fmt_num(v) for v in rob)}],[{','.join(fmt_num(v) for v in eax)}]]"


def fmt_robtarget(trans_mm: Sequence[float], quat_wxyz: Sequence[float], conf: Sequence[int] = (0, 0, 0, 0)) -> str:
    """``[[x,y,z],[q1..q4],[cf1,cf4,cf6,cfx],[9E9 x6]]`` with the quaternion normalised (w first)."""
    norm = math.sqrt(sum(float(q) ** 2 for q in quat_wxyz))
    if len(trans_mm) != 3 or len(quat_wxyz) != 4 or len(conf) != 4 or not norm > 0:
        raise ValueError("robtarget needs xyz (3), a non-zero quaternion (4) and confdata (4)")
    quat = [float(q) / norm for q in quat_wxyz]
    parts = [",".join(fmt_num(v) for v in trans_mm), ",".join(fmt_num(v) for v in quat),
             ",".join(str(int(c)) for c in conf), ",".join("9E9" for _ in range(6))]
    return "[" + ",".join(f"[{p}]" for p in parts) + "]"


def fmt_string(text: str) -> str:
    """RAPID string literal with the quotes (``"`` and ``\\`` doubled as RAPID requires)."""
    return '"' + text.replace("\\", "\\\\").replace('"', '""') + '"'


def parse_string(literal: str) -> str:
    """Inverse of ``fmt_string``; tolerates a value without quotes."""
    text = literal.strip()
    if len(text) >= 2 and text[0] == text[-1] == '"':
        text = text[1:-1].replace('""', '"').replace("\\\\", "\\")
    return text


def parse_num(literal: str) -> float:
    """A RAPID num literal (``12``, ``-0.5``, ``9E+09``)."""
    try:
        return float(literal.strip())
    except ValueError as exc:
        raise DriverError(f"not a RAPID num: {literal[:40]!r}") from exc


# --------------------------------------------------------------------------- options


class RapidRejected(MotionError):
    """CalServer rejected the request through ``cal_err_seq`` (RAPID still runs); ``errno`` is its ERRNO."""

    def __init__(self, message: str, errno: int) -> None:
        super().__init__(message)
        self.errno = errno


class OptionsError(DriverError):
    """Invalid ``robot.options`` for the abb-rws driver (message starts with the key path)."""


@dataclass(frozen=True)
class CredentialOptions:
    """Where the credentials come from: environment variable names, an optional ``key=value`` file, and whether
    ABB's factory account (``Default User``/``robotics``) may be used when nothing else is set."""
    user_env: str = "RWS_USER"
    password_env: str = "RWS_PASSWORD"
    file: str | None = None
    use_default: bool = False


@dataclass(frozen=True)
class RwsOptions:
    """Driver options (``robot.options`` in the campaign config); see ``docs/drivers_abb.md`` for the schema."""
    rws_version: int | None = None            # None = detect
    scheme: str | None = None                 # None = detect (http / https)
    verify: bool | str = False                # TLS: False (OmniCore self-signed), True, or a CA/cert PEM path
    task: str = "T_ROB1"
    module: str = "CalServer"
    mechunit: str = "ROB_1"
    n_joints: int = 6
    upload_module: bool = False
    module_file: str | None = None            # default: the packaged drivers/rapid/CalServer.mod
    remote_dir: str = "$HOME"
    start_rapid: bool = False                 # start a stopped CalServer at connect (PP per ``entry`` + start)
    entry: str = "routine"                    # routine: PP to cal_run, restored to main at close; main: PP to main
    motors_on: bool = False                   # switch motors on at connect (AUTO only)
    speed: tuple[float, float, float, float] = (200.0, 100.0, 200.0, 1000.0)    # speeddata mm/s, deg/s, mm/s, deg/s
    settle_s: float = 0.5
    poll_s: float = 0.25
    health_s: float = 1.0
    max_poll_rate_hz: float = 3.0             # requests/s ceiling of the polls while waiting for CalServer
    timeouts: Timeouts = field(default_factory=Timeouts)
    retry: RetryPolicy = field(default_factory=RetryPolicy)
    credentials: CredentialOptions = field(default_factory=CredentialOptions)

    @classmethod
    def from_mapping(cls, options: Mapping[str, Any]) -> "RwsOptions":
        """Validate a plain mapping (YAML) into options; unknown keys and wrong types raise OptionsError."""
        return _OptionReader(options, "options").build()


class _OptionReader:
    """Reads one mapping level with key-path errors."""

    _SCALARS = {"task": str, "module": str, "mechunit": str, "remote_dir": str, "module_file": str,
                "upload_module": bool, "start_rapid": bool, "motors_on": bool, "entry": str}
    _POSITIVE = {"settle_s": True, "poll_s": False, "health_s": False, "max_poll_rate_hz": False}
    _NESTED = {"timeouts", "retry", "credentials"}

    def __init__(self, data: Mapping[str, Any], where: str) -> None:
        if not isinstance(data, Mapping):
            raise OptionsError(f"{where}: expected a mapping, got {type(data).__name__}")
        self.data, self.where = dict(data), where

    def build(self) -> RwsOptions:
        known = set(self._SCALARS) | set(self._POSITIVE) | self._NESTED | {"rws_version", "scheme", "verify",
                                                                            "n_joints", "speed"}
        self._unknown(known)
        kw: dict[str, Any] = {k: self._typed(k, t) for k, t in self._SCALARS.items() if k in self.data}
        kw.update({k: self._number(k, allow_zero=z) for k, z in self._POSITIVE.items() if k in self.data})
        if kw.get("entry", "routine") not in ("routine", "main"):
            raise self._err("entry", "expected routine or main")
        kw.update(self._transport_keys())
        if "n_joints" in self.data:
            kw["n_joints"] = self._int("n_joints", 1, 6)
        if "speed" in self.data:
            kw["speed"] = self._speed()
        kw["timeouts"] = self._dataclass("timeouts", Timeouts)
        kw["retry"] = self._dataclass("retry", RetryPolicy)
        kw["credentials"] = self._credentials()
        return RwsOptions(**kw)

    def _unknown(self, known: set[str]) -> None:
        extra = sorted(set(self.data) - known)
        if extra:
            raise OptionsError(f"{self.where}: unknown key(s) {', '.join(extra)} "
                               f"(expected: {', '.join(sorted(known))})")

    def _err(self, key: str, msg: str) -> OptionsError:
        return OptionsError(f"{self.where}.{key}: {msg}, got {self.data.get(key)!r}")

    def _typed(self, key: str, typ: type) -> Any:
        value = self.data[key]
        if not isinstance(value, typ) or (typ is not bool and isinstance(value, bool)):
            raise self._err(key, f"expected {typ.__name__}")
        return value

    def _number(self, key: str, *, allow_zero: bool) -> float:
        value = self.data[key]
        ok = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
        if not ok or value < 0 or (value == 0 and not allow_zero):
            raise self._err(key, "expected a " + ("non-negative" if allow_zero else "positive") + " number")
        return float(value)

    def _int(self, key: str, lo: int, hi: int) -> int:
        value = self.data[key]
        if not isinstance(value, int) or isinstance(value, bool) or not lo <= value <= hi:
            raise self._err(key, f"expected an integer in [{lo}, {hi}]")
        return value

    def _transport_keys(self) -> dict[str, Any]:
        kw: dict[str, Any] = {}
        version = self.data.get("rws_version", "auto")
        if version not in ("auto", None, 1, 2, "1", "2", "1.0", "2.0"):
            raise self._err("rws_version", "expected auto, 1 or 2")
        kw["rws_version"] = None if version in ("auto", None) else int(float(version))
        scheme = self.data.get("scheme", "auto")
        if scheme not in ("auto", None, "http", "https"):
            raise self._err("scheme", "expected auto, http or https")
        kw["scheme"] = None if scheme in ("auto", None) else scheme
        if "verify" in self.data:
            verify = self.data["verify"]
            if not isinstance(verify, (bool, str)):
                raise self._err("verify", "expected true, false or a path to a CA/certificate PEM file")
            kw["verify"] = verify
        return kw

    def _speed(self) -> tuple[float, float, float, float]:
        value = self.data["speed"]
        if (not isinstance(value, Sequence) or isinstance(value, str) or len(value) != 4
                or not all(isinstance(v, (int, float)) and not isinstance(v, bool) and v > 0 for v in value)):
            raise self._err("speed", "expected speeddata [v_tcp mm/s, v_ori deg/s, v_leax mm/s, v_reax deg/s] > 0")
        return tuple(float(v) for v in value)  # type: ignore[return-value]

    def _dataclass(self, key: str, cls: type) -> Any:
        """A Timeouts / RetryPolicy from a sub-mapping: ``retries`` an integer, the rest positive seconds."""
        sub = _OptionReader(self.data.get(key, {}), f"{self.where}.{key}")
        defaults = cls()
        sub._unknown(set(defaults.__dataclass_fields__))
        values = {name: sub._int(name, 0, 20) if name == "retries" else
                  sub._number(name, allow_zero=name == "backoff_s") for name in sub.data}
        return replace(defaults, **values)

    def _credentials(self) -> CredentialOptions:
        sub = _OptionReader(self.data.get("credentials", {}), f"{self.where}.credentials")
        sub._unknown(set(CredentialOptions.__dataclass_fields__))
        kw = {k: sub._typed(k, str) for k in ("user_env", "password_env", "file") if k in sub.data}
        if "use_default" in sub.data:
            kw["use_default"] = sub._typed("use_default", bool)
        return CredentialOptions(**kw)


# --------------------------------------------------------------------------- credentials


def load_credentials(opts: CredentialOptions, environ: Mapping[str, str] | None = None) -> Credentials:
    """Credentials from ``opts.file`` (``user=`` / ``password=`` lines), else the environment variables, else ABB's
    factory account if ``use_default``; otherwise a DriverError that names where to put them (never their value)."""
    env = os.environ if environ is None else environ
    if opts.file:
        return _credentials_file(opts.file)
    user, password = env.get(opts.user_env), env.get(opts.password_env)
    if user and password:
        return Credentials(user, password)
    if opts.use_default:
        log.warning("using ABB's factory RWS account %r (options.credentials.use_default)", DEFAULT_USER)
        return Credentials(DEFAULT_USER, DEFAULT_PASSWORD)
    missing = [n for n, v in ((opts.user_env, user), (opts.password_env, password)) if not v]
    raise DriverError(f"abb-rws: no RWS credentials: set {' and '.join(missing)} in the environment, or "
                      "options.credentials.file, or options.credentials.use_default: true for ABB's factory account")


def _credentials_file(path: str) -> Credentials:
    """Parse a ``user=...`` / ``password=...`` file (``#`` comments); warn if others can read it."""
    path = os.path.expanduser(path)
    try:
        text = open(path, encoding="utf-8").read()
        mode = os.stat(path).st_mode
    except OSError as exc:
        raise DriverError(f"abb-rws: cannot read credentials file {path}: {exc.strerror}") from None
    if os.name == "posix" and mode & (stat.S_IRWXG | stat.S_IRWXO):
        log.warning("credentials file %s is readable by other users (chmod 600 it)", path)
    values: dict[str, str] = {}
    for line in text.splitlines():
        key, sep, value = line.strip().partition("=")
        if sep and not key.startswith("#"):
            values[key.strip().lower()] = value.strip()
    if not values.get("user") or not values.get("password"):
        raise DriverError(f"abb-rws: credentials file {path} needs 'user=' and 'password=' lines")
    return Credentials(values["user"], values["password"])


# --------------------------------------------------------------------------- the robot


def calserver_source() -> str:
    """Text of the packaged ``drivers/rapid/CalServer.mod``."""
    return resources.files("drivers").joinpath("rapid/CalServer.mod").read_text(encoding="latin-1")


class Deadline:
    """A point in monotonic time ``seconds`` from now."""

    def __init__(self, seconds: float, clock: Callable[[], float] = time.monotonic) -> None:
        self._clock, self.seconds = clock, seconds
        self.end = clock() + seconds

    def expired(self) -> bool:
        return self._clock() >= self.end


class AbbRwsRobot:
    """``Robot`` over RWS driving CalServer.mod; also ``move_linear``, ``write_module`` and ``heartbeat``."""

    def __init__(self, url: str, options: RwsOptions, credentials: Credentials, *,
                 transport: httpx.BaseTransport | None = None, sleep: Callable[[float], None] = time.sleep) -> None:
        parts = urlsplit(url)
        if parts.scheme != "abb-rws" or not parts.hostname:
            raise DriverError(f"{url}: expected abb-rws://host[:port]")
        self.url, self.opts, self.n_joints = url, options, options.n_joints
        self._sleep = sleep
        self.session = RwsSession(url, parts.netloc, credentials, version=options.rws_version,
                                  scheme=options.scheme, verify=_verify(options.verify), timeouts=options.timeouts,
                                  policy=options.retry, transport=transport, sleep=sleep)
        self._seq = 0
        self._written: dict[str, str] = {}
        self._elog_mark: int | None = None
        self._suspect = False
        self._limits = MotionLimits()             # safe default until the runner sets the campaign's caps
        self._payload: Payload | None = None
        self._explicit = False                    # True once the controller refused implicit mastership
        self._restore_pp = False                  # we moved the PP to cal_run: put it back to main at close
        self._identity: dict[str, str] | None = None
        self._capped_warned = False
        self._epoch = random.SystemRandom().randint(1, 999_999)   # marks this session's cached arguments

    @property
    def _routes(self) -> Routes:
        """URL grammar of the open session, or a DriverError before ``connect()``."""
        if self.session.routes is None or self.session.client is None:
            raise DriverError(f"{self.url}: not connected (call connect() first)")
        return self.session.routes

    # -- Robot protocol

    def connect(self) -> None:
        """Open the session, run the preflight (RobotNotReady with a one-line reason) and ping CalServer."""
        self.session.close()                       # reconnecting: log the previous session out first
        try:
            self.session.open()
            self._preflight()
        except BaseException:
            self.close()
            raise

    def move_joints(self, q_deg: Sequence[float]) -> None:
        """MoveAbsJ to ``q_deg`` (deg) with a fine stop and ``settle_s`` dwell; return when done, else raise."""
        q = [float(v) for v in q_deg]
        if len(q) != self.n_joints or not all(math.isfinite(v) for v in q):
            raise MotionError(f"{self.url}: expected {self.n_joints} finite joint values (deg), got {list(q_deg)}")
        self._command(KIND_MOVEABSJ, {"cal_target": fmt_jointtarget(q)}, f"MoveAbsJ {_fmt_q(q)}")

    def move_linear(self, trans_mm: Sequence[float], quat_wxyz: Sequence[float],
                    conf: Sequence[int] = (0, 0, 0, 0)) -> None:
        """MoveL (tool0, wobj0) to the pose (mm, w-first quaternion, confdata) with a fine stop and settle dwell."""
        try:
            literal = fmt_robtarget(trans_mm, quat_wxyz, conf)
        except ValueError as exc:
            raise MotionError(f"{self.url}: {exc}") from None
        self._command(KIND_MOVEL, {"cal_ptarget": literal}, f"MoveL {literal}")

    def read_joints(self) -> tuple[float, ...]:
        """Actual joints of the mechanical unit (deg), ``rax_1..rax_n``."""
        path, params = self._routes.jointtarget(self.opts.mechunit)
        items = self.session.get(path, params)
        return tuple(parse_num(first(items, f"rax_{i + 1}", "jointtarget")) for i in range(self.n_joints))

    def stop(self) -> None:
        """Request RAPID stop (best effort, never raises)."""
        try:
            path, params = self._routes.execution_action("stop")
            self.session.post(path, params, {"stopmode": "stop", "usetsp": "normal"},
                              timeout=self.opts.timeouts.connect_s)
            log.warning("%s: RAPID stop requested", self.url)
        except Exception as exc:                                   # noqa: BLE001 - best effort by contract
            log.warning("%s: RAPID stop request failed: %s", self.url, exc)

    def close(self) -> None:
        """Put the program pointer back to main if we moved it, log out and close; idempotent, never raises."""
        if self._restore_pp and self.session.client is not None:
            self._restore_pp = False
            try:
                if self._exec_state() == "running":
                    self._rapid_stop_and_wait()
                self._reset_pp()
                log.info("%s: RAPID stopped and the program pointer restored to main", self.url)
            except Exception as exc:                               # noqa: BLE001 - close never raises
                log.warning("%s: could not restore the program pointer to main: %s", self.url, exc)
        self.session.close()

    # -- optional capabilities (drivers/base.py)

    def set_motion_limits(self, limits: MotionLimits) -> None:
        """Enforce the caps on every later command: ``cal_speed`` is clamped here (TCP and linear external axes
        to ``max_tcp_speed_mm_s``), and RAPID applies ``VelSet max_joint_speed_pct, max_tcp_speed_mm_s`` plus
        its own clamp before moving."""
        tcp, pct = float(limits.max_tcp_speed_mm_s), float(limits.max_joint_speed_pct)
        if not (math.isfinite(tcp) and tcp > 0 and math.isfinite(pct) and 0 < pct <= 100):
            raise RobotError(f"{self.url}: motion limits need a positive TCP speed (mm/s) and 0 < joint % <= 100, "
                             f"got {tcp} mm/s, {pct} %")
        self._limits = MotionLimits(tcp, pct)
        self._capped_warned = False
        self._epoch = random.SystemRandom().randint(1, 999_999)   # marks this session's cached arguments
        if self.session.client is not None and self.session.routes is not None:
            self._write_values(self._motion_arguments())

    def set_payload(self, payload: Payload) -> None:
        """Load data of ``cal_tool`` (tool0's frame): mass (kg) and centre of gravity (mm, flange frame); written
        now if connected and with every later request. A mass of 0 becomes RAPID's minimum 0.001 kg."""
        mass = float(payload.mass_kg)
        cog = tuple(float(v) for v in payload.cog_flange_mm)
        if not (math.isfinite(mass) and mass >= 0 and len(cog) == 3 and all(math.isfinite(v) for v in cog)):
            raise RobotError(f"{self.url}: payload needs a mass >= 0 kg and a finite CoG (mm), got {payload}")
        self._payload = Payload(mass, cog)
        if self.session.client is not None and self.session.routes is not None:
            self._write_values({"cal_tool": self._tool_literal()})

    def speed_override_pct(self) -> float | None:
        """The controller's speed ratio (%) from the panel, or None if it cannot be read."""
        try:
            path, params = self._routes.speedratio()
            return float(first(self.session.get(path, params), "speedratio", "speedratio"))
        except (DriverError, ValueError) as exc:
            log.info("%s: speed ratio not readable: %s", self.url, exc)
            return None

    def identity(self) -> dict[str, str]:
        """vendor, model (robot type), controller_type (IRC5 / OmniCore), serial, software_version (RobotWare),
        controller_name and absacc (``yes`` if the Absolute Accuracy option is installed, ``no``, ``unknown``)."""
        if self._identity is None:
            self._identity = self._read_identity()
        return dict(self._identity)

    def _read_identity(self) -> dict[str, str]:
        system = self._first_item(("/rw/system", {}))
        ident = self._first_item(self._routes.identity())
        robot = self._first_item(self._routes.robottype())
        try:
            path, params = self._routes.system_options()
            options = [str(i.get("option", "")) for i in self.session.get(path, params)]
            absacc = "yes" if any("absolute accuracy" in o.lower() for o in options) else "no"
        except DriverError as exc:
            log.info("%s: system options not readable: %s", self.url, exc)
            absacc = "unknown"
        return {"vendor": "ABB", "model": str(robot.get("robot-type", "unknown")),
                "controller_type": "IRC5" if self.session.version == 1 else "OmniCore",
                "serial": str(ident.get("ctrl-id", "unknown")),
                "software_version": f"RobotWare {system.get('rwversion', 'unknown')}",
                "controller_name": str(ident.get("ctrl-name") or system.get("name", "unknown")),
                "rws_version": f"{self.session.version}.0", "absacc": absacc}

    def _first_item(self, route: tuple[str, dict]) -> dict:
        """First item of a GET, or {} when the resource is missing or refused (identity is best effort)."""
        try:
            items = self.session.get(*route)
        except RwsError as exc:
            log.info("%s: %s not readable: %s", self.url, route[0], exc)
            return {}
        return items[0] if items else {}

    def __enter__(self) -> "AbbRwsRobot":
        self.connect()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- extras

    def heartbeat(self) -> None:
        """Keep the RWS session alive while idle (the runner may call this during long measurements)."""
        self.session.heartbeat()

    def write_module(self, name: str, text: str) -> None:
        """Upload ``text`` as ``<remote_dir>/<name>.mod``, read it back and compare, then load it into the task
        (RAPID is stopped for the load and restarted if it was running). Raises RobotError on any mismatch."""
        data = _module_bytes(name, text, self.url)
        remote = f"{self.opts.remote_dir}/{name}.mod"
        self.session.put_file(remote, data)
        back = self.session.get_file(remote)
        if back != data:
            raise RobotError(f"{self.url}: read-back of {remote} differs from what was sent "
                             f"({len(back)} vs {len(data)} bytes); not loaded")
        was_running = self._exec_state() == "running"
        if was_running:
            self._rapid_stop_and_wait()
        try:
            self._load(remote, reset_pp=False)
            if name.lower() not in {m.lower() for m in self._modules()}:
                raise RobotError(f"{self.url}: module {name} is not listed in {self.opts.task} after loading")
            if was_running and name.lower() == self.opts.module.lower():
                self._set_entry_pp()
        except DriverError:
            if was_running:
                self._restart_quietly()
            raise
        if was_running:
            self._rapid_start()
        log.info("%s: module %s written (%d bytes), verified and loaded into %s", self.url, name, len(data),
                 self.opts.task)

    def _restart_quietly(self) -> None:
        """Leave RAPID running as found after a failed load (best effort; the load error is what is raised)."""
        try:
            self._rapid_start()
        except DriverError as exc:
            log.warning("%s: RAPID could not be restarted after the failed load: %s", self.url, exc)

    # -- preflight

    def _preflight(self) -> None:
        """AUTO, motors on, no foreign mastership, CalServer present/loaded, RAPID running, CalServer answering."""
        self._check_opmode()
        self._check_motors()
        self._check_mastership()
        self._elog_mark = self._newest_elog()
        ident = self.identity()
        log.info("%s: %s %s, serial %s, %s", self.url, ident["controller_type"], ident["model"], ident["serial"],
                 ident["software_version"])
        if ident["absacc"] == "yes":
            log.warning("%s: Absolute Accuracy is installed: joint moves are unaffected, but Cartesian targets "
                        "corrected by this campaign must not be written back (the controller would correct them "
                        "twice)", self.url)
        if self.opts.upload_module:
            self._install_calserver()
        else:
            self._check_module()
        self._check_running()
        self._check_version()
        self._sync_seq()
        self._ping()
        self._write_values(self._motion_arguments())     # cached from here on: a move writes 3 symbols

    def _check_opmode(self) -> None:
        mode = self._opmode()
        if mode != "AUTO":
            raise RobotNotReady(f"{self.url}: controller is in {mode} mode, not AUTO (turn the mode key to AUTO)")

    def _check_motors(self) -> None:
        state = self._ctrlstate()
        if state == "motoroff" and self.opts.motors_on:
            path, params = self._routes.set_ctrlstate()
            self.session.post(path, params, {"ctrl-state": "motoron"})
            self._sleep(min(0.5, self.opts.poll_s))
            state = self._ctrlstate()
        if state != "motoron":
            hint = "press Motors On or set options.motors_on" if state == "motoroff" else "reset the stop first"
            raise RobotNotReady(f"{self.url}: motors are not on (ctrlstate={state}; {hint})")

    def _check_mastership(self) -> None:
        for domain in (self._routes.edit_domain, "motion"):
            path, params = self._routes.mastership(domain)
            try:
                items = self.session.get(path, params)
            except RwsError as exc:
                log.info("%s: mastership state %s not readable (%s)", self.url, domain, exc)
                continue
            item = items[0] if items else {}
            holder = str(item.get("mastership", "nomaster")).lower()
            mine = str(item.get("mastershipheldbyme", "false")).lower() == "true"
            if holder not in ("nomaster", "", "internal") and not mine:     # internal: RAPID itself while it runs
                who = item.get("application") or item.get("location") or holder
                raise RobotNotReady(f"{self.url}: {domain} mastership is held by another client ({who}); "
                                    "release write access in RobotStudio / close the FlexPendant editor")

    def _check_module(self) -> None:
        if self.opts.module.lower() not in {m.lower() for m in self._modules()}:
            raise RobotNotReady(f"{self.url}: RAPID module {self.opts.module} is not loaded in {self.opts.task} "
                                "(load drivers/rapid/CalServer.mod or set options.upload_module: true)")

    def _check_running(self) -> None:
        state = self._exec_state()
        if state == "running":
            return
        if not self.opts.start_rapid:
            raise RobotNotReady(f"{self.url}: RAPID execution is {state} (set the PP to routine {ENTRY_ROUTINE} "
                                "and start, or set options.start_rapid: true)")
        self._set_entry_pp()
        self._rapid_start()

    def _check_version(self) -> None:
        try:
            version = parse_num(self._read("cal_version"))
        except RwsError as exc:
            raise RobotNotReady(f"{self.url}: {self.opts.module} has no readable cal_version ({exc.code}); "
                                "upload the module shipped with this driver") from exc
        if int(version) != CALSERVER_VERSION:
            raise RobotNotReady(f"{self.url}: {self.opts.module} interface version {version:g} on the controller, "
                                f"driver needs {CALSERVER_VERSION} (upload the module shipped with this driver)")

    def _sync_seq(self) -> None:
        """Next request number = one above every sequence counter on the controller."""
        names = ("cal_req_seq", "cal_ack_seq", "cal_done_seq", "cal_err_seq")
        self._seq = max(int(parse_num(self._read(n))) for n in names)
        self._written.clear()

    def _ping(self) -> None:
        """A no-motion request proves the CalServer loop answers."""
        try:
            self._command(KIND_PING, {}, "ping", move_s=0.0)
        except MotionError as exc:
            raise RobotNotReady(f"{self.url}: CalServer does not answer ({exc}){self._pp_hint()}") from exc

    def _pp_hint(self) -> str:
        """Where the program pointer is, for a CalServer that does not answer (best effort)."""
        try:
            item = self._first_item(self._routes.pcp(self.opts.task))
        except DriverError:
            return ""
        module, routine = item.get("modulemame") or item.get("modulename"), item.get("routinename")
        if not module or str(routine).lower() == ENTRY_ROUTINE:
            return ""
        return (f"; the program pointer is in {module}/{routine}: run {ENTRY_ROUTINE} (PP to routine, or call "
                f"'{ENTRY_ROUTINE};' from main)")

    def _install_calserver(self) -> None:
        """Upload and verify CalServer, stop RAPID, load it with PP to main, and start RAPID."""
        text = _read_text(self.opts.module_file) if self.opts.module_file else calserver_source()
        data = _module_bytes(self.opts.module, text, self.url)
        remote = f"{self.opts.remote_dir}/{self.opts.module}.mod"
        self.session.put_file(remote, data)
        if self.session.get_file(remote) != data:
            raise RobotNotReady(f"{self.url}: read-back of {remote} differs from the uploaded module")
        if self._exec_state() == "running":
            self._rapid_stop_and_wait()
        self._load(remote, reset_pp=False)
        self._check_module()
        self._set_entry_pp()
        self._rapid_start()
        log.info("%s: %s uploaded to %s, loaded into %s and started", self.url, self.opts.module, remote,
                 self.opts.task)

    # -- the handshake

    def _command(self, kind: int, args: Mapping[str, str], what: str, *, move_s: float | None = None) -> None:
        """Write the request, wait for ack and done (or error); any failure but a RAPID rejection makes the next
        command check the controller and resynchronise the sequence numbers first."""
        if self._suspect:
            self._require_ready()
        seq = self._seq + 1
        limit = self.opts.timeouts.move_s if move_s is None else move_s
        try:
            self._write_request(kind, args, seq)
            self._seq = seq
            self._await_done(seq, what, limit + self.opts.settle_s * (kind != KIND_PING))
        except RapidRejected:
            raise
        except DriverError:
            self._suspect = True
            raise

    def _write_request(self, kind: int, args: Mapping[str, str], seq: int) -> None:
        """Arguments first (only speed, settle, caps and tool are cached: a stale kind or target is never safe),
        then the trigger. The speed is clamped to the motion limits here, before anything is sent."""
        values = dict(args, cal_kind=str(kind))
        if kind != KIND_PING:
            self._check_epoch()
            values.update(self._motion_arguments())
        values["cal_req_seq"] = str(seq)
        self._write_values(values)

    def _check_epoch(self) -> None:
        """A reloaded CalServer has its PERS initial values again (speed, caps, tool): if ``cal_epoch`` is not this
        session's mark, forget what was cached so every argument is written again before the trigger."""
        if self._written and int(parse_num(self._read("cal_epoch"))) != self._epoch:
            log.warning("%s: %s was reloaded since the last request; writing every argument again", self.url,
                        self.opts.module)
            self._written.clear()

    def _motion_arguments(self) -> dict[str, str]:
        """The cached arguments of a motion request: capped speed, settle time, caps and tool (RAPID literals)."""
        return {"cal_speed": "[" + ",".join(fmt_num(v) for v in self._speeddata()) + "]",
                "cal_settle_s": fmt_num(self.opts.settle_s), "cal_vmax": fmt_num(self._limits.max_tcp_speed_mm_s),
                "cal_override": fmt_num(min(100.0, self._limits.max_joint_speed_pct)), "cal_tool": self._tool_literal(),
                "cal_epoch": str(self._epoch)}

    def _speeddata(self) -> tuple[float, float, float, float]:
        """``options.speed`` with v_tcp and v_leax clamped to the TCP speed cap (mm/s)."""
        v_tcp, v_ori, v_leax, v_reax = self.opts.speed
        cap = self._limits.max_tcp_speed_mm_s
        if max(v_tcp, v_leax) > cap and not self._capped_warned:
            self._capped_warned = True
            log.warning("%s: options.speed %g mm/s is above the %g mm/s cap; moving at the cap", self.url,
                        max(v_tcp, v_leax), cap)
        return min(v_tcp, cap), v_ori, min(v_leax, cap), v_reax

    def _tool_literal(self) -> str:
        """``cal_tool``: tool0's frame with the payload's loaddata (kg, mm); RAPID's minimum mass without one."""
        mass, cog = (0.0, (0.0, 0.0, 0.001)) if self._payload is None else \
            (self._payload.mass_kg, self._payload.cog_flange_mm)
        load = f"[{fmt_num(max(mass, 0.001))},[{','.join(fmt_num(v) for v in cog)}],[1,0,0,0],0,0,0]"
        return f"[TRUE,[[0,0,0],[1,0,0,0]],{load}]"

    def _write_values(self, values: Mapping[str, str]) -> None:
        """Write CalServer symbols in order; implicit mastership first, and for the rest of the session explicit
        edit mastership (requested with retries, released after the block) once the controller refuses implicit."""
        if not self._explicit:
            try:
                for name, literal in values.items():
                    self._write(name, literal, cache=name in _CACHED)
                return
            except _MasterRejected:
                self._explicit = True
                log.warning("%s: implicit mastership refused (403 E_MASTER_REJECT); using explicit edit "
                            "mastership for writes", self.url)
        with self._edit_mastership():
            for name, literal in values.items():
                self._write(name, literal, cache=name in _CACHED)

    def _await_done(self, seq: int, what: str, move_s: float) -> None:
        """Poll ``cal_state`` = [ack, done, err] and every ``health_s`` the RAPID execution state, never faster than
        ``max_poll_rate_hz`` requests per second (at least ``poll_s`` between polls)."""
        ack_deadline = Deadline(self.opts.timeouts.ack_s)
        deadline = Deadline(self.opts.timeouts.ack_s + move_s)
        health = Deadline(self.opts.health_s)
        pacer = _Pacer(self.opts.max_poll_rate_hz, self._sleep)
        acked = False
        while True:
            ack, done, err = self._read_state()
            pacer.count()
            if done == seq:
                return
            if err == seq:
                self._raise_rejected(seq, what)
            acked = acked or ack >= seq
            if health.expired():
                pacer.count(self._check_health(seq, what))
                health = Deadline(self.opts.health_s)
            if not acked and (ack_deadline.expired() or deadline.expired()):
                self._fail(seq, what, f"CalServer did not acknowledge within {self.opts.timeouts.ack_s:g} s")
            if deadline.expired():
                self._fail(seq, what, f"not done within {deadline.seconds:g} s")
            pacer.wait(self.opts.poll_s)

    def _read_state(self) -> tuple[int, int, int]:
        """(ack, done, err) request numbers from ``cal_state`` in one request."""
        text = self._read("cal_state").strip()
        try:
            values = [int(float(v)) for v in text.strip("[]").split(",")]
        except ValueError:
            values = []
        if len(values) != 3:
            raise DriverError(f"{self.url}: cal_state is not [ack,done,err]: {text[:40]!r}")
        return values[0], values[1], values[2]

    def _check_health(self, seq: int, what: str) -> int:
        """RAPID must run (it stops when the motors go off); returns the number of requests made."""
        state = self._exec_state()
        if state == "running":
            return 1
        ctrl = self._ctrlstate()
        if ctrl != "motoron":
            self._fail(seq, what, f"motors went off (ctrlstate={ctrl})")
        self._fail(seq, what, f"RAPID execution {state}")
        return 2

    def _fail(self, seq: int, what: str, reason: str) -> None:
        """Stop RAPID (best effort) and raise MotionError with the reason and new elog errors."""
        self.stop()
        raise MotionError(f"{self.url}: request #{seq} ({_short(what)}) failed: {reason}{self._elog_errors()}")

    def _raise_rejected(self, seq: int, what: str) -> None:
        """The RAPID loop rejected the request: MotionError with its message and ERRNO."""
        message = parse_string(self._read("cal_err_msg"))
        errno = int(parse_num(self._read("cal_err_no")))
        raise RapidRejected(f"{self.url}: request #{seq} ({_short(what)}) rejected by RAPID: {message} "
                            f"(ERRNO {errno})", errno)

    def _require_ready(self) -> None:
        """After a failure: RobotNotReady unless motors are on and RAPID runs again."""
        ctrl, state = self._ctrlstate(), self._exec_state()
        if ctrl != "motoron" or state != "running":
            raise RobotNotReady(f"{self.url}: controller not ready after the previous failure "
                                f"(ctrlstate={ctrl}, RAPID {state}); operator action needed")
        self._sync_seq()
        self._suspect = False

    # -- RAPID program control

    @contextmanager
    def _edit_mastership(self) -> Iterator[None]:
        """Hold the RAPID-edit mastership (``rapid`` on 1.0, ``edit`` on 2.0) for the block; always release.
        A request refused because another client holds it is retried with backoff (``retry`` options)."""
        domain = self._routes.edit_domain
        delay = self.opts.retry.backoff_s
        for attempt in range(self.opts.retry.retries + 1):
            try:
                self._mastership(domain, "request")
                break
            except RobotNotReady:
                if attempt == self.opts.retry.retries:
                    raise
                log.info("%s: %s mastership held elsewhere; retry %d/%d in %.2f s", self.url, domain, attempt + 1,
                         self.opts.retry.retries, delay)
                self._sleep(delay)
                delay = min(delay * 2, self.opts.retry.backoff_max_s)
        try:
            yield
        finally:
            self._mastership(domain, "release", quiet=True)

    def _set_entry_pp(self) -> None:
        """RAPID stopped: PP to routine ``cal_run`` (restored to main at close) or, with ``entry: main``, PP to
        the task's main (which must call ``cal_run``)."""
        with self._edit_mastership():
            if self.opts.entry == "main":
                self._post_resetpp()
                return
            path, params = self._routes.pp_to_routine(self.opts.task)
            try:
                self.session.post(path, params, {"module": self.opts.module, "routine": ENTRY_ROUTINE,
                                                 "userlevel": "false"})
            except RwsError as exc:
                raise RobotNotReady(f"{self.url}: cannot set the program pointer to {self.opts.module}/"
                                    f"{ENTRY_ROUTINE} ({exc})") from exc
            self._restore_pp = True

    def _load(self, remote: str, *, reset_pp: bool) -> None:
        """``loadmod`` (replace) under edit mastership, optionally followed by PP to main."""
        with self._edit_mastership():
            path, params = self._routes.loadmod(self.opts.task)
            self.session.post(path, params, {"modulepath": remote, "replace": "true"},
                              timeout=self.opts.timeouts.load_s)
            if reset_pp:
                self._post_resetpp()

    def _reset_pp(self) -> None:
        """PP to main (edit mastership is required on RWS 2.0; taken on both)."""
        with self._edit_mastership():
            self._post_resetpp()

    def _post_resetpp(self) -> None:
        path, params = self._routes.execution_action("resetpp")
        self.session.post(path, params, {})

    def _rapid_start(self) -> None:
        """Start RAPID (cycle forever) and wait until the execution state says running."""
        path, params = self._routes.execution_action("start")
        form = {"regain": "continue", "execmode": "continue", "cycle": "forever", "condition": "none",
                "stopatbp": "disabled", "alltaskbytsp": "false"}
        try:
            self.session.post(path, params, form)
        except RwsError as exc:
            raise RobotNotReady(f"{self.url}: RAPID start refused ({exc})") from exc
        self._wait_exec("running")

    def _rapid_stop_and_wait(self) -> None:
        path, params = self._routes.execution_action("stop")
        self.session.post(path, params, {"stopmode": "stop", "usetsp": "normal"})
        self._wait_exec("stopped")

    def _wait_exec(self, wanted: str) -> None:
        deadline = Deadline(self.opts.timeouts.ack_s)
        while self._exec_state() != wanted:
            if deadline.expired():
                raise RobotNotReady(f"{self.url}: RAPID execution did not become {wanted} "
                                    f"within {deadline.seconds:g} s")
            self._sleep(min(self.opts.poll_s, 0.05))

    def _mastership(self, domain: str, verb: str, *, quiet: bool = False) -> None:
        path, params = self._routes.mastership_action(domain, verb)
        try:
            self.session.post(path, params, {})
        except RwsError as exc:
            if quiet:
                log.warning("%s: mastership %s %s failed: %s", self.url, domain, verb, exc)
                return
            if exc.code == E_RESOURCE_HELD:
                raise RobotNotReady(f"{self.url}: {domain} mastership is held by another client") from exc
            raise

    # -- reads and writes

    def _read(self, name: str) -> str:
        """Value literal of a CalServer symbol."""
        path, params = self._routes.symbol(self.opts.task, self.opts.module, name)
        return first(self.session.get(path, params), "value", name)

    def _write(self, name: str, literal: str, *, cache: bool) -> None:
        """Write a CalServer symbol (skipped if this session already wrote the same literal)."""
        if cache and self._written.get(name) == literal:
            return
        path, params = self._routes.set_symbol(self.opts.task, self.opts.module, name, implicit=not self._explicit)
        try:
            self.session.post(path, params, {"value": literal})
        except RwsError as exc:
            self._written.pop(name, None)
            if exc.code == E_MASTER_REJECT and not self._explicit:
                raise _MasterRejected(str(exc)) from exc
            if exc.code == E_RESOURCE_HELD:
                raise RobotNotReady(f"{self.url}: cannot write {name}: RAPID mastership held by another client") \
                    from exc
            raise
        self._written[name] = literal

    def _ctrlstate(self) -> str:
        path, params = self._routes.ctrlstate()
        return first(self.session.get(path, params), "ctrlstate", "ctrlstate")

    def _opmode(self) -> str:
        path, params = self._routes.opmode()
        return first(self.session.get(path, params), "opmode", "opmode")

    def _exec_state(self) -> str:
        path, params = self._routes.execution()
        return first(self.session.get(path, params), "ctrlexecstate", "execution")

    def _modules(self) -> list[str]:
        path, params = self._routes.modules(self.opts.task)
        return [str(i.get("name", "")) for i in self.session.get(path, params)]

    def _elog_entries(self) -> list[dict]:
        """Common elog entries (newest first) with int ``seqnum``; empty if the log is not readable."""
        path, params = self._routes.elog()
        try:
            items = self.session.get(path, params)
        except DriverError as exc:
            log.info("%s: event log not readable: %s", self.url, exc)
            return []
        out = []
        for item in items:
            try:
                out.append(dict(item, seqnum=int(str(item.get("_title", "")).rstrip("/").split("/")[-1])))
            except ValueError:
                continue
        return out

    def _newest_elog(self) -> int | None:
        """Newest sequence number in the log (uint16 wrap-aware), or None for an empty/unreadable log."""
        newest = None
        for entry in self._elog_entries():
            if _newer(entry["seqnum"], newest):
                newest = entry["seqnum"]
        return newest

    def _elog_errors(self) -> str:
        """``; elog: code title`` for error entries (msgtype >= 3) newer than the mark; advances the mark."""
        entries = [e for e in self._elog_entries() if _newer(e["seqnum"], self._elog_mark)]
        for entry in entries:
            if _newer(entry["seqnum"], self._elog_mark):
                self._elog_mark = entry["seqnum"]
        errors = [f"{e.get('code', '?')} {e.get('title', '')}".strip() for e in entries
                  if str(e.get("msgtype", "0")).isdigit() and int(e["msgtype"]) >= 3]
        return f"; elog: {'; '.join(errors[:3])}" if errors else ""


# --------------------------------------------------------------------------- helpers and factory


class _MasterRejected(RobotError):
    """A write refused for lack of mastership (403 E_MASTER_REJECT): switch to explicit mastership."""


class _Pacer:
    """Keeps a polling loop at or under ``rate_hz`` requests per second: ``count`` the requests made, then
    ``wait`` sleeps at least ``min_s`` and long enough for the requests since the previous wait."""

    def __init__(self, rate_hz: float, sleep: Callable[[float], None]) -> None:
        self.rate_hz, self._sleep, self._n = rate_hz, sleep, 0

    def count(self, n: int = 1) -> None:
        self._n += n

    def wait(self, min_s: float) -> None:
        self._sleep(max(min_s, self._n / self.rate_hz))
        self._n = 0


def _newer(seq: int, mark: int | None) -> bool:
    """uint16 sequence comparison with wrap-around."""
    return mark is None or 0 < (seq - mark) % 65536 < 32768


def _short(text: str, limit: int = 80) -> str:
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _fmt_q(q: Sequence[float]) -> str:
    return "[" + ", ".join(f"{v:.3f}" for v in q) + "] deg"


def _module_bytes(name: str, text: str, url: str) -> bytes:
    """Validate a module name/text pair and encode it (ISO-8859-1, as RobotWare reads modules)."""
    if not _IDENT.match(name):
        raise RobotError(f"{url}: {name!r} is not a RAPID module name (letter, then letters/digits/_; max 32)")
    if not re.search(rf"^\s*MODULE\s+{re.escape(name)}\b", text, re.IGNORECASE | re.MULTILINE) \
            or not re.search(r"\bENDMODULE\b", text, re.IGNORECASE):
        raise RobotError(f"{url}: module text must start with 'MODULE {name}' and end with 'ENDMODULE'")
    try:
        return text.encode("latin-1")
    except UnicodeEncodeError as exc:
        raise RobotError(f"{url}: module {name} has characters outside ISO-8859-1 ({exc.reason})") from None


def _read_text(path: str) -> str:
    """A local module file (ISO-8859-1); DriverError if unreadable."""
    try:
        return open(os.path.expanduser(path), encoding="latin-1").read()
    except OSError as exc:
        raise DriverError(f"abb-rws: options.module_file: cannot read {path}: {exc.strerror}") from None


def _verify(value: bool | str) -> Any:
    """httpx ``verify``: bool, or an SSL context trusting the given CA/certificate PEM file."""
    if isinstance(value, bool):
        return value
    import ssl
    try:
        return ssl.create_default_context(cafile=os.path.expanduser(value))
    except (OSError, ssl.SSLError) as exc:
        raise DriverError(f"abb-rws: options.verify: cannot load {value}: {exc}") from exc


def open_robot(url: str, options: Mapping[str, Any], **context: Any) -> AbbRwsRobot:
    """Registry factory: validate options, resolve credentials, return an unconnected ``AbbRwsRobot``.

    ``context`` may carry ``n_joints`` (from the robot config), ``transport`` (an httpx transport, for tests)
    and ``environ`` (a mapping replacing ``os.environ`` for the credential lookup)."""
    opts = RwsOptions.from_mapping(options or {})
    if "n_joints" in context and "n_joints" not in (options or {}):
        opts = replace(opts, n_joints=int(context["n_joints"]))
    credentials = load_credentials(opts.credentials, context.get("environ"))
    return AbbRwsRobot(url, opts, credentials, transport=context.get("transport"))


def validate_options(url: str, options: Mapping[str, Any], **context: Any) -> None:
    """What ``open_robot`` checks, without credentials or a connection: the url's host and the options."""
    parts = urlsplit(url)
    try:
        parts.port
    except ValueError as exc:
        raise DriverError(f"{url}: {exc}") from None
    if parts.scheme != "abb-rws" or not parts.hostname:
        raise DriverError(f"{url}: expected abb-rws://host[:port]")
    opts = RwsOptions.from_mapping(options or {})
    n = context.get("n_joints")
    if n is not None and "n_joints" not in (options or {}) and not 1 <= int(n) <= 6:
        raise DriverError(f"{url}: an ABB robot has 1 to 6 robot axes, the config has {n} joints")
    del opts
