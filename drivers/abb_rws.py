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
import time
from dataclasses import replace
from typing import Any, Callable, Mapping, Sequence
from urllib.parse import urlsplit

import httpx

from .abb_axes import axes_layout
from .base import DriverError, MotionError, MotionLimits, Payload, RobotError, RobotNotReady
from .rws_client import Credentials, Routes, RwsError, RwsSession, first
from .rapid import calserver_text
from .rapid.literals import fmt_jointtarget, fmt_num, fmt_robtarget, fmt_string, parse_num, parse_string  # noqa: F401
from .abb_rws_options import (DEFAULT_PASSWORD, DEFAULT_USER, CredentialOptions, OptionsError, RapidRejected,  # noqa: F401
                              RwsOptions, load_credentials)
from .abb_rws_preflight import (CALSERVER_VERSION, KIND_MOVEABSJ, KIND_MOVEL, KIND_PING, PreflightMixin,  # noqa: F401
                                module_bytes)
from .abb_rws_program import ENTRY_ROUTINE, Deadline, RapidProgramMixin, MasterRejected  # noqa: F401

log = logging.getLogger(__name__)

_CACHED = ("cal_speed", "cal_settle_s", "cal_vmax", "cal_override", "cal_tool", "cal_epoch")


# --------------------------------------------------------------------------- the robot


calserver_source = calserver_text   # the packaged drivers/rapid/CalServer.mod (one loader: drivers.rapid)


class AbbRwsRobot(PreflightMixin, RapidProgramMixin):
    """``Robot`` over RWS driving CalServer.mod; also ``move_linear``, ``write_module`` and ``heartbeat``."""

    def __init__(self, url: str, options: RwsOptions, credentials: Credentials, *,
                 transport: httpx.BaseTransport | None = None, sleep: Callable[[float], None] = time.sleep) -> None:
        parts = urlsplit(url)
        if parts.scheme != "abb-rws" or not parts.hostname:
            raise DriverError(f"{url}: expected abb-rws://host[:port]")
        self.url, self.opts, self.n_joints = url, options, options.n_joints
        try:
            self.axes = axes_layout(options.n_joints, options.track_unit is not None)
        except ValueError as exc:
            raise DriverError(f"{url}: {exc}") from None
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
        self._command(KIND_MOVEABSJ, {"cal_target": fmt_jointtarget(*self.axes.split(q))}, f"MoveAbsJ {_fmt_q(q)}")

    def move_linear(self, trans_mm: Sequence[float], quat_wxyz: Sequence[float],
                    conf: Sequence[int] = (0, 0, 0, 0), ext: Sequence[float] = ()) -> None:
        """MoveL (tool0, wobj0) to the pose (mm, w-first quaternion, confdata) with a fine stop and settle dwell;
        ``ext``: its external axes (a track's carriage in mm, a seven-axis arm's arm angle in deg: ``eax_a``)."""
        try:
            literal = fmt_robtarget(trans_mm, quat_wxyz, conf, ext)
        except ValueError as exc:
            raise MotionError(f"{self.url}: {exc}") from None
        self._command(KIND_MOVEL, {"cal_ptarget": literal}, f"MoveL {literal}")

    def read_joints(self) -> tuple[float, ...]:
        """Actual joints (deg) of the mechanical unit, ``rax_1..rax_n``; a seven-axis arm's axis 7 is its ``eax_a``,
        a track's carriage (mm) the ``eax_a`` of the track's own unit (``abb_axes``)."""
        path, params = self._routes.jointtarget(self.opts.mechunit)
        items = self.session.get(path, params)
        rob = [parse_num(first(items, f"rax_{i + 1}", "jointtarget")) for i in range(min(6, self.n_joints))]
        if self.axes.external == 0:
            return tuple(rob)
        if self.opts.track_unit is not None:
            items = self.session.get(*self._routes.jointtarget(self.opts.track_unit))
        return self.axes.join(rob, [parse_num(first(items, "eax_a", "jointtarget"))])

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
        data = module_bytes(name, text, self.url)
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
            except MasterRejected:
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

# --------------------------------------------------------------------------- helpers and factory


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


def _short(text: str, limit: int = 80) -> str:
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _fmt_q(q: Sequence[float]) -> str:
    return "[" + ", ".join(f"{v:.3f}" for v in q) + "] deg"


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
    opts = _with_context(RwsOptions.from_mapping(options or {}), options, context)
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
    opts = _with_context(RwsOptions.from_mapping(options or {}), options, context)
    try:
        axes_layout(opts.n_joints, opts.track_unit is not None)
    except ValueError as exc:
        raise DriverError(f"{url}: {exc}") from None


def _with_context(opts: RwsOptions, options, context: Mapping[str, Any]) -> RwsOptions:
    """The options with the config's joint count and track unit where the options do not set them."""
    given = options or {}
    if "n_joints" in context and "n_joints" not in given:
        opts = replace(opts, n_joints=int(context["n_joints"]))
    if context.get("track_unit") and "track_unit" not in given:
        opts = replace(opts, track_unit=str(context["track_unit"]))
    return opts
