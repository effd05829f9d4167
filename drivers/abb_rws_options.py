"""Options and credentials of the ABB RWS driver (``drivers.abb_rws``): parsing, validation, defaults."""

from __future__ import annotations

import logging
import math
import os
import stat
from dataclasses import dataclass, field, replace
from typing import Any, Mapping, Sequence

from .base import DriverError, MotionError
from .redaction import register_secret
from .rws_client import Credentials, RetryPolicy, Timeouts

log = logging.getLogger("drivers.abb_rws")

DEFAULT_USER, DEFAULT_PASSWORD = "Default User", "robotics"   # ABB's documented factory account


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
    n_joints: int = 6                         # 7: a seven-axis arm (YuMi), or a 6-axis arm on ``track_unit``
    track_unit: str | None = None             # the track's mechanical unit (eax_a of the robot's targets)
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

    _SCALARS = {"task": str, "module": str, "mechunit": str, "remote_dir": str, "module_file": str, "track_unit": str,
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
            kw["n_joints"] = self._int("n_joints", 1, 7)
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
        register_secret(password)                       # masked in every line and file the software writes
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
        with open(path, encoding="utf-8") as fh:
            text = fh.read()
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
    register_secret(values["password"])
    return Credentials(values["user"], values["password"])
