"""Localhost emulator of an ABB controller's Robot Web Services: RWS 1.0 (IRC5) or RWS 2.0 (OmniCore).

It implements what ``drivers.abb_rws`` and public RWS clients (``abb_robot_client.rws.RWS`` for RWS 1.0, the RWS 2.0
client ``RWS2`` of the Mesh-ch fork of abb_robot_client) use:

- authentication: real Digest (RFC 7616 / 2617, MD5, ``qop="auth"``, realm ``validusers@robapi.abb``, fresh nonce
  per challenge, stale nonces rejected) on 1.0; Basic on 2.0 (Digest rejected);
- sessions: cookies ``-http-session-`` and ``ABBCX`` set on the first authenticated answer; a valid cookie
  authenticates; a session cap (default 70) answers 503; idle sessions expire; ``GET /logout`` frees the slot
  and the session's mastership;
- representations: 1.0 ``?json=1`` (``_embedded._state``, ``Content-Type: application/json`` exactly) or XHTML;
  2.0 HAL (``state[]`` / ``_embedded.resources[]``) requiring ``Accept: …;v=2.0`` (else 406) and ``;v=2.0``
  request bodies (else 415); error envelopes with RobotWare return codes;
- controller model: operating mode, controller state, RAPID execution state and cycle, the program pointer
  (module, routine), mastership per domain and session (``internal`` for motion while RAPID runs), a task ``T_ROB1``
  whose modules are parsed from uploaded ``.mod`` text (module-level ``PERS``/``VAR``/``CONST`` declarations
  become typed RAPID symbols, procedures and what ``main`` calls are recorded), a production program
  ``MainModule`` (its ``main`` calls ``cal_run`` or not: ``customer_program``), a file service (``$HOME``,
  ``$TEMP``, ``$RAMDISK``), the ROB_1 joint and Cartesian state (also as the task's ``motion/jointtarget`` and
  ``motion/robtarget`` read by RW7 clients), speed ratio, identity (``/ctrl/identity``, robot type, system
  options with or without ``Absolute Accuracy``) and an event log;
- rules: motors on only in AUTO; start only in AUTO with motors on, stopped, PP set, program linked (2.0: caller
  holds no edit mastership); resetpp / PP to routine / loadmod only when stopped and with edit mastership;
  a second ``main`` (or main calling an unknown procedure) loads but does not link, as on a controller: elog
  "Link error" and start / PP moves answer 400 ``-1073442802``; PP to a routine with parameters -> 400
  ``-1073442801``; foreign mastership -> 403 ``-1073445862``; missing mastership (and, with
  ``implicit_mastership=False``, writes with ``mastership=implicit``) -> 403 ``-1073445859``; bad literal -> 400
  ``-1073445879``; unknown symbol -> 1.0 400 ``-1073414146`` / 2.0 404 ``-1073442816``; missing load file -> 400
  ``-1073438708``;
- a thread that plays ``CalServer.mod`` while RAPID runs cal_run (PP at cal_run, or at a main calling it):
  resync on a PP move, ack, ``cal_limit`` (clamp the speed to ``cal_vmax``, VelSet override; recorded with the
  ``cal_tool`` load in ``executed``), move the simulated robot at ``joint_speed_deg_s`` x override (interrupted if
  RAPID stops or motors go off), call the ``move_hook`` (plug the campaign's mock world in here), dwell
  ``cal_settle_s``, set ``cal_reached`` and done; ``cal_state`` mirrors [ack, done, err];
- fault injection: 503 storms, 401 (session expiry) on the next requests, motors off / RAPID stop / RAPID-side
  error / hang on the next move, manual mode, foreign mastership (optionally released after N refusals), extra
  elog entries.

Not implemented: subscriptions / WebSockets, IO signals, RMMP, configuration, XHTML on RWS 2.0 beyond the basics.

RWS 2.0 is served over HTTPS with a throwaway self-signed certificate when the ``cryptography`` package is
installed (``tls=None``, the default); otherwise, or with ``tls=False`` / ``--http``, over plain HTTP on loopback.
The server binds to loopback only. Elog codes produced by faults are illustrative.

Run: ``python -m drivers.emulators.rws_server --version 1 --port 0 --print-port``; in-process:
``with RwsEmulator(version=2) as emu: open_robot(emu.url, {...})``.
"""
from __future__ import annotations

import argparse
import base64
import hashlib
import hmac
import ipaddress
import json
import logging
import os
import re
import secrets
import signal
import ssl
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from datetime import datetime
from email.message import Message
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from typing import Any, Callable, Iterable, Sequence
from urllib.parse import parse_qs, unquote, urlsplit
from urllib.request import parse_http_list, parse_keqv_list

log = logging.getLogger(__name__)

REALM = "validusers@robapi.abb"
S_OK = 294912
E = {  # RobotWare return codes used here -> description
    -1073445879: "An argument specified by the client is not valid for this type of operation.",
    -1073445866: "The URL used to initialize the helper does not resolve to a valid object.",
    -1073445862: "Requested resource is held by someone else.",
    -1073445860: "The operation is not allowed in current operation mode.",
    -1073445859: "The user does not have required mastership for the operation.",
    -1073442816: "RAPID symbol was not found.",
    -1073442814: "The given file was not recognized as a program file.",
    -1073442813: "Ambiguous module name.",
    -1073442809: "Operation is illegal in current execution state.",
    -1073442802: "Operation not allowed due to semantic error(s).",
    -1073442801: "Given routine is not a legal entrypoint.",
    -1073442783: "No program pointer is available.",
    -1073438716: "Invalid path.",
    -1073438713: "The directory does not exist.",
    -1073438708: "File not found or could not be opened for reading.",
    -1073435887: "The requested action cannot be performed in the current state.",
    -1073414146: "Unspecified error.",
}
INVALIDARG, UNRESOLVED_URL, RESOURCE_HELD, MODE_REJECT, MASTER_REJECT = (
    -1073445879, -1073445866, -1073445862, -1073445860, -1073445859)
NO_SUCH_SYMBOL, INVALID_PROGRAMFILE, MOD_AMBNAME, EXEC_STATE, NO_PP = (
    -1073442816, -1073442814, -1073442813, -1073442809, -1073442783)
INVALID_PATH, DIR_NOT_EXIST, FILE_NOT_FOUND, INVALID_STATE, E_FAIL = (
    -1073438716, -1073438713, -1073438708, -1073435887, -1073414146)
RAPID_SEMANTIC_ERROR, ILLEGAL_ENTRYPOINT = -1073442802, -1073442801
ENTRY = "cal_run"      # CalServer's entry routine

TASK = "T_ROB1"
VOLUMES = ("HOME", "TEMP", "RAMDISK")
DEFAULT_LIMITS_DEG = ((-180, 180), (-95, 155), (-180, 75), (-400, 400), (-120, 120), (-400, 400))
UNUSED = 9e9


# --------------------------------------------------------------------------- RAPID literals and modules


class RapidSyntaxError(ValueError):
    """A RAPID literal or module that does not parse."""


_TOKEN = re.compile(r'\s*(?:(?P<open>\[)|(?P<close>\])|(?P<comma>,)|(?P<str>"(?:[^"]|"")*")'
                    r'|(?P<bool>TRUE\b|FALSE\b)|(?P<num>[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?))', re.I)


def parse_literal(text: str) -> Any:
    """RAPID literal -> nested lists of float / str / bool (aggregates are lists)."""
    value, pos = _parse_value(text, 0)
    if text[pos:].strip():
        raise RapidSyntaxError(f"trailing text after literal: {text[pos:pos + 20]!r}")
    return value


def _parse_value(text: str, pos: int) -> tuple[Any, int]:
    m = _TOKEN.match(text, pos)
    if not m or m.lastgroup in ("close", "comma"):
        raise RapidSyntaxError(f"unexpected text at {pos}: {text[pos:pos + 20]!r}")
    if m.lastgroup == "num":
        return float(m.group("num")), m.end()
    if m.lastgroup == "str":
        return m.group("str")[1:-1].replace('""', '"'), m.end()
    if m.lastgroup == "bool":
        return m.group("bool").upper() == "TRUE", m.end()
    items, pos = [], m.end()
    while True:
        item, pos = _parse_value(text, pos)
        items.append(item)
        m = _TOKEN.match(text, pos)
        if m and m.lastgroup == "comma":
            pos = m.end()
        elif m and m.lastgroup == "close":
            return items, m.end()
        else:
            raise RapidSyntaxError(f"expected ',' or ']' at {pos}")


N, S, B = "num", "string", "bool"
SHAPES: dict[str, Any] = {
    "num": N, "dnum": N, "bool": B, "string": S, "speeddata": [N] * 4, "pos": [N] * 3, "orient": [N] * 4,
    "confdata": [N] * 4, "robjoint": [N] * 6, "extjoint": [N] * 6, "jointtarget": [[N] * 6, [N] * 6],
    "robtarget": [[N] * 3, [N] * 4, [N] * 4, [N] * 6], "pose": [[N] * 3, [N] * 4],
    "loaddata": [N, [N] * 3, [N] * 4, N, N, N],
    "tooldata": [B, [[N] * 3, [N] * 4], [N, [N] * 3, [N] * 4, N, N, N]],
}


def matches(value: Any, shape: Any) -> bool:
    """Whether a parsed literal has the shape of a RAPID type (``SHAPES``)."""
    if shape == N:
        return isinstance(value, float)
    if shape == S:
        return isinstance(value, str)
    if shape == B:
        return isinstance(value, bool)
    return isinstance(value, list) and len(value) == len(shape) and all(map(matches, value, shape))


def render(value: Any) -> str:
    """A parsed literal as the controller prints it: single precision, ``9E+09``, quoted strings."""
    if isinstance(value, bool):
        return "TRUE" if value else "FALSE"
    if isinstance(value, float):
        if abs(value) >= 1e9:
            return "9E+09" if value > 0 else "-9E+09"
        text = f"{value:.7g}".replace("e", "E")
        return "0" if text == "-0" else text
    if isinstance(value, str):
        return '"' + value.replace('"', '""') + '"'
    return "[" + ",".join(render(v) for v in value) + "]"


@dataclass
class Symbol:
    """A module-level RAPID data declaration; ``value`` is the rendered literal."""
    module: str
    name: str
    storage: str        # PERS, VAR, CONST
    dtype: str
    value: str
    array: bool = False


@dataclass
class Module:
    name: str
    text: str
    symbols: dict[str, Symbol]
    has_main: bool
    routines: dict[str, str] = field(default_factory=dict)   # lower-case PROC name -> its parameter text
    main_calls: frozenset[str] = frozenset()                  # lower-case procedures main calls without arguments

    def calls(self, routine: str, callee: str) -> bool:
        """Whether PROC ``routine`` of this module calls ``callee`` (a procedure call statement)."""
        code = _strip_comments(self.text)
        m = re.search(rf"^\s*(?:LOCAL\s+)?PROC\s+{routine}\s*\(.*?^\s*ENDPROC\b", code, re.I | re.M | re.S)
        return bool(m and re.search(rf"^\s*{callee}\s*;", m.group(0), re.I | re.M))


_ROUTINE = re.compile(r"^\s*(?:LOCAL\s+)?(PROC|FUNC|TRAP)\b.*?^\s*END(?:PROC|FUNC|TRAP)\b", re.I | re.M | re.S)
_DECL = re.compile(r"^\s*(?:LOCAL\s+|TASK\s+)?(PERS|VAR|CONST)\s+(\w+)\s+(\w+)\s*(\{[^}]*\})?\s*(?::=\s*(.*?))?;",
                   re.I | re.M | re.S)


def _strip_comments(text: str) -> str:
    """Remove ``!`` comments (outside string literals)."""
    out = []
    for line in text.splitlines():
        quoted = False
        for i, ch in enumerate(line):
            if ch == '"':
                quoted = not quoted
            elif ch == "!" and not quoted:
                line = line[:i]
                break
        out.append(line)
    return "\n".join(out)


def parse_module(text: str) -> Module:
    """Parse a module's name, ``main`` and module-level data declarations (types checked for known types)."""
    code = _strip_comments(text)
    head = re.match(r"\s*MODULE\s+([A-Za-z]\w*)", code, re.I)
    if not head or not re.search(r"^\s*ENDMODULE\b", code, re.I | re.M):
        raise RapidSyntaxError("not a RAPID module (MODULE name ... ENDMODULE)")
    has_main = bool(re.search(r"^\s*PROC\s+main\s*\(\s*\)", code, re.I | re.M))
    routines = {name.lower(): params.strip() for name, params in
                re.findall(r"^\s*(?:LOCAL\s+)?PROC\s+(\w+)\s*\(([^)]*)\)", code, re.I | re.M)}
    data = _ROUTINE.sub("", code)
    symbols = {}
    for storage, dtype, name, dims, init in _DECL.findall(data):
        value = _initial_value(dtype, init, bool(dims), name)
        symbols[name.lower()] = Symbol(head.group(1), name, storage.upper(), dtype.lower(), value, bool(dims))
    main = re.search(r"^\s*PROC\s+main\s*\(\s*\).*?^\s*ENDPROC\b", code, re.I | re.M | re.S)
    calls = frozenset(c.lower() for c in re.findall(r"^\s*(\w+)\s*;", main.group(0), re.M)) if main else frozenset()
    return Module(head.group(1), text, symbols, has_main, routines, calls - RAPID_KEYWORDS)


RAPID_KEYWORDS = frozenset({"stop", "exit", "return", "break", "endproc", "endwhile", "endif", "endfor", "endtest",
                            "else", "retry", "trynext"})

# The production program a cell runs: its main either calls CalServer's entry routine (the documented one-line
# integration) or not (the driver then sets the PP to cal_run and restores it to main when it is done).
CUSTOMER_PROGRAMS = {
    "calls": "MODULE MainModule\n    PROC main()\n        ! production program; campaigns run CalServer\n"
             "        cal_run;\n    ENDPROC\nENDMODULE\n",
    "plain": "MODULE MainModule\n    PERS num cycle_count:=0;\n    PROC main()\n        ! production cycle\n"
             "        cycle_count:=cycle_count+1;\n        WaitTime 1;\n    ENDPROC\nENDMODULE\n",
}


def _initial_value(dtype: str, init: str, array: bool, name: str) -> str:
    """Rendered initial value; zero/empty default when a VAR has no initialiser."""
    shape = SHAPES.get(dtype.lower())
    if not init.strip():
        return render(_zero(shape)) if shape is not None and not array else "[]"
    value = parse_literal(init)
    if shape is not None and not array and not matches(value, shape):
        raise RapidSyntaxError(f"initial value of {name} is not a {dtype}")
    return render(value)


def _zero(shape: Any) -> Any:
    if shape == N:
        return 0.0
    if shape == S:
        return ""
    if shape == B:
        return False
    return [_zero(s) for s in shape]


def calserver_text() -> str:
    """The module shipped with the driver (``drivers/rapid/CalServer.mod``)."""
    return (Path(__file__).resolve().parent.parent / "rapid" / "CalServer.mod").read_text(encoding="latin-1")


# --------------------------------------------------------------------------- HTTP plumbing


@dataclass
class Request:
    """One HTTP request as the emulator sees it (``target`` is the raw request-line target)."""
    method: str
    target: str
    headers: Message | dict
    body: bytes = b""

    @property
    def path(self) -> str:
        return urlsplit(self.target).path

    @property
    def query(self) -> dict[str, list[str]]:
        return parse_qs(urlsplit(self.target).query, keep_blank_values=True)

    def q(self, key: str, default: str | None = None) -> str | None:
        return self.query.get(key, [default])[0]

    def form(self) -> dict[str, str]:
        return {k: v[0] for k, v in parse_qs(self.body.decode("latin-1"), keep_blank_values=True).items()}

    def header(self, name: str) -> str:
        return str(self.headers.get(name) or "")


@dataclass
class Response:
    status: int
    body: bytes = b""
    headers: list[tuple[str, str]] = field(default_factory=list)


class EmulatedMotionFault(Exception):
    """Raised by a ``move_hook``: RAPID stops with an error in the event log (``code``, ``title``)."""

    def __init__(self, title: str, code: int = 50050) -> None:
        super().__init__(title)
        self.title, self.code = title, code


@dataclass
class _Session:
    sid: str
    abbcx: str
    user: str
    last_seen: float


@dataclass
class _Holder:
    """Who holds a mastership domain: a session id (remote client) or a foreign local/remote client."""
    session: str | None
    application: str
    location: str


@dataclass
class _Fault:
    kind: str                  # error, motors_off, rapid_stop, hang
    message: str = ""
    code: int = 0
    after_s: float = 0.0


class RwsEmulator:
    """An in-process RWS server on 127.0.0.1 (see the module docstring). Use as a context manager."""

    def __init__(self, version: int = 1, *, host: str = "127.0.0.1", port: int = 0, tls: bool | None = None,
                 user: str = "Default User", password: str = "robotics", max_sessions: int = 70,
                 session_idle_s: float = 300.0, preload_calserver: bool = True, rapid_running: bool = True,
                 joint_speed_deg_s: float = 200.0, q0_deg: Sequence[float] = (0, 0, 0, 0, 30, 0),
                 joint_limits_deg: Sequence[tuple[float, float]] = DEFAULT_LIMITS_DEG,
                 move_hook: Callable[[tuple[float, ...]], Sequence[float] | None] | None = None,
                 robtarget_hook: Callable[[tuple[float, ...], tuple[float, ...], tuple[int, ...]],
                                          Sequence[float] | None] | None = None,
                 customer_program: str | None = "auto", implicit_mastership: bool = True,
                 serial: str = "6700-104512", robot_type: str = "IRB 6700-150/3.20", absacc: bool = False) -> None:
        if version not in (1, 2):
            raise ValueError("version must be 1 or 2")
        if not ipaddress.ip_address(host).is_loopback:
            raise ValueError(f"the emulator binds to loopback only, not {host}")
        self.version, self.host, self._port = version, host, port
        self.tls = (version == 2 and _have_cryptography()) if tls is None else bool(tls)
        self._user, self._password = user, password
        self.max_sessions, self.session_idle_s = max_sessions, session_idle_s
        self.joint_speed_deg_s, self.joint_limits = joint_speed_deg_s, [tuple(x) for x in joint_limits_deg]
        self.move_hook, self.robtarget_hook = move_hook, robtarget_hook
        self._lock = threading.RLock()
        self._wake = threading.Event()
        self._halt = threading.Event()
        self._opaque = secrets.token_hex(8)
        self._nonces: dict[str, float] = {}
        self._sessions: dict[str, _Session] = {}
        self._fail_503 = 0
        self._fail_401 = 0
        self._faults: list[_Fault] = []
        self.calserver_alive = True    # False: RAPID runs but the loop never takes requests (stuck elsewhere)
        # controller model
        self.opmode, self.ctrlstate, self.speedratio = "AUTO", "motoron", 100
        self.execution, self.cycle, self._fresh_start = "stopped", "forever", True
        self.pp: tuple[str, str] | None = None       # (module, routine) of the program pointer
        self.implicit_mastership = implicit_mastership
        self.serial, self.robot_type = serial, robot_type
        self.system_options = ["RobotWare Base", "English", "PC Interface" if version == 1 else "Robot Web Services",
                               "Multitasking"] + (["Absolute Accuracy"] if absacc else [])
        self.executed: list[dict] = []    # per served motion request: what the simulated RAPID did (speeds, load)
        self._foreign_refusals: dict[str, int] = {}
        self.mastership: dict[str, _Holder] = {}
        self.modules: dict[str, Module] = {}
        self.files: dict[str, bytes] = {}
        self.elog: list[dict] = []
        self._elog_seq = 100
        self.joints = [float(v) for v in q0_deg] + [0.0] * (6 - len(q0_deg))
        self.robtarget = ([600.0, 0.0, 800.0], [0.0, 0.0, 1.0, 0.0], [0, 0, 0, 0])
        self.moves: list[tuple[str, tuple[float, ...]]] = []
        self.requests: list[tuple[str, str, str, int]] = []   # method, path, query, status
        self.counts = {"logouts": 0, "sessions": 0, "auth_failures": 0}
        if customer_program == "auto":
            customer_program = "calls" if preload_calserver else "plain"
        if customer_program is not None:
            self._install(parse_module(CUSTOMER_PROGRAMS[customer_program]))
        if preload_calserver:
            self._install(parse_module(calserver_text()))
        main = next((m.name for m in self.modules.values() if m.has_main), None)
        self.pp = (main, "main") if main else ("CalServer", ENTRY) if preload_calserver else None
        self.add_elog(1, 10011, "Motors ON state")
        if rapid_running and preload_calserver and self._pp_reaches_calserver():
            self.execution = "running"
            self.add_elog(1, 10151, "Program started")
        self._server: ThreadingHTTPServer | None = None
        self._threads: list[threading.Thread] = []
        self._tmpdir: tempfile.TemporaryDirectory | None = None
        self.cert_path: str | None = None

    # -- lifecycle

    def start(self) -> "RwsEmulator":
        """Bind, serve in a thread and start the simulated CalServer loop."""
        ctx = self._ssl_context() if self.tls else None
        self._server = _Server((self.host, self._port), _Handler, self, ctx)
        self._threads = [threading.Thread(target=self._server.serve_forever, kwargs={"poll_interval": 0.05},
                                          name="rws-emulator-http", daemon=True),
                         threading.Thread(target=self._calserver_loop, name="rws-emulator-calserver", daemon=True)]
        for t in self._threads:
            t.start()
        return self

    def stop(self) -> None:
        """Stop serving and the simulated loop."""
        self._halt.set()
        self._wake.set()
        if self._server is not None:
            self._server.shutdown()
            self._server.server_close()
        for t in self._threads:
            t.join(timeout=2)
        self._threads = []
        if self._tmpdir is not None:
            self._tmpdir.cleanup()
            self._tmpdir = None

    def __enter__(self) -> "RwsEmulator":
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    @property
    def port(self) -> int:
        return self._server.server_address[1] if self._server else self._port

    @property
    def scheme(self) -> str:
        return "https" if self.tls else "http"

    @property
    def base_url(self) -> str:
        """``http(s)://127.0.0.1:PORT`` (for third-party clients)."""
        return f"{self.scheme}://{self.host}:{self.port}"

    @property
    def url(self) -> str:
        """``abb-rws://127.0.0.1:PORT`` (for the driver registry)."""
        return f"abb-rws://{self.host}:{self.port}"

    def _ssl_context(self) -> ssl.SSLContext:
        self._tmpdir = tempfile.TemporaryDirectory(prefix="rws-emulator-")
        cert, key = _self_signed_cert(Path(self._tmpdir.name), self.host)
        self.cert_path = cert                   # the self-signed certificate (PEM), for clients that verify
        ctx = ssl.SSLContext(ssl.PROTOCOL_TLS_SERVER)
        ctx.load_cert_chain(cert, key)
        return ctx

    # -- fault injection and operator actions

    def inject_503(self, count: int) -> None:
        """The next ``count`` requests answer 503 (session pool exhausted)."""
        with self._lock:
            self._fail_503 = count

    def inject_401(self, count: int = 1) -> None:
        """The next ``count`` requests answer 401 and their session expires (cookies and nonces forgotten)."""
        with self._lock:
            self._fail_401 = count

    def expire_sessions(self) -> None:
        """Drop every session and nonce (as after a controller-side timeout)."""
        with self._lock:
            for sid in list(self._sessions):
                self._drop_session(sid)
            self._nonces.clear()

    def fail_next_move(self, kind: str, *, message: str = "", code: int = 0, after_s: float = 0.0) -> None:
        """Make the next CalServer motion request fail: ``error`` (cal_err_seq with ``message``), ``motors_off``
        (guard stop: motors off, RAPID stopped), ``rapid_stop`` (execution error ``code`` in the elog, RAPID
        stopped) or ``hang`` (acknowledged, never done); applied ``after_s`` after the acknowledgement."""
        if kind not in ("error", "motors_off", "rapid_stop", "hang"):
            raise ValueError(f"unknown fault kind {kind!r}")
        with self._lock:
            self._faults.append(_Fault(kind, message, code, after_s))

    def set_opmode(self, mode: str) -> None:
        """Turn the mode key (AUTO, MANR, MANF)."""
        with self._lock:
            self.opmode = mode
            if mode != "AUTO" and self.execution == "running":
                self._stop_program(1, 10125, "Program stopped", "mode change")

    def set_ctrlstate(self, state: str) -> None:
        """Operator / safety change of the controller state; leaving motoron stops RAPID."""
        with self._lock:
            self.ctrlstate = state
            if state != "motoron" and self.execution == "running":
                self._stop_program(1, 10010, "Motors OFF state", f"ctrlstate {state}")

    def set_execution(self, running: bool) -> None:
        """Operator start/stop from the FlexPendant (no rule checks)."""
        with self._lock:
            if running:
                self.execution = "running"
            else:
                self._stop_program(1, 10125, "Program stopped", "stopped by operator")
        self._wake.set()

    def hold_mastership(self, domain: str, application: str = "RobotStudio", location: str = "local",
                        release_after: int | None = None) -> None:
        """A foreign client (RobotStudio, FlexPendant editor) takes mastership of ``domain``; with
        ``release_after`` it lets go after refusing that many mastership requests (a short edit)."""
        with self._lock:
            self.mastership[_domain_key(domain)] = _Holder(None, application, location)
            if release_after is not None:
                self._foreign_refusals[_domain_key(domain)] = release_after

    def release_foreign_mastership(self, domain: str) -> None:
        with self._lock:
            self.mastership.pop(_domain_key(domain), None)

    def add_elog(self, msgtype: int, code: int, title: str, desc: str = "") -> int:
        """Append an event log entry; returns its sequence number."""
        with self._lock:
            self._elog_seq = (self._elog_seq + 1) % 65536
            self.elog.append({"seqnum": self._elog_seq, "msgtype": msgtype, "code": code, "title": title,
                              "desc": desc, "tstamp": datetime.now().strftime("%Y-%m-%d T %H:%M:%S")})
            return self._elog_seq

    # -- observation

    def symbol(self, name: str, module: str = "CalServer") -> str:
        """Rendered value of a module symbol."""
        with self._lock:
            return self.modules[module.lower()].symbols[name.lower()].value

    def set_symbol(self, name: str, literal: str, module: str = "CalServer") -> None:
        with self._lock:
            sym = self.modules[module.lower()].symbols[name.lower()]
            sym.value = render(parse_literal(literal))
        self._wake.set()

    @property
    def session_count(self) -> int:
        with self._lock:
            return len(self._sessions)

    def count(self, method: str, path: str, contains: str = "") -> int:
        """Number of requests seen with this method and path (and ``contains`` in the query string)."""
        with self._lock:
            return sum(1 for m, p, q, _ in self.requests if m == method and p == path and contains in q)

    # -- request dispatch

    def dispatch(self, req: Request) -> Response:
        """Answer one request (thread-safe)."""
        with self._lock:
            resp = self._dispatch(req)
            self.requests.append((req.method, req.path, urlsplit(req.target).query, resp.status))
        self._wake.set()
        return resp

    def _dispatch(self, req: Request) -> Response:
        if self._fail_503 > 0:
            self._fail_503 -= 1
            return Response(503, b"Service Unavailable", [("Content-Type", "text/plain")])
        session, cookies, denied = self._authenticate(req)
        if denied is not None:
            return denied
        bad = self._check_media(req)
        if bad is not None:
            return bad
        try:
            resp = self._route(req, session)
        except _Reject as rej:
            resp = self._error(req, rej.status, rej.code, rej.detail)
        resp.headers.extend(("Set-Cookie", c) for c in cookies)
        return resp

    # -- authentication and sessions

    def _authenticate(self, req: Request) -> tuple[_Session | None, list[str], Response | None]:
        """(session, Set-Cookie values, refusal). Cookie first, then Digest (1.0) / Basic (2.0)."""
        self._expire_idle()
        sid = _cookies(req.header("Cookie")).get("-http-session-")
        if self._fail_401 > 0:
            self._fail_401 -= 1
            if sid in self._sessions:
                self._drop_session(sid)
            self._nonces.clear()
            return None, [], self._challenge(stale=True)
        if sid in self._sessions:
            session = self._sessions[sid]
            session.last_seen = time.monotonic()
            return session, [], None
        user, stale = self._check_credentials(req)
        if user is None:
            self.counts["auth_failures"] += bool(req.header("Authorization"))
            return None, [], self._challenge(stale=stale)
        if len(self._sessions) >= self.max_sessions:
            return None, [], Response(503, b"Too many sessions", [("Content-Type", "text/plain")])
        return self._new_session(user)

    def _new_session(self, user: str) -> tuple[_Session, list[str], None]:
        session = _Session(secrets.token_hex(12), secrets.token_hex(8), user, time.monotonic())
        self._sessions[session.sid] = session
        self.counts["sessions"] += 1
        return session, [f"-http-session-={session.sid}; path=/; httponly", f"ABBCX={session.abbcx}; path=/"], None

    def _drop_session(self, sid: str) -> None:
        self._sessions.pop(sid, None)
        for domain, holder in list(self.mastership.items()):
            if holder.session == sid:
                del self.mastership[domain]

    def _expire_idle(self) -> None:
        now = time.monotonic()
        for sid, s in list(self._sessions.items()):
            if now - s.last_seen > self.session_idle_s:
                self._drop_session(sid)

    def _check_credentials(self, req: Request) -> tuple[str | None, bool]:
        """(user or None, stale nonce?) from the Authorization header."""
        auth = req.header("Authorization")
        scheme, _, rest = auth.partition(" ")
        if self.version == 1 and scheme.lower() == "digest":
            return self._check_digest(req, rest)
        if self.version == 2 and scheme.lower() == "basic":
            return self._check_basic(rest), False
        return None, False

    def _check_digest(self, req: Request, fields_text: str) -> tuple[str | None, bool]:
        """RFC 7616 Digest with MD5 and qop=auth against this request's method and target."""
        f = parse_keqv_list(parse_http_list(fields_text))
        needed = ("username", "realm", "nonce", "uri", "response", "qop", "nc", "cnonce")
        if any(k not in f for k in needed) or f["realm"] != REALM or f["qop"] != "auth":
            return None, False
        if f.get("algorithm", "MD5").upper() != "MD5" or f["uri"] != req.target:
            return None, False
        if f["nonce"] not in self._nonces:
            return None, True
        ha1 = _md5(f"{f['username']}:{REALM}:{self._password}")
        ha2 = _md5(f"{req.method}:{f['uri']}")
        expected = _md5(f"{ha1}:{f['nonce']}:{f['nc']}:{f['cnonce']}:auth:{ha2}")
        ok = hmac.compare_digest(expected, f["response"]) and f["username"] == self._user
        return (f["username"] if ok else None), False

    def _check_basic(self, token: str) -> str | None:
        try:
            user, _, password = base64.b64decode(token.strip()).decode("utf-8").partition(":")
        except (ValueError, UnicodeDecodeError):
            return None
        ok = hmac.compare_digest(user.encode(), self._user.encode()) and \
            hmac.compare_digest(password.encode(), self._password.encode())
        return user if ok else None

    def _challenge(self, *, stale: bool = False) -> Response:
        """401 with a fresh Digest nonce (1.0) or a Basic challenge (2.0)."""
        if self.version == 1:
            nonce = secrets.token_hex(16)
            self._nonces[nonce] = time.monotonic()
            value = (f'Digest realm="{REALM}", domain="/", qop="auth", nonce="{nonce}", opaque="{self._opaque}", '
                     f'algorithm="MD5", stale="{"TRUE" if stale else "FALSE"}"')
        else:
            value = f'Basic realm="{REALM}"'
        return Response(401, b"", [("WWW-Authenticate", value)])

    def _check_media(self, req: Request) -> Response | None:
        """RWS 2.0 media-type versioning: Accept and body types must carry ``;v=2.0``."""
        if self.version != 2 or req.path.startswith("/logout"):
            return None
        files = req.path.startswith("/fileservice")
        if req.method in ("GET", "HEAD") and not files and "v=2.0" not in req.header("Accept"):
            return Response(406, b"", [("Content-Type", "text/plain")])
        if req.method in ("POST", "PUT") and req.body and "v=2.0" not in req.header("Content-Type"):
            return Response(415, b"", [("Content-Type", "text/plain")])
        return None

    # -- routing

    def _route(self, req: Request, session: _Session) -> Response:
        path = req.path.rstrip("/") or "/"
        for method, pattern, handler in self._table():
            m = re.fullmatch(pattern, path)
            if m and method == req.method:
                return handler(req, session, *m.groups())
        if any(re.fullmatch(p, path) for _, p, _ in self._table()):
            return Response(405, b"", [("Content-Type", "text/plain")])
        raise _Reject(404, UNRESOLVED_URL, path)

    def _table(self) -> list[tuple[str, str, Callable[..., Response]]]:
        common = [
            ("GET", r"/", self._get_root), ("GET", r"/logout", self._logout), ("GET", r"/rw/system", self._system),
            ("GET", r"/rw/panel/opmode", self._get_opmode), ("GET", r"/rw/panel/speedratio", self._get_speedratio),
            ("POST", r"/rw/panel/speedratio", self._set_speedratio), ("GET", r"/rw/rapid/execution", self._get_exec),
            ("GET", r"/rw/rapid/tasks", self._get_tasks), ("GET", r"/rw/mastership/(\w+)", self._get_mastership),
            ("GET", r"/rw/motionsystem/mechunits", self._get_mechunits),
            ("GET", r"/rw/motionsystem/mechunits/(\w+)/jointtarget", self._get_jointtarget),
            ("GET", r"/rw/motionsystem/mechunits/(\w+)/robtarget", self._get_robtarget),
            ("GET", r"/rw/elog/(\d+)", self._get_elog), ("GET", r"/ctrl/identity", self._get_identity),
            ("GET", r"/rw/system/robottype", self._get_robottype), ("GET", r"/rw/system/options", self._get_options),
            ("GET", r"/rw/rapid/tasks/(\w+)/pcp", self._get_pcp), ("GET", r"/ctrl/(\$?\w+)", self._get_ctrl_var),
            ("GET", r"/fileservice/(.+)", self._get_file), ("PUT", r"/fileservice/(.+)", self._put_file),
            ("DELETE", r"/fileservice/(.+)", self._delete_file), ("HEAD", r"/fileservice/(.+)", self._head_file),
        ]
        if self.version == 1:
            return common + [
                ("GET", r"/rw/panel/ctrlstate", self._get_ctrlstate),
                ("POST", r"/rw/panel/ctrlstate", self._post1_ctrl),
                ("POST", r"/rw/rapid/execution", self._post1_exec), ("GET", r"/rw/rapid/modules", self._get_modules1),
                ("POST", r"/rw/rapid/tasks/(\w+)", self._post1_task),
                ("POST", r"/rw/rapid/tasks/(\w+)/pcp", self._post1_pcp),
                ("GET", r"/rw/rapid/tasks/(\w+)/motion", self._get_task_motion1),
                ("GET", r"/rw/rapid/symbol/data/RAPID/(\w+)/(\w+)(?:/(\w+))?", self._get_symbol),
                ("POST", r"/rw/rapid/symbol/data/RAPID/(\w+)/(\w+)(?:/(\w+))?", self._post1_symbol),
                ("POST", r"/rw/mastership(?:/(\w+))?", self._post1_mastership),
            ]
        return common + [
            ("GET", r"/rw/panel/ctrl-state", self._get_ctrlstate), ("POST", r"/rw/panel/ctrl-state", self._set_ctrl),
            ("POST", r"/rw/rapid/execution/(start|stop|resetpp)", self._post2_exec),
            ("GET", r"/rw/rapid/tasks/(\w+)/modules", self._get_modules2),
            ("POST", r"/rw/rapid/tasks/(\w+)/(loadmod|unloadmod)", self._post2_task),
            ("POST", r"/rw/rapid/tasks/(\w+)/pcp/routine", self._post2_pcp),
            ("GET", r"/rw/rapid/tasks/(\w+)/motion/(jointtarget|robtarget)", self._get_task_motion2),
            ("GET", r"/rw/rapid/symbol/RAPID/(\w+)/(\w+)(?:/(\w+))?/data", self._get_symbol),
            ("POST", r"/rw/rapid/symbol/RAPID/(\w+)/(\w+)(?:/(\w+))?/data", self._post2_symbol),
            ("POST", r"/rw/mastership(?:/(\w+))?/(request|release)", self._post2_mastership),
        ]

    # -- representations

    def _ok(self, req: Request, items: list[dict], *, collection: bool = False) -> Response:
        """200 with items in the flavour's envelope (1.0 JSON/XHTML, 2.0 HAL)."""
        base = {"href": f"{self.base_url}{req.path.rsplit('/', 1)[0]}/"}
        if self.version == 1 and req.q("json") != "1":
            return Response(200, _xhtml(items).encode(), [("Content-Type", "application/xhtml+xml")])
        if self.version == 1:
            doc: dict[str, Any] = {"_links": {"base": base}, "_embedded": {"_state": items}}
            return _json(200, doc, "application/json")
        if collection:
            doc = {"_links": {"base": base, "self": {"href": ""}}, "_embedded": {"resources": items}}
        else:
            doc = {"_links": {"base": base, "self": {"href": ""}}, "status": {"code": S_OK}, "state": items}
        return _json(200, doc, "application/hal+json;v=2.0")

    def _error(self, req: Request, status: int, code: int, detail: str = "") -> Response:
        """Error envelope: 1.0 ``_embedded.status`` (or XHTML), 2.0 ``status``."""
        msg = f"rws_emulator.py[0] {E.get(code, 'Error.')} {detail} code:{code} icode:-1".replace("  ", " ")
        base = {"href": f"{self.base_url}/"}
        if self.version == 1 and req.q("json") != "1":
            body = (f'<html><body><div class="status"><span class="code">{code}</span>'
                    f'<span class="msg">{_esc(msg)}</span></div></body></html>')
            return Response(status, body.encode(), [("Content-Type", "application/xhtml+xml")])
        if self.version == 1:
            return _json(status, {"_links": {"base": base}, "_embedded": {"status": {"code": code, "msg": msg},
                                                                           "_state": []}}, "application/json")
        return _json(status, {"_links": {"base": base}, "status": {"code": code, "msg": msg}},
                     "application/hal+json;v=2.0")

    # -- panel, system, session

    def _get_root(self, req: Request, s: _Session) -> Response:
        return self._ok(req, [{"_type": "rw-root", "_title": "rw", "name": "RWS emulator"}])

    def _logout(self, req: Request, s: _Session) -> Response:
        self._drop_session(s.sid)
        self.counts["logouts"] += 1
        return Response(204, b"", [("Set-Cookie", "-http-session-=; path=/; max-age=0")])

    def _system(self, req: Request, s: _Session) -> Response:
        rw = "6.16.0.0" if self.version == 1 else "7.10.0"
        return self._ok(req, [{"_type": "sys-system", "_title": "system", "rwversion": rw,
                               "name": "RWS-EMULATOR", "sysid": "{00000000-0000-0000-0000-000000000000}"}])

    def _get_ctrlstate(self, req: Request, s: _Session) -> Response:
        title = "ctrlstate" if self.version == 1 else "ctrl-state"
        return self._ok(req, [{"_type": "pnl-ctrlstate", "_title": title, "ctrlstate": self.ctrlstate}])

    def _post1_ctrl(self, req: Request, s: _Session) -> Response:
        if req.q("action") != "setctrlstate":
            raise _Reject(400, INVALIDARG, "action")
        return self._set_ctrl(req, s)

    def _set_ctrl(self, req: Request, s: _Session) -> Response:
        wanted = req.form().get("ctrl-state", "")
        if wanted not in ("motoron", "motoroff"):
            raise _Reject(400, INVALIDARG, "ctrl-state")
        if wanted == "motoron" and self.opmode != "AUTO":
            raise _Reject(403, MODE_REJECT, "remote motors on needs AUTO")
        if wanted == "motoron" and self.ctrlstate not in ("motoroff", "motoron"):
            raise _Reject(400, INVALID_STATE, f"ctrlstate {self.ctrlstate}")
        if wanted == "motoron":
            self.ctrlstate = "motoron"
            self.add_elog(1, 10011, "Motors ON state")
        else:
            self.set_ctrlstate("motoroff")
        return Response(204)

    def _get_opmode(self, req: Request, s: _Session) -> Response:
        return self._ok(req, [{"_type": "pnl-opmode", "_title": "opmode", "opmode": self.opmode}])

    def _get_speedratio(self, req: Request, s: _Session) -> Response:
        return self._ok(req, [{"_type": "pnl-speedratio", "_title": "speedratio", "speedratio": str(self.speedratio)}])

    def _set_speedratio(self, req: Request, s: _Session) -> Response:
        try:
            ratio = int(req.form().get("speed-ratio", ""))
        except ValueError:
            raise _Reject(400, INVALIDARG, "speed-ratio") from None
        if not 0 <= ratio <= 100:
            raise _Reject(400, INVALIDARG, "speed-ratio")
        self.speedratio = ratio
        return Response(204)

    # -- RAPID execution

    def _get_exec(self, req: Request, s: _Session) -> Response:
        return self._ok(req, [{"_type": "rap-execution", "_title": "execution", "ctrlexecstate": self.execution,
                               "cycle": self.cycle}])

    def _post1_exec(self, req: Request, s: _Session) -> Response:
        action = req.q("action") or ""
        if action not in ("start", "stop", "resetpp"):
            raise _Reject(400, INVALIDARG, f"action {action}")
        return self._post2_exec(req, s, action)

    def _post2_exec(self, req: Request, s: _Session, verb: str) -> Response:
        {"start": self._start, "stop": self._stop, "resetpp": self._resetpp}[verb](req, s)
        return Response(204)

    def _start(self, req: Request, s: _Session) -> None:
        form = req.form()
        if self.version == 1 and any(k not in form for k in ("regain", "execmode", "cycle", "condition",
                                                              "stopatbp", "alltaskbytsp")):
            raise _Reject(400, INVALIDARG, "start needs regain, execmode, cycle, condition, stopatbp, alltaskbytsp")
        if self.opmode != "AUTO":
            raise _Reject(403, MODE_REJECT, "remote start needs AUTO")
        if self.ctrlstate != "motoron" or self.execution == "running":
            raise _Reject(400, EXEC_STATE, f"ctrlstate {self.ctrlstate}, execution {self.execution}")
        self._require_edit(s, for_start=True)
        self._require_linked()
        if self.pp is None:
            raise _Reject(400, NO_PP, "set the PP to main or to a routine")
        self.execution, self.cycle = "running", form.get("cycle", "forever")
        self.add_elog(1, 10151, "Program started")

    def _stop(self, req: Request, s: _Session) -> None:
        if self.execution == "running":
            self._stop_program(1, 10125, "Program stopped", "stopped by remote client")

    def _resetpp(self, req: Request, s: _Session) -> None:
        if self.execution == "running":
            raise _Reject(400, EXEC_STATE, "RAPID is running")
        self._require_edit(s, explicit=self.version == 2, implicit=self._implicit(req))
        self._require_linked()
        main = next((m.name for m in self.modules.values() if m.has_main), None)
        if main is None:
            raise _Reject(400, NO_PP, "no main routine")
        self.pp, self._fresh_start = (main, "main"), True
        self.add_elog(1, 10002, "Program pointer has been reset")

    def _post1_pcp(self, req: Request, s: _Session, task: str) -> Response:
        if req.q("action") != "set-pp-routine":
            raise _Reject(400, INVALIDARG, f"action {req.q('action')}")
        return self._post2_pcp(req, s, task)

    def _post2_pcp(self, req: Request, s: _Session, task: str) -> Response:
        """PP to routine (``module`` and ``routine`` both required): stopped, edit mastership, no link error,
        a procedure without parameters."""
        if task != TASK:
            raise _Reject(400 if self.version == 1 else 404, E_FAIL, "unknown task")
        if self.execution == "running":
            raise _Reject(400, EXEC_STATE, "RAPID is running")
        self._require_edit(s, explicit=True, implicit=self._implicit(req))
        self._require_linked()
        form = req.form()
        module = self.modules.get(form.get("module", "").lower())
        routine = form.get("routine", "")
        if module is None or not routine:
            raise _Reject(400, INVALIDARG, "module and routine are required")
        if routine.lower() not in module.routines or module.routines[routine.lower()]:
            raise _Reject(400, ILLEGAL_ENTRYPOINT, f"{module.name}/{routine}")
        self.pp, self._fresh_start = (module.name, routine), True
        self.add_elog(1, 10006, "Program pointer moved to routine", f"{module.name}/{routine}")
        return Response(204)

    def _implicit(self, req: Request) -> bool:
        """RWS 2.0 ``?mastership=implicit`` accepted (unless the controller is set to refuse implicit mastership)."""
        return self.version == 2 and req.q("mastership") == "implicit" and self.implicit_mastership

    def _get_mechunits(self, req: Request, s: _Session) -> Response:
        return self._ok(req, [{"_type": "ms-mechunit-li", "_title": "ROB_1", "mode": "Activated"}], collection=True)

    def _get_pcp(self, req: Request, s: _Session, task: str) -> Response:
        module, routine = self.pp or ("", "")
        item = {"_type": "pcp-info", "_title": "progpointer", "beginposition": "1,1" if self.pp else "",
                "endposition": "1,1" if self.pp else "", "modulemame": module, "routinename": routine,
                "execlevel": "Normal"}
        return self._ok(req, [item])

    def link_error(self) -> str:
        """What keeps the task's program from linking (empty if it links): two ``main`` procedures, or main calling
        a procedure that no module defines."""
        mains = [m.name for m in self.modules.values() if m.has_main]
        if len(mains) > 1:
            return f"Ambiguous name main (modules {', '.join(mains)})"
        defined = {r for m in self.modules.values() for r in m.routines}
        for m in self.modules.values():
            unknown = sorted(m.main_calls - defined)
            if unknown:
                return f"Reference to unknown procedure {unknown[0]} in {m.name}"
        return ""

    def _require_linked(self) -> None:
        error = self.link_error()
        if error:
            raise _Reject(400, RAPID_SEMANTIC_ERROR, error)

    def _stop_program(self, msgtype: int, code: int, title: str, desc: str = "") -> None:
        self.execution = "stopped"
        self.add_elog(msgtype, code, title, desc)

    # -- mastership

    def _get_mastership(self, req: Request, s: _Session, domain: str) -> Response:
        key = self._domain(domain)
        holder = self.mastership.get(key)
        item = {"_type": "msh-resource", "_title": domain, "mastership": "nomaster", "mastershipheldbyme": "FALSE"}
        if holder is None and key == "motion" and self.execution == "running":
            item["mastership"] = "internal"          # RAPID itself holds motion while it runs
        if holder is not None:
            mine = holder.session == s.sid
            item.update(mastership="remote" if holder.session else holder.location,
                        mastershipheldbyme="TRUE" if mine else "FALSE", application=holder.application,
                        location=holder.location, uid=holder.session or "0")
        return self._ok(req, [item])

    def _post1_mastership(self, req: Request, s: _Session, domain: str | None) -> Response:
        verb = req.q("action") or ""
        if verb not in ("request", "release"):
            raise _Reject(400, INVALIDARG, f"action {verb}")
        return self._post2_mastership(req, s, domain, verb)

    def _post2_mastership(self, req: Request, s: _Session, domain: str | None, verb: str) -> Response:
        keys = [self._domain(domain)] if domain else ["edit", "motion"] + (["cfg"] if self.version == 1 else [])
        if verb == "request":
            if self.opmode != "AUTO":
                raise _Reject(403, MODE_REJECT, "mastership in manual mode needs RMMP")
            for key in keys:
                holder = self.mastership.get(key)
                if holder is not None and holder.session != s.sid:
                    self._count_foreign_refusal(key)
                    raise _Reject(403, RESOURCE_HELD, f"{key} held by {holder.application}")
            for key in keys:
                self.mastership[key] = _Holder(s.sid, "RWS", "remote")
        else:
            for key in keys:   # a release from a non-holder is a silent no-op
                if self.mastership.get(key) and self.mastership[key].session == s.sid:
                    del self.mastership[key]
        return Response(204)

    def _count_foreign_refusal(self, key: str) -> None:
        left = self._foreign_refusals.get(key)
        if left is not None:
            self._foreign_refusals[key] = left - 1
            if left - 1 <= 0:
                self._foreign_refusals.pop(key)
                self.mastership.pop(key, None)

    def _domain(self, domain: str) -> str:
        valid = ("rapid", "motion", "cfg") if self.version == 1 else ("edit", "motion")
        if domain not in valid:
            raise _Reject(404, UNRESOLVED_URL, f"mastership domain {domain}")
        return _domain_key(domain)

    def _require_edit(self, s: _Session, *, explicit: bool = False, implicit: bool = False,
                      for_start: bool = False) -> None:
        """Mastership rules for RAPID edits and start (see the module docstring)."""
        holder = self.mastership.get("edit")
        if holder is not None and holder.session != s.sid:
            raise _Reject(403, RESOURCE_HELD, f"edit held by {holder.application}")
        if for_start:
            if self.version == 2 and holder is not None:
                raise _Reject(403, RESOURCE_HELD, "release edit mastership before start")
            return
        if explicit and holder is None and not implicit:
            raise _Reject(403, MASTER_REJECT, "request mastership first")

    # -- tasks, modules, symbols

    def _get_tasks(self, req: Request, s: _Session) -> Response:
        item = {"_type": "rap-task-li", "_title": TASK, "name": TASK, "type": "normal",
                "taskstate": "started" if self.modules else "empty",
                "excstate": "started" if self.execution == "running" else "stopped", "active": "On",
                "motiontask": "TRUE"}
        return self._ok(req, [item], collection=True)

    def _module_items(self) -> list[dict]:
        system = [{"_type": "rap-module-info-li", "_title": n, "name": n, "type": "SysMod"} for n in ("BASE", "user")]
        return system + [{"_type": "rap-module-info-li", "_title": m.name, "name": m.name, "type": "ProgMod"}
                         for m in self.modules.values()]

    def _get_modules1(self, req: Request, s: _Session) -> Response:
        if (req.q("task") or TASK) != TASK:
            raise _Reject(400, E_FAIL, "unknown task")
        return self._ok(req, self._module_items())

    def _get_modules2(self, req: Request, s: _Session, task: str) -> Response:
        if task != TASK:
            raise _Reject(404, UNRESOLVED_URL, "unknown task")
        return self._ok(req, self._module_items())

    def _post1_task(self, req: Request, s: _Session, task: str) -> Response:
        action = req.q("action") or ""
        if action in ("activate", "deactivate"):
            return Response(204)
        if action not in ("loadmod", "unloadmod"):
            raise _Reject(400, INVALIDARG, f"action {action}")
        return self._post2_task(req, s, task, action)

    def _post2_task(self, req: Request, s: _Session, task: str, verb: str) -> Response:
        if task != TASK:
            raise _Reject(400 if self.version == 1 else 404, E_FAIL, "unknown task")
        if self.execution == "running":
            raise _Reject(400 if self.version == 1 else 403, EXEC_STATE, "Operation not allowed for current PGM state")
        self._require_edit(s, explicit=True, implicit=self._implicit(req))
        form = req.form()
        if verb == "unloadmod":
            return self._unload(form.get("module", ""))
        return self._loadmod(form.get("modulepath", ""), form.get("replace", "false").lower() == "true")

    def _loadmod(self, modulepath: str, replace: bool) -> Response:
        key = self._file_key(modulepath)
        if key not in self.files:
            raise _Reject(400, FILE_NOT_FOUND, modulepath)
        try:
            module = parse_module(self.files[key].decode("latin-1"))
        except RapidSyntaxError as exc:
            self.add_elog(3, 40010, "Syntax error", str(exc))
            raise _Reject(400, INVALID_PROGRAMFILE, str(exc)) from None
        if module.name.lower() in self.modules and not replace:
            raise _Reject(400, MOD_AMBNAME, module.name)
        self._install(module)
        error = self.link_error()
        if error:                                  # loaded, but the program does not link (as on a controller)
            self.add_elog(3, 40192, "Link error", error)
        return Response(204)

    def _install(self, module: Module) -> None:
        self.modules[module.name.lower()] = module
        if module.has_main or (self.pp is not None and self.pp[0].lower() == module.name.lower()):
            self.pp = None

    def _unload(self, name: str) -> Response:
        module = self.modules.pop(name.lower(), None)
        if module is None:
            raise _Reject(400, NO_SUCH_SYMBOL if self.version == 1 else MOD_AMBNAME, name)
        if module.has_main or (self.pp is not None and self.pp[0].lower() == module.name.lower()):
            self.pp = None
        return Response(204)

    def _find_symbol(self, task: str, first: str, second: str | None) -> Symbol:
        """``RAPID/{task}/{module}/{symbol}`` or the task-global ``RAPID/{task}/{symbol}``."""
        missing = _Reject(400, E_FAIL, "symbol not found") if self.version == 1 else \
            _Reject(404, NO_SUCH_SYMBOL, "symbol not found")
        if task != TASK:
            raise missing
        if second is not None:
            module = self.modules.get(first.lower())
            if module is None or second.lower() not in module.symbols:
                raise missing
            return module.symbols[second.lower()]
        for module in self.modules.values():
            sym = module.symbols.get(first.lower())
            if sym is not None and sym.storage == "PERS":
                return sym
        raise missing

    def _get_symbol(self, req: Request, s: _Session, task: str, first: str, second: str | None) -> Response:
        sym = self._find_symbol(task, first, second)
        title = f"RAPID/{task}/{first}" + (f"/{second}" if second else "")
        return self._ok(req, [{"_type": "rap-data", "_title": title, "value": sym.value}])

    def _post1_symbol(self, req: Request, s: _Session, task: str, first: str, second: str | None) -> Response:
        if req.q("action") != "set":
            raise _Reject(400, INVALIDARG, "action")
        return self._write_symbol(req, s, self._find_symbol(task, first, second), implicit=True)

    def _post2_symbol(self, req: Request, s: _Session, task: str, first: str, second: str | None) -> Response:
        sym = self._find_symbol(task, first, second)
        if req.q("mastership") == "implicit" and not self.implicit_mastership:
            holder = self.mastership.get("edit")
            if holder is None or holder.session != s.sid:
                raise _Reject(403, MASTER_REJECT, "implicit mastership refused; request edit mastership")
        return self._write_symbol(req, s, sym, implicit=req.q("mastership") == "implicit" and self.implicit_mastership)

    def _write_symbol(self, req: Request, s: _Session, sym: Symbol, *, implicit: bool) -> Response:
        if self.opmode != "AUTO":
            raise _Reject(403, MODE_REJECT, "remote writes in manual mode need RMMP")
        self._require_edit(s, explicit=True, implicit=implicit)
        if sym.storage == "CONST":
            raise _Reject(400, INVALIDARG, f"{sym.name} is a constant")
        try:
            value = parse_literal(req.form().get("value", ""))
        except RapidSyntaxError:
            raise _Reject(400, INVALIDARG, "value does not parse") from None
        shape = SHAPES.get(sym.dtype)
        if shape is not None and not sym.array and not matches(value, shape):
            raise _Reject(400, INVALIDARG, f"value is not a {sym.dtype}")
        sym.value = render(value)
        return Response(204)

    # -- motion system and elog

    def _get_jointtarget(self, req: Request, s: _Session, mechunit: str) -> Response:
        self._check_mechunit(mechunit)
        item = {"_type": "ms-jointtarget", "_title": mechunit}
        item.update({f"rax_{i + 1}": render(float(v)) for i, v in enumerate(self.joints)})
        item.update({f"eax_{c}": "9E+09" for c in "abcdef"})
        return self._ok(req, [item])

    def _get_robtarget(self, req: Request, s: _Session, mechunit: str) -> Response:
        self._check_mechunit(mechunit)
        (x, y, z), quat, conf = self.robtarget
        item = {"_type": "ms-robtargets", "_title": mechunit, "x": render(x), "y": render(y), "z": render(z)}
        item.update({f"q{i + 1}": render(float(q)) for i, q in enumerate(quat)})
        item.update(dict(zip(("cf1", "cf4", "cf6", "cfx"), (str(int(c)) for c in conf))))
        item.update({f"eax_{c}": "9E+09" for c in "abcdef"})
        item.update({f"eax{c}": "9E+09" for c in "abcdef"})
        return self._ok(req, [item])

    def _check_mechunit(self, mechunit: str) -> None:
        if mechunit != "ROB_1":
            raise _Reject(400 if self.version == 1 else 404, -1073436668, f"no mechunit {mechunit}")

    def _get_elog(self, req: Request, s: _Session, domain: str) -> Response:
        entries = list(reversed(self.elog)) if domain == "0" else []
        start = int(req.q("start") or 1)
        limit = int(req.q("limit") or 200)
        items = [self._elog_item(e) for e in entries[start - 1:start - 1 + limit]]
        return self._ok(req, items, collection=True)

    def _elog_item(self, e: dict) -> dict:
        item = {"_type": "elog-message-li", "_title": f"/rw/elog/0/{e['seqnum']}", "msgtype": str(e["msgtype"]),
                "code": str(e["code"]), "tstamp": e["tstamp"], "title": e["title"], "desc": e["desc"],
                "conseqs": "", "causes": "", "actions": "", "argc": "0"}
        if self.version == 2:
            item["_links"] = {"self": {"href": f"0/{e['seqnum']}?lang=en"}}
        return item

    def _get_identity(self, req: Request, s: _Session) -> Response:
        return self._ok(req, [{"_type": "ctrl-identity-info", "_title": "identity", "ctrl-name": "RWS-EMULATOR",
                               "ctrl-type": "Virtual Controller", "ctrl-id": self.serial,
                               "mac-address": "00-00-00-00-00-00"}])

    def _get_robottype(self, req: Request, s: _Session) -> Response:
        return self._ok(req, [{"_type": "sys-robottype", "_title": "robottype", "robot-type": self.robot_type}])

    def _get_options(self, req: Request, s: _Session) -> Response:
        return self._ok(req, [{"_type": "sys-option-li", "_title": str(i), "option": o}
                              for i, o in enumerate(self.system_options)], collection=True)

    def _get_task_motion1(self, req: Request, s: _Session, task: str) -> Response:
        resource = req.q("resource") or ""
        if resource not in ("jointtarget", "robtarget"):
            raise _Reject(400, INVALIDARG, "resource")
        return self._get_task_motion2(req, s, task, resource)

    def _get_task_motion2(self, req: Request, s: _Session, task: str, resource: str) -> Response:
        """The motion task's current jointtarget / robtarget (what RW7 clients read)."""
        if task != TASK:
            raise _Reject(400 if self.version == 1 else 404, E_FAIL, "unknown task")
        return self._get_jointtarget(req, s, "ROB_1") if resource == "jointtarget" else \
            self._get_robtarget(req, s, "ROB_1")

    def _get_ctrl_var(self, req: Request, s: _Session, name: str) -> Response:
        return self._ok(req, [{"_type": "ctrl-var", "_title": name, "_value": f"{name.strip('$')}",
                               "value": f"{name.strip('$')}"}])

    # -- file service

    def _file_key(self, path: str) -> str:
        """``$HOME/a/b.mod`` (2.0 also ``%24HOME``, ``HOME``) -> ``HOME/a/b.mod``."""
        if "%24" in path.upper() and self.version == 1:
            raise _Reject(400, INVALID_PATH, "use a literal $ in the volume name")
        path = unquote(path).strip("/")
        volume, _, rest = path.partition("/")
        volume = volume[1:] if volume.startswith("$") else volume
        if volume.upper() not in VOLUMES or (self.version == 1 and not path.startswith("$")):
            raise _Reject(404, DIR_NOT_EXIST if self.version == 2 else E_FAIL, "no such volume")
        return f"{volume.upper()}/{rest}".rstrip("/")

    def _get_file(self, req: Request, s: _Session, raw: str) -> Response:
        key = self._file_key(raw)
        if key in self.files:
            return Response(200, self.files[key], [("Content-Type", "application/octet-stream")])
        prefix = key + "/"
        names = sorted({k[len(prefix):].split("/")[0] for k in self.files if k.startswith(prefix)})
        if "/" not in key or names:
            items = [{"_type": "fs-file", "_title": n, "fs-size": str(len(self.files.get(prefix + n, b"")))}
                     for n in names]
            return self._ok(req, items, collection=True)
        raise _Reject(404, DIR_NOT_EXIST if self.version == 2 else E_FAIL, "file not found")

    def _head_file(self, req: Request, s: _Session, raw: str) -> Response:
        return Response(200 if self._file_key(raw) in self.files else 404)

    def _put_file(self, req: Request, s: _Session, raw: str) -> Response:
        if self.version == 2 and "v=2.0" not in req.header("Content-Type"):
            return Response(415, b"", [("Content-Type", "text/plain")])
        key = self._file_key(raw)
        existed = key in self.files
        self.files[key] = req.body
        return Response(200 if existed else 201)

    def _delete_file(self, req: Request, s: _Session, raw: str) -> Response:
        if self.files.pop(self._file_key(raw), None) is None:
            raise _Reject(404, DIR_NOT_EXIST if self.version == 2 else E_FAIL, "file not found")
        return Response(204)

    # -- the simulated CalServer loop

    def _calserver_loop(self) -> None:
        """Plays CalServer.mod: wait for a new request, ack it, serve it (see ``_serve``)."""
        while not self._halt.is_set():
            self._wake.wait(0.005)
            self._wake.clear()
            job = self._take_request()
            if job is not None:
                try:
                    self._serve(*job)
                except Exception:                     # noqa: BLE001 - a hook failing must not kill the loop
                    log.exception("CalServer simulation failed")
                    with self._lock:
                        self._stop_program(3, 40000, "Emulator error")

    def _serving(self) -> bool:
        module = self.modules.get("calserver")
        return self.execution == "running" and self.ctrlstate == "motoron" and module is not None and \
            self._pp_reaches_calserver()

    def _pp_reaches_calserver(self) -> bool:
        """The program runs CalServer's loop: PP set to cal_run, or to a main that calls it."""
        if self.pp is None:
            return False
        module, routine = self.pp
        if routine.lower() == ENTRY:
            return True
        owner = self.modules.get(module.lower())
        return routine.lower() == "main" and owner is not None and ENTRY in owner.main_calls

    def _publish(self) -> None:
        """What cal_publish does: cal_state := [ack, done, err]."""
        syms = self.modules["calserver"].symbols
        if "cal_state" in syms:
            values = [parse_literal(syms[n].value) for n in ("cal_ack_seq", "cal_done_seq", "cal_err_seq")]
            syms["cal_state"].value = render(values)

    def _take_request(self) -> tuple | None:
        """Under the lock: resync after PP reset; if req != ack, ack it and snapshot the arguments."""
        with self._lock:
            if not self._serving() or not self.calserver_alive:
                return None
            syms = self.modules["calserver"].symbols
            num = lambda n: parse_literal(syms[n].value)  # noqa: E731
            if self._fresh_start:
                syms["cal_ack_seq"].value = syms["cal_done_seq"].value = syms["cal_req_seq"].value
                self._fresh_start = False
                self._publish()
            if num("cal_req_seq") == num("cal_ack_seq"):
                return None
            seq = num("cal_req_seq")
            syms["cal_ack_seq"].value = render(seq)
            self._publish()
            fault = self._faults.pop(0) if self._faults and num("cal_kind") in (1.0, 2.0) else None
            limits = self._limits(syms, num("cal_speed")) if int(num("cal_kind")) in (1, 2) else None
            return (seq, int(num("cal_kind")), parse_literal(syms["cal_target"].value),
                    parse_literal(syms["cal_ptarget"].value), limits, num("cal_settle_s"), fault)

    def _limits(self, syms: dict[str, Symbol], speed: list) -> dict:
        """What cal_limit does (clamp the speed to cal_vmax, VelSet) and the load in cal_tool; recorded."""
        get = lambda n, d: parse_literal(syms[n].value) if n in syms else d  # noqa: E731
        vmax, override = get("cal_vmax", 1e9), get("cal_override", 100.0)
        vmax = vmax if vmax > 0 else 1.0
        override = min(100.0, max(1.0, override))
        tool = get("cal_tool", None)
        record = {"v_tcp_programmed": speed[0], "v_leax_programmed": speed[2], "vmax": vmax, "override": override,
                  "v_tcp": min(speed[0], vmax) * override / 100.0, "v_leax": min(speed[2], vmax),
                  "load_kg": tool[2][0] if tool else None, "cog_mm": tuple(tool[2][1]) if tool else None}
        self.executed.append(record)
        return record

    def _serve(self, seq: float, kind: int, target: list, ptarget: list, limits: dict | None, settle_s: float,
               fault: _Fault | None) -> None:
        if fault is not None and self._apply_fault(seq, fault):
            return
        if kind == 0:
            return self._set_done(seq)
        if kind == 1:
            reached = self._move_joints(tuple(target[0][:6]), limits["override"] / 100.0)
        elif kind == 2:
            reached = self._move_linear(tuple(ptarget[0]), tuple(ptarget[1]), tuple(int(c) for c in ptarget[2]))
        else:
            return self._reject(seq, -1, f"CalServer: unknown request kind {kind}")
        if reached is None or not self._dwell(settle_s):
            return
        self._set_done(seq)

    def _apply_fault(self, seq: float, fault: _Fault) -> bool:
        """Play an injected fault; True if the request ends here."""
        if fault.after_s and not self._dwell(fault.after_s):
            return True
        with self._lock:
            if fault.kind == "error":
                self._reject(seq, fault.code or 41617, fault.message or "CalServer: move rejected, ERRNO 41617")
            elif fault.kind == "motors_off":
                self.add_elog(3, fault.code or 20205, fault.message or "Auto stop open")
                self.set_ctrlstate("guardstop")
            elif fault.kind == "rapid_stop":
                self._stop_program(3, fault.code or 50050, fault.message or "Position outside reach")
        return True

    def _reject(self, seq: float, errno: int, message: str) -> None:
        """What ``cal_reject`` does in RAPID."""
        with self._lock:
            syms = self.modules["calserver"].symbols
            syms["cal_err_no"].value = render(float(errno))
            syms["cal_err_msg"].value = render(message[:80])
            self.add_elog(2, 80002, "CalServer request rejected", message)
            syms["cal_err_seq"].value = render(seq)
            self._publish()

    def _set_done(self, seq: float) -> None:
        with self._lock:
            syms = self.modules["calserver"].symbols
            syms["cal_reached"].value = render([list(map(float, self.joints)), [UNUSED] * 6])
            syms["cal_done_seq"].value = render(seq)
            self._publish()

    def _move_joints(self, q: tuple[float, ...], override: float = 1.0) -> tuple[float, ...] | None:
        """Interpolate to ``q`` (deg) at ``joint_speed_deg_s`` times the VelSet override; None if limits, a hook
        fault or a stop intervene."""
        for i, (v, (lo, hi)) in enumerate(zip(q, self.joint_limits)):
            if not lo <= v <= hi:
                with self._lock:
                    self._stop_program(3, 50027, "Joint Out of Range", f"axis {i + 1}: {v:g} deg not in [{lo}, {hi}]")
                return None
        with self._lock:
            start = list(self.joints)
        duration = max(abs(a - b) for a, b in zip(q, start)) / (self.joint_speed_deg_s * override)
        steps = max(1, int(duration / 0.01))
        for k in range(1, steps + 1):
            if not self._dwell(duration / steps):
                return None
            with self._lock:
                self.joints = [a + (b - a) * k / steps for a, b in zip(start, q)]
        try:
            actual = self.move_hook(q) if self.move_hook else None
        except EmulatedMotionFault as fault:
            with self._lock:
                self._stop_program(3, fault.code, fault.title)
            return None
        with self._lock:
            self.joints = [float(v) for v in (actual if actual is not None else q)]
            self.moves.append(("MoveAbsJ", tuple(q)))
            return tuple(self.joints)

    def _move_linear(self, trans: tuple, quat: tuple, conf: tuple) -> tuple[float, ...] | None:
        """MoveL: the robtarget hook may return joints; by default only the Cartesian state changes."""
        try:
            actual = self.robtarget_hook(trans, quat, conf) if self.robtarget_hook else None
        except EmulatedMotionFault as fault:
            with self._lock:
                self._stop_program(3, fault.code, fault.title)
            return None
        with self._lock:
            self.robtarget = (list(trans), list(quat), list(conf))
            if actual is not None:
                self.joints = [float(v) for v in actual]
            self.moves.append(("MoveL", tuple(trans) + tuple(quat)))
            return tuple(self.joints)

    def _dwell(self, seconds: float) -> bool:
        """Wait ``seconds`` while RAPID keeps running with motors on; False if interrupted."""
        end = time.monotonic() + max(0.0, seconds)
        while True:
            with self._lock:
                if not self._serving():
                    return False
            left = end - time.monotonic()
            if left <= 0:
                return True
            if self._halt.wait(min(left, 0.005)):
                return False


class _Reject(Exception):
    """An RWS error answer (HTTP status, return code, detail)."""

    def __init__(self, status: int, code: int, detail: str = "") -> None:
        super().__init__(detail)
        self.status, self.code, self.detail = status, code, detail


def _domain_key(domain: str) -> str:
    """1.0 ``rapid`` and 2.0 ``edit`` guard the same thing."""
    return "edit" if domain in ("rapid", "edit") else domain


def _cookies(header: str) -> dict[str, str]:
    out = {}
    for part in header.split(";"):
        name, sep, value = part.strip().partition("=")
        if sep:
            out[name] = value
    return out


def _md5(text: str) -> str:
    return hashlib.md5(text.encode("utf-8")).hexdigest()


def _json(status: int, doc: dict, ctype: str) -> Response:
    return Response(status, json.dumps(doc).encode(), [("Content-Type", ctype)])


def _esc(text: str) -> str:
    return text.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;").replace('"', "&quot;")


def _xhtml(items: Iterable[dict]) -> str:
    """RWS 1.0 XHTML: one ``li`` per item with ``span`` fields."""
    lis = []
    for item in items:
        spans = "".join(f'<span class="{_esc(k)}">{_esc(str(v))}</span>' for k, v in item.items()
                        if not k.startswith("_") and not isinstance(v, (dict, list)))
        lis.append(f'<li class="{_esc(item.get("_type", ""))}" title="{_esc(item.get("_title", ""))}">{spans}</li>')
    return ('<?xml version="1.0" encoding="utf-8"?><html xmlns="http://www.w3.org/1999/xhtml"><head>'
            '<title>rws</title></head><body><div class="state"><ul>' + "".join(lis) + "</ul></div></body></html>")


# --------------------------------------------------------------------------- TLS and the socket server


def _have_cryptography() -> bool:
    try:
        import cryptography  # noqa: F401
    except ImportError:
        return False
    return True


def _self_signed_cert(folder: Path, host: str) -> tuple[str, str]:
    """A throwaway EC P-256 certificate for ``host`` (1 day), like OmniCore's self-signed one."""
    from datetime import timedelta, timezone

    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import NameOID

    key = ec.generate_private_key(ec.SECP256R1())
    name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, "rws-emulator")])
    now = datetime.now(timezone.utc)
    san = x509.SubjectAlternativeName([x509.IPAddress(ipaddress.ip_address(host)), x509.DNSName("localhost")])
    cert = (x509.CertificateBuilder().subject_name(name).issuer_name(name).public_key(key.public_key())
            .serial_number(x509.random_serial_number()).not_valid_before(now - timedelta(minutes=5))
            .not_valid_after(now + timedelta(days=1)).add_extension(san, critical=False)
            .sign(key, hashes.SHA256()))
    cert_path, key_path = folder / "cert.pem", folder / "key.pem"
    cert_path.write_bytes(cert.public_bytes(serialization.Encoding.PEM))
    key_path.write_bytes(key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                                           serialization.NoEncryption()))
    os.chmod(key_path, 0o600)
    return str(cert_path), str(key_path)


class _Server(ThreadingHTTPServer):
    daemon_threads = True
    block_on_close = False

    def __init__(self, address: tuple[str, int], handler: type, emu: RwsEmulator,
                 ssl_context: ssl.SSLContext | None) -> None:
        self.emu, self.ssl_context = emu, ssl_context
        super().__init__(address, handler)

    def finish_request(self, request: Any, client_address: Any) -> None:
        """TLS handshake in the worker thread, so a silent client cannot block the accept loop."""
        if self.ssl_context is None:
            return super().finish_request(request, client_address)
        request.settimeout(5)
        try:
            tls = self.ssl_context.wrap_socket(request, server_side=True)
        except (ssl.SSLError, OSError):
            return None
        try:
            super().finish_request(tls, client_address)
        finally:
            tls.close()


class _Handler(BaseHTTPRequestHandler):
    protocol_version = "HTTP/1.1"
    timeout = 30
    wbufsize = 1 << 16               # headers and body leave in one segment (no Nagle / delayed-ACK stalls)
    disable_nagle_algorithm = True
    server: _Server

    def _handle(self) -> None:
        length = int(self.headers.get("Content-Length") or 0)
        body = self.rfile.read(length) if length else b""
        resp = self.server.emu.dispatch(Request(self.command, self.path, self.headers, body))
        self.send_response(resp.status)
        for key, value in resp.headers:
            self.send_header(key, value)
        if resp.status not in (204, 304):
            self.send_header("Content-Length", str(len(resp.body)))
        self.end_headers()
        if self.command != "HEAD" and resp.body:
            self.wfile.write(resp.body)

    do_GET = do_POST = do_PUT = do_DELETE = do_HEAD = _handle

    def log_message(self, fmt: str, *args: Any) -> None:
        log.debug("%s " + fmt, self.address_string(), *args)


# --------------------------------------------------------------------------- CLI


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m drivers.emulators.rws_server --version 1|2 [--port 0] [--print-port]``: serve until ^C."""
    p = argparse.ArgumentParser(description="ABB Robot Web Services emulator (loopback only)")
    p.add_argument("--version", type=int, choices=(1, 2), default=1, help="RWS 1.0 (IRC5) or 2.0 (OmniCore)")
    p.add_argument("--host", default="127.0.0.1", help="loopback address to bind (default 127.0.0.1)")
    p.add_argument("--port", type=int, default=0, help="TCP port (0 = a free one)")
    p.add_argument("--print-port", action="store_true", help="print the bound port on stdout")
    p.add_argument("--http", action="store_true", help="serve RWS 2.0 over plain HTTP")
    p.add_argument("--user", default="Default User")
    p.add_argument("--password-env", default="RWS_PASSWORD",
                   help="environment variable holding the password (default RWS_PASSWORD, else 'robotics')")
    p.add_argument("--joint-speed", type=float, default=200.0, help="simulated joint speed (deg/s)")
    a = p.parse_args(argv)
    emu = RwsEmulator(a.version, host=a.host, port=a.port, tls=False if a.http else None, user=a.user,
                      password=os.environ.get(a.password_env, "robotics"), joint_speed_deg_s=a.joint_speed)
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    with emu:
        if a.print_port:
            print(emu.port, flush=True)
        print(f"RWS {a.version}.0 emulator on {emu.base_url} (user {a.user!r})", file=sys.stderr, flush=True)
        try:
            while not stop.wait(0.2):
                pass
        except KeyboardInterrupt:
            pass
    return 0


if __name__ == "__main__":
    sys.exit(main())
